"""Backends as plugins: the registry, the spec syntax, the example of docs/backends.md run as
an entry-point plugin of a temporary distribution, and the conformance check."""

from __future__ import annotations

import importlib
import os
import re
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from hexapod import deltalab
from hexapod.backends.base import BackendStep
from hexapod.backends.conformance import check_backend
from hexapod.backends.registry import ENTRY_POINT_GROUP, BackendRegistry, backends
from hexapod.backends.sim import SimulatedRobot
from hexapod.exceptions import BackendPluginError, UnknownBackendError
from hexapod.geometry import HexapodGeometry

ROOT = Path(__file__).resolve().parents[2]
DIST, VERSION = "hexapod-test-robot", "1.2.3"


def _doc_example() -> str:
    """The ``my_robot.py`` block of docs/backends.md, as the user reads it."""
    text = (ROOT / "docs" / "backends.md").read_text()
    match = re.search(r"<!-- example: my_robot.py -->\n```python\n(.*?)```", text, re.S)
    assert match, "docs/backends.md has lost its example"
    return match.group(1)


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """A temporary distribution shipping the documented backend, plus a broken one."""
    root = tmp_path_factory.mktemp("site")
    (root / "my_robot.py").write_text(_doc_example())
    (root / "broken_robot.py").write_text("raise ImportError('needs vendor_sdk')\n")
    info = root / f"hexapod_test_robot-{VERSION}.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {DIST}\nVersion: {VERSION}\n")
    (info / "entry_points.txt").write_text(
        f"[{ENTRY_POINT_GROUP}]\nlagging = my_robot:LaggingRobot\n"
        "broken = broken_robot:Robot\n")
    sys.path.insert(0, str(root))
    try:
        yield root
    finally:
        sys.path.remove(str(root))
        for mod in ("my_robot", "broken_robot"):
            sys.modules.pop(mod, None)


def test_entry_point_backend_is_registered_and_a_broken_one_reported(site: Path) -> None:
    reg = BackendRegistry()
    reg.register("sim", backends.resolve("sim")[1])
    assert "lagging" in reg.names()
    info = {i.name: i for i in reg.info()}["lagging"]
    assert (info.package, info.version) == (DIST, VERSION)
    assert info.description.startswith("Legs that follow their setpoints")
    assert [e.spec for e in reg.errors] == ["broken"]
    assert "needs vendor_sdk" in str(reg.errors[0])
    robot = reg.open("lagging:0.01", deltalab(), np.full(6, 0.4))
    assert robot.identity == "lagging robot (tau 0.01 s)"
    np.testing.assert_allclose(robot.measured_lengths(), 0.4)


def test_spec_syntax_and_errors(site: Path) -> None:
    name, _, args = backends.resolve("my_robot:LaggingRobot:0.02")
    assert (name, args) == ("my_robot:LaggingRobot", "0.02")
    name, _, args = backends.resolve("serial:socket://127.0.0.1:5000")
    assert (name, args) == ("serial", "socket://127.0.0.1:5000")
    with pytest.raises(UnknownBackendError, match="did you mean 'emulator'"):
        backends.resolve("emulatr")
    with pytest.raises(BackendPluginError, match="on PYTHONPATH"):  # (a class named as
        backends.resolve("no_such_module:Robot")  # module:attr: its module is missing)
    with pytest.raises(UnknownBackendError, match="or name a class as module:attr"):
        backends.resolve("no_such_module:/dev/ttyUSB0")  # (not a class name: a typo)
    with pytest.raises(BackendPluginError, match="ModuleNotFoundError"):
        backends.resolve("no_such_package.robot:Robot")
    with pytest.raises(BackendPluginError, match="not a subclass"):
        backends.resolve("numpy:ndarray")
    with pytest.raises(BackendPluginError, match="needs arguments: serial:URL"):
        backends.open("serial", deltalab())


def test_documented_backend_conforms_and_its_lag_is_measured(site: Path) -> None:
    robot_cls = importlib.import_module("my_robot").LaggingRobot
    g = deltalab()
    exact = check_backend(lambda geo, q: robot_cls.open("", geo, q), g)
    assert exact.ok, exact.problems
    assert exact.max_deviation < 1e-12
    lag = check_backend(lambda geo, q: robot_cls.open("0.01", geo, q), g, tolerance=1e-3)
    assert lag.ok, lag.problems
    assert 1e-5 < lag.max_deviation < 1e-3
    strict = check_backend(lambda geo, q: robot_cls.open("0.01", geo, q), g)
    assert not strict.ok and "smooth motion, period 0: leg" in strict.problems[0]


def test_conformance_catches_a_backend_that_ignores_the_limits() -> None:
    from hexapod.backends.base import BackendStep
    from hexapod.backends.sim import SimulatedRobot

    class Careless(SimulatedRobot):
        def step(self, velocities, dt):  # type: ignore[no-untyped-def]
            v = np.nan_to_num(np.asarray(velocities, float))
            self._q = self._q + v * dt
            return BackendStep(self.measured_lengths(), v, np.zeros(6, bool))

    report = check_backend(lambda geo, q: Careless(geo, q), deltalab())
    text = " ".join(report.problems)
    assert "speed limit: a leg moved" in text and "not reported clamped" in text
    assert "stroke: measured" in text


def test_a_backend_given_args_it_does_not_take_is_a_spec_error() -> None:
    """``NAME:ARGS`` for a backend whose constructor takes no ARGS: a ``BackendError``
    naming the class and the ARGS, which the commands report as a bad spec (exit 2; it
    was a ``TypeError`` traceback, exit 1); without ARGS it opens."""
    from hexapod.backends.sim import SimulatedRobot
    from hexapod.exceptions import BackendError

    class NoArgs(SimulatedRobot):
        def __init__(self, geometry: HexapodGeometry) -> None:
            super().__init__(geometry)

    with pytest.raises(BackendError, match="NoArgs: cannot be opened with the ARGS 'foo' "
                                           "after its name"):
        NoArgs.open("foo", deltalab())
    NoArgs.open("", deltalab()).close()


def test_conformance_fails_a_reading_that_cannot_be_the_legs() -> None:
    """A NaN leg from period 5 on, and readings in millimetres: each fails the check
    naming the stage, the leg and the value, with the millimetre hint (a NaN passed:
    'largest deviation 0.000 um ... PASS', a comparison with NaN being false; millimetres
    were a deviation without the hint); halt and close are still called."""
    from hexapod.backends.base import BackendStep
    from hexapod.backends.sim import SimulatedRobot

    calls: list[str] = []

    class NanLeg(SimulatedRobot):
        steps = 0

        def step(self, velocities, dt):  # type: ignore[no-untyped-def]
            got = super().step(velocities, dt)
            self.steps += 1
            q = got.lengths.copy()
            if self.steps > 5:
                q[3] = np.nan
            return BackendStep(q, got.applied_velocities, got.clamped)

        def halt(self) -> None:
            calls.append("halt")

        def close(self) -> None:
            calls.append("close")

    class Millimetres(SimulatedRobot):
        def measured_lengths(self) -> np.ndarray:
            return super().measured_lengths() * 1e3

    report = check_backend(lambda geo, q: NanLeg(geo, q), deltalab())
    assert not report.ok
    assert report.problems == ["smooth motion, period 5: the backend measured leg 3 as nan "
                               "(not a number: a fault of the robot's sensors or of its "
                               "link)"], report.problems
    assert calls == ["halt", "close"]
    report = check_backend(lambda geo, q: Millimetres(geo, q), deltalab())
    assert report.problems == ["start: the backend measured leg 0 at 415 m, where no leg of "
                               "the nominal robot can be (its stroke 345 to 485 mm) "
                               "(millimetres? SI units: metres)"], report.problems


def test_the_collector_is_off_while_driving_and_as_it_was_after() -> None:
    """A collection pause would show as a lagging in-process emulator: the check drives
    the backend with the garbage collector off, and leaves it as it found it."""
    import gc

    from hexapod.backends.sim import SimulatedRobot

    seen: list[bool] = []

    class Watched(SimulatedRobot):
        def step(self, velocities, dt):  # type: ignore[no-untyped-def]
            seen.append(gc.isenabled())
            return super().step(velocities, dt)

    was = gc.isenabled()
    try:
        for before in (True, False):
            (gc.enable if before else gc.disable)()
            seen.clear()
            report = check_backend(lambda geo, q: Watched(geo, q), deltalab())
            assert report.ok, report.problems
            assert seen and not any(seen)
            assert gc.isenabled() is before
    finally:
        (gc.enable if was else gc.disable)()


class _Late(SimulatedRobot):
    """A simulated robot read before its period's motion ends in the periods of ``late``
    (half the motion done; the next period's setpoint starts from that reading, as the
    serial backend's does), saying so (``missed_period``) when ``says`` is true."""

    late: frozenset[int] = frozenset()
    says = True

    def __init__(self, geometry: HexapodGeometry, lengths: np.ndarray) -> None:
        super().__init__(geometry, lengths)
        self.n = 0

    def step(self, velocities: np.ndarray, dt: float) -> BackendStep:
        before = self._q.copy()
        done = super().step(velocities, dt)
        self.n += 1
        if self.n - 1 not in self.late:
            return done
        self._q = (before + self._q) / 2  # the next setpoint starts from the reading
        return replace(done, lengths=self.measured_lengths(), missed_period=self.says)


def test_a_period_the_host_missed_is_counted_not_compared() -> None:
    """A period reported missed (read early: the host was late) is not compared and the
    simulator goes on from the reading; too many of them, or a lag the backend does not
    report, is a problem."""
    late = type("OneLate", (_Late,), {"late": frozenset({6})})
    report = check_backend(lambda geo, q: late(geo, q), deltalab())
    assert report.ok, report.problems
    assert report.missed_periods == 1 and report.max_deviation < 1e-12
    silent = type("Silent", (_Late,), {"late": frozenset({6}), "says": False})
    report = check_backend(lambda geo, q: silent(geo, q), deltalab())
    assert report.problems[0].startswith("smooth motion, period 6: leg")
    always = type("Always", (_Late,), {"late": frozenset(range(25))})
    report = check_backend(lambda geo, q: always(geo, q), deltalab())
    assert report.missed_periods == 25
    assert report.problems == ["smooth motion: the host missed 25 of its 25 periods (only "
                               "the others are compared): a longer period (dt) or a quieter "
                               "machine"]
    for every, ok in ((4, False), (5, True)):  # 7 of 25 periods missed, then 5: a quarter
        some = type("Some", (_Late,), {"late": frozenset(range(0, 25, every))})
        report = check_backend(some, deltalab())
        assert report.ok is ok and report.missed_periods == len(range(0, 25, every))


@pytest.mark.realtime
@pytest.mark.slow
def test_the_emulator_conforms_through_a_host_stall() -> None:
    """The host stalls 250 ms before one period (a loaded machine: 214 ms once in CI): the
    board's 100 ms watchdog trips, the backend clears it and sends the MOV again, reads
    the lengths early and says the period was missed; the check goes on from there."""
    robots: list[Any] = []

    def stalling(geo: HexapodGeometry, q: np.ndarray) -> Any:
        robot = backends.open("emulator", geo, q)
        step, calls = robot.step, [0]

        def late_once(v: np.ndarray, dt: float) -> BackendStep:
            calls[0] += 1
            if calls[0] == 6:
                time.sleep(0.25)
            return step(v, dt)

        robot.step = late_once
        robots.append(robot)
        return robot

    report = check_backend(stalling, deltalab(), tolerance=1e-5)
    assert report.ok, report.problems
    # at least: a loaded machine may add stalls of its own
    assert report.missed_periods >= 1 and robots[0].watchdog_trips >= 1
    assert 1e-7 < report.max_deviation < 1e-5


@pytest.mark.realtime
@pytest.mark.slow
def test_emulator_conforms_within_its_micrometre_quantisation() -> None:
    """The protocol carries lengths in micrometres and each period starts from the rounded
    measurement: the emulator drifts from the exact simulator by a few micrometres."""
    report = check_backend(lambda geo, q: backends.open("emulator", geo, q), deltalab(),
                           tolerance=1e-5)
    assert report.ok, report.problems
    assert 1e-7 < report.max_deviation < 1e-5


@pytest.mark.slow
def test_a_plugin_backend_runs_a_trial(site: Path, tmp_path: Path) -> None:
    """`hexapod-bench run --backend lagging:0.005` in a fresh process that finds the plugin
    through its distribution's entry points; the trial converges as with the simulator."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), str(ROOT)])}
    out = tmp_path / "lag"
    cmd = [sys.executable, "-m", "benchmarks.cli", "run", "quick", "--out", str(out),
           "--trials", "1", "--controllers", "leg-edge", "--backend", "lagging:0.005",
           "--no-progress"]
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    from benchmarks.study.runner import read_results

    rows = read_results(out)
    assert len(rows) == 1 and rows[0]["backend"] == "lagging:0.005"
    assert rows[0]["failure"] is None and rows[0]["converged"], rows[0]
    listed = subprocess.run([sys.executable, "-m", "benchmarks.cli", "list"], env=env,
                            capture_output=True, text=True, timeout=300)
    assert "lagging" in listed.stdout and DIST in listed.stdout
    assert "backend plugin failed to load" in listed.stdout and "broken" in listed.stdout
