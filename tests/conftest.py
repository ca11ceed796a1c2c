"""Shared fixtures: the reference robot, another robot, seeded generators."""

from __future__ import annotations

import signal

import numpy as np
import pytest

from hexapod import HexapodGeometry, deltalab
from hexapod.geometry import circular_points

_SETUP_SECONDS = pytest.StashKey[float]()


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--unmarked-budget", type=float, default=None, metavar="SECONDS",
                     help="fail a test not marked slow whose setup and call take longer "
                          "(`make quick` uses 2 s, so that the quick tier stays quick)")


def pytest_configure(config: pytest.Config) -> None:
    """Ctrl-C as a terminal gives it, however the suite was started.

    A background job of a non-interactive shell (``make test &``, ``nohup``) starts with
    SIGINT ignored, and ignored signals stay ignored in every child process. The tests
    that interrupt an exchange, a run or an emulator with SIGINT would then check
    nothing real, so the suite puts Python's own handler back (children get the
    default action on exec).
    """
    if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]
                              ) -> pytest.TestReport:
    """With ``--unmarked-budget``: an unmarked test over budget fails, with its time."""
    report: pytest.TestReport = yield
    if report.when == "setup":
        item.stash[_SETUP_SECONDS] = report.duration
    budget = item.config.getoption("--unmarked-budget")
    if (budget is None or report.when != "call" or not report.passed
            or item.get_closest_marker("slow") is not None):
        return report
    took = report.duration + item.stash.get(_SETUP_SECONDS, 0.0)
    if took > budget:
        report.outcome = "failed"
        report.longrepr = (f"{item.nodeid} took {took:.2f} s (setup and call), over the quick "
                           f"tier's budget of {budget:g} s: make it cheaper or mark it "
                           f"@pytest.mark.slow")
    return report


@pytest.fixture
def geometry() -> HexapodGeometry:
    """The reference robot of docs/math.md section 9."""
    return deltalab()


@pytest.fixture
def other_geometry() -> HexapodGeometry:
    """A robot that is not the reference one: other radii and angles, irregular joints,
    off-plane points (inverse Jacobian condition number about 13 at home)."""
    rng = np.random.default_rng(1234)
    al, be = 12.0, 10.0  # a 6-6 platform like the reference one, other radii and angles
    a = np.array([al, -al, 120 + al, 120 - al, 240 + al, 240 - al])
    b = np.array([60 - be, -60 + be, 180 - be, 60 + be, 300 - be, 180 + be])
    base = circular_points(0.31, np.deg2rad(a + rng.uniform(-3, 3, 6)))
    base[:, 2] = rng.uniform(-0.01, 0.01, 6)
    plat = circular_points(0.17, np.deg2rad(b + rng.uniform(-3, 3, 6)))
    plat[:, 2] = rng.uniform(-0.01, 0.01, 6)
    return HexapodGeometry(base, plat, (0.38, 0.56), leg_radius=0.02, name="other")


@pytest.fixture
def rng() -> np.random.Generator:
    """A seeded generator."""
    return np.random.default_rng(20261122)
