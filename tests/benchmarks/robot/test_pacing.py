"""A servo session keeps the control period of a robot that does not: a backend that
sends its command and returns (neither simulated nor pacing itself) is waited for by the
session (one command per period of wall time, a late period reported missed); a backend
that keeps its periods, or a simulation, is not waited for again."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

from benchmarks.robot import servo
from benchmarks.robot.exits import ServoExit
from benchmarks.robot.limits import PACING_CHECK_PERIODS, LimitedRobot, SessionLimits
from hexapod.actuation import Actuation
from hexapod.backends import rate
from hexapod.backends.sim import SimulatedRobot
from hexapod.geometry import deltalab
from tests.benchmarks.robot.sessions import goal_file, periods
from tests.benchmarks.robot.unpaced_robot import UnpacedRobot

DT = 0.03


def test_a_paced_session_sends_one_command_per_period() -> None:
    robot = UnpacedRobot(deltalab())
    limited = LimitedRobot(robot, SessionLimits(max_speed=0.01), robot.measured_lengths(),
                           pace=True)
    t0 = time.perf_counter()
    for _ in range(6):
        bs = limited.apply(np.full(6, 0.001), Actuation.VELOCITY, DT)
    assert time.perf_counter() - t0 >= 6 * DT - 1e-3  # (each period waited out)
    assert limited.rate is not None and limited.rate.iterations == 6
    assert not bs.missed_period


def test_a_late_period_is_reported_missed() -> None:
    class Slow(UnpacedRobot):
        def step(self, velocities: np.ndarray, dt: float):  # type: ignore[no-untyped-def]
            time.sleep(1.5 * dt)  # longer than the period
            return super().step(velocities, dt)

    robot = Slow(deltalab())
    limited = LimitedRobot(robot, SessionLimits(max_speed=0.01), robot.measured_lengths(),
                           pace=True)
    assert limited.apply(np.zeros(6), Actuation.VELOCITY, DT).missed_period


def test_without_pacing_the_session_does_not_wait(monkeypatch: pytest.MonkeyPatch) -> None:
    slept: list[float] = []
    monkeypatch.setattr(rate.time, "sleep", slept.append)
    robot = SimulatedRobot(deltalab())
    limited = LimitedRobot(robot, SessionLimits(max_speed=0.01), robot.measured_lengths())
    for _ in range(3):
        limited.apply(np.zeros(6), Actuation.VELOCITY, DT)
    assert slept == [] and limited.rate is None


@pytest.mark.slow
def test_a_servo_session_on_an_unpaced_plugin_keeps_the_period(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "session"
    code = servo.main(["--backend", "tests.benchmarks.robot.unpaced_robot:UnpacedRobot",
                       "--camera", "sim", "--simulated-camera-on-real-robot",
                       "--goal", str(goal_file(tmp_path)), "--out", str(out),
                       "--dt", str(DT), "--max-steps", "12"])
    stdout = capsys.readouterr().out
    assert code == ServoExit.LIMIT, stdout  # (its --max-steps)
    assert f"does not wait out its periods: the session does ({DT * 1e3:g} ms)" in stdout
    t = np.array([p["t_s"] for p in periods(out)])
    assert len(t) == 12
    assert np.median(np.diff(t)) >= 0.95 * DT  # one period of wall time per command


def test_the_link_time_of_a_paced_backend_is_the_time_its_step_took() -> None:
    """A plugin reports no round trip (0) while its step takes 12 ms: the period's link
    time is what the step took, not 0 (a late period would blame the compute), and not
    the wait for the end of the period: it ends before the rate limiter reads its clock,
    ``DT - slack`` after the command was sent (slack < 0 when the period is missed: the
    bound holds on a loaded machine too)."""
    class Busy(UnpacedRobot):
        def step(self, velocities: np.ndarray, dt: float):  # type: ignore[no-untyped-def]
            time.sleep(0.012)
            return super().step(velocities, dt)

    robot = Busy(deltalab())
    assert robot.apply(np.zeros(6), Actuation.VELOCITY, DT).round_trip_s == 0.0
    limited = LimitedRobot(robot, SessionLimits(max_speed=0.01), robot.measured_lengths(),
                           pace=True)
    bs = limited.apply(np.zeros(6), Actuation.VELOCITY, DT)
    assert limited.rate is not None and limited.rate.iterations == 1
    assert 0.012 <= bs.round_trip_s <= DT - limited.rate.slack + 1e-9


def test_a_backend_that_claims_to_pace_and_does_not_is_paced(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """``paces_periods`` True but returning at once: after five steps the session warns,
    naming the backend and the gaps, and waits out the periods from then on; a backend
    that does keep its periods is not warned about nor paced again."""
    class Claims(UnpacedRobot):
        paces_periods = True

    warned: list[str] = []
    robot = Claims(deltalab())
    limited = LimitedRobot(robot, SessionLimits(max_speed=0.01), robot.measured_lengths(),
                           check_pacing=True, warn=warned.append)
    for _ in range(PACING_CHECK_PERIODS + 1):
        limited.apply(np.zeros(6), Actuation.VELOCITY, DT)
    assert len(warned) == 1 and "Claims says it waits out its periods" in warned[0]
    assert f"for a {DT * 1e3:g} ms period: the session paces them" in warned[0]
    t0 = time.perf_counter()
    for _ in range(3):
        limited.apply(np.zeros(6), Actuation.VELOCITY, DT)
    assert time.perf_counter() - t0 >= 2 * DT  # paced now (the first on the new grid)

    class Keeps(Claims):
        def step(self, velocities: np.ndarray, dt: float):  # type: ignore[no-untyped-def]
            time.sleep(dt)
            return super().step(velocities, dt)

    warned.clear()
    robot = Keeps(deltalab())
    limited = LimitedRobot(robot, SessionLimits(max_speed=0.01), robot.measured_lengths(),
                           check_pacing=True, warn=warned.append)
    for _ in range(PACING_CHECK_PERIODS + 2):
        limited.apply(np.zeros(6), Actuation.VELOCITY, DT)
    assert warned == [] and not limited.pace and limited.rate is None
