"""Backends as plugins: the registry, the spec syntax, the example of docs/backends.md run as
an entry-point plugin of a temporary distribution, and the conformance check."""

from __future__ import annotations

import importlib
import os
import re
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from hexapod import deltalab
from hexapod.backends.conformance import check_backend
from hexapod.backends.registry import ENTRY_POINT_GROUP, BackendRegistry, backends
from hexapod.exceptions import BackendPluginError, UnknownBackendError

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
    with pytest.raises(UnknownBackendError, match="or name a class as module:attr"):
        backends.resolve("no_such_module:Robot")
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
