"""``hexapod-bench conformance BACKEND_SPEC`` (benchmarks.robot.conformance_command): its
figures and exit codes, through the real CLI entry point."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.cli import main as cli_main
from hexapod.backends.base import BackendStep
from hexapod.backends.sim import SimulatedRobot


class Careless(SimulatedRobot):
    """A simulated robot that neither clamps its speed nor stops at its strokes (named on
    the command line as ``tests.benchmarks.robot.test_conformance_command:Careless``)."""

    def step(self, velocities: np.ndarray, dt: float) -> BackendStep:
        v = np.nan_to_num(np.asarray(velocities, float))
        self._q = self._q + v * dt
        return BackendStep(self.measured_lengths(), v, np.zeros(6, bool))


def test_the_exact_simulator_passes(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli_main(["conformance", "sim"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("conformance of sim (sim) against the simulator, deltalab, dt 20 ms")
    assert "largest deviation over the smooth motion 0.000 um (tolerance 10 um): PASS" in out


def test_a_backend_that_does_not_clamp_fails_with_exit_1(
        capsys: pytest.CaptureFixture[str]) -> None:
    spec = "tests.benchmarks.robot.test_conformance_command:Careless"
    assert cli_main(["conformance", spec]) == 1
    out = capsys.readouterr().out
    assert ": FAIL\n" in out
    assert "  - speed limit: a leg moved" in out
    assert "  - speed limit: a command 10x the limit was not reported clamped" in out
    assert "  - stroke: measured" in out


@pytest.mark.parametrize(("argv", "fragment"), [
    (["serial:/nonexistent/port"], "is real hardware: the check drives its legs through "
                                   "their whole stroke; add --move-real-robot"),
    (["sim", "--tolerance-um", "-1"], "--tolerance-um must be >= 0 and finite, got -1"),
    (["sim", "--periods", "0"], "--periods must be >= 1, got 0"),
    (["simm"], "simm"),
])
def test_bad_input_exits_2(capsys: pytest.CaptureFixture[str], argv: list[str],
                           fragment: str) -> None:
    assert cli_main(["conformance", *argv]) == 2
    assert fragment in capsys.readouterr().err


@pytest.mark.realtime
@pytest.mark.slow
def test_the_emulator_verdict_matches_its_figures(capsys: pytest.CaptureFixture[str]) -> None:
    """The firmware emulator on a pseudo-terminal: the verdict, the exit code and the
    figures agree. (Whether it passes is a wall-clock race on a loaded machine: a period
    whose MOV is sent late ends before its motion, docs/backends.md; unloaded it passes
    at 50 ms within the protocol's micrometres.)"""
    code = cli_main(["conformance", "emulator", "--dt", "0.05"])
    out = capsys.readouterr().out
    assert out.startswith("conformance of emulator (emulator) against the simulator, "
                          "deltalab, dt 50 ms: ")
    dev = float(out.split("smooth motion ")[1].split(" um")[0])
    problems = [line for line in out.splitlines() if line.startswith("  - ")]
    assert dev >= 0.1, "the micrometre quantisation of the protocol shows"
    if code == 0:
        assert ": PASS\n" in out and dev <= 10.0 and not problems
    else:
        assert code == 1 and ": FAIL\n" in out and problems
        assert dev > 10.0 or not problems[0].startswith("  - smooth motion")
