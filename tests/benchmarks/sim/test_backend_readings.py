"""A backend's reading that cannot be the robot's legs (not a number, millimetres for
metres) ends its study trial, or stops a servo session for safety, with the reading named
(it used to reach the forward kinematics: "forward kinematics of the true robot failed
(singularity?)" in a study, an internal error with a traceback in a session)."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from benchmarks.cli import main as cli_main
from benchmarks.robot import servo
from benchmarks.robot.exits import ServoExit
from benchmarks.sim.plant import BackendPlant, KinematicPlant, reading_problem
from hexapod.backends.base import BackendStep
from hexapod.backends.sim import SimulatedRobot
from hexapod.fk import forward_kinematics
from hexapod.geometry import deltalab
from tests.benchmarks.robot.sessions import final, goal_file

HERE = "tests.benchmarks.sim.test_backend_readings"


class NanAtFifth(SimulatedRobot):
    """Leg 3 reads NaN at the fifth period (a dropped encoder word)."""

    def __init__(self, *args: object, **kwargs: object) -> None:
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]
        self.periods = 0

    def step(self, velocities: np.ndarray, dt: float) -> BackendStep:
        done = super().step(velocities, dt)
        self.periods += 1
        if self.periods != 5:
            return done
        q = done.lengths.copy()
        q[3] = np.nan
        return replace(done, lengths=q)


class Millimetres(SimulatedRobot):
    """A plugin that reports its legs in millimetres."""

    def step(self, velocities: np.ndarray, dt: float) -> BackendStep:
        done = super().step(velocities, dt)
        return replace(done, lengths=done.lengths * 1e3)


def test_reading_problem_names_the_leg_and_the_units() -> None:
    g = deltalab()
    q = np.full(6, g.q_mid)
    assert reading_problem(q, g.stroke) is None
    past = q.copy()
    past[2] = g.stroke[1] + 0.06  # an end stop plus an offset: a leg, if a strange one
    assert reading_problem(past, g.stroke) is None
    bad = q.copy()
    bad[4] = np.inf
    assert reading_problem(bad, g.stroke) == (
        "the backend measured leg 4 as inf (not a number: a fault of the robot's sensors "
        "or of its link)")
    text = reading_problem(q * 1e3, g.stroke)
    assert text is not None and text.startswith("the backend measured leg 0 at 415 m")
    assert text.endswith("(millimetres? SI units: metres)")
    assert reading_problem(q[:5], g.stroke) == ("the backend measured 5 values of shape "
                                                "(5,), not 6 leg lengths")


def test_the_row_fails_and_keeps_its_last_good_reading() -> None:
    g = deltalab()
    q0 = np.full((2, 6), g.q_mid)
    robots = [SimulatedRobot(g, q0[0]), NanAtFifth(g, q0[1])]
    q = q0.copy()
    start = forward_kinematics(g, q0[0])
    R = np.array([start.rotation] * 2)
    t = np.array([start.translation] * 2)
    poses = KinematicPlant(q, R, t, g.base_points, g.platform_points, g.stroke, g.max_speed)
    plant = BackendPlant(robots, q, R, t, np.zeros((2, 6)), poses.solve_poses, g.stroke)
    run, v = np.arange(2), np.full((2, 6), 0.001)
    for _ in range(4):
        assert plant.advance(run, v, 0.02) == {}
    before, t_before = q.copy(), t.copy()
    failures = plant.advance(run, v, 0.02)
    assert list(failures) == [1] and "leg 3 as nan" in failures[1]
    assert np.array_equal(q[1], before[1])  # the last good reading
    assert np.allclose(q[0], before[0] + 0.02 * 0.001)  # the other row moved, posed
    assert t[0, 2] > start.translation[2] and np.array_equal(t[1], t_before[1])


@pytest.mark.parametrize(("robot", "reason"), [
    ("NanAtFifth", "the backend measured leg 3 as nan (not a number"),
    ("Millimetres", "(millimetres? SI units: metres)")])
def test_a_study_trial_ends_with_the_reading_named(tmp_path: Path, robot: str,
                                                   reason: str) -> None:
    out = tmp_path / "run"
    cli_main(["run", "quick", "--trials", "1", "--controllers", "leg-edge", "--backend",
              f"{HERE}:{robot}", "--out", str(out)])
    rows = [json.loads(line) for line in (out / "results.jsonl").read_text().splitlines()]
    assert len(rows) == 1 and not rows[0]["converged"]
    assert reason in rows[0]["failure"]


@pytest.mark.slow
@pytest.mark.parametrize(("robot", "reason"), [
    ("NanAtFifth", "period 4: the backend measured leg 3 as nan (not a number"),
    ("Millimetres", "period 0: the backend measured leg 0 at 415")])
def test_a_servo_session_stops_for_safety_and_halts(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], robot: str, reason: str) -> None:
    out = tmp_path / "session"
    code = servo.main(["--backend", f"{HERE}:{robot}", "--camera", "sim",
                       "--simulated-camera-on-real-robot", "--goal", str(goal_file(tmp_path)),
                       "--out", str(out), "--max-steps", "50"])
    stdout = capsys.readouterr().out
    assert code == ServoExit.SAFETY, stdout
    assert f"stopped: {reason}" in stdout
    assert "robot: halted and confirmed stopped" in stdout
    assert reason in json.dumps(final(out))
