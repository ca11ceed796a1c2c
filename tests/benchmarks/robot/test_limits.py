"""The limits of a servo session (benchmarks.robot.limits) on the simulated robot."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.robot.exits import ServoExit, SessionStop
from benchmarks.robot.limits import MISSED_WINDOW, DeadlinePolicy, LimitedRobot, SessionLimits
from hexapod.actuation import Actuation
from hexapod.backends.sim import SimulatedRobot
from hexapod.geometry import deltalab


def _robot(limits: SessionLimits) -> LimitedRobot:
    robot = SimulatedRobot(deltalab())
    return LimitedRobot(robot, limits, robot.measured_lengths())


def test_the_speed_cap_is_applied_and_flagged() -> None:
    robot = _robot(SessionLimits(max_speed=0.002))
    v = np.array([0.01, -0.01, 0.001, 0.0, 0.002, -0.003])
    bs = robot.apply(v, Actuation.VELOCITY, 0.02)
    np.testing.assert_allclose(bs.applied_velocities, [0.002, -0.002, 0.001, 0, 0.002, -0.002])
    assert bs.clamped.tolist() == [True, True, False, False, False, True]
    assert robot.moved and np.allclose(robot.last_applied, bs.applied_velocities)


def test_a_command_beyond_the_travel_limit_is_not_sent() -> None:
    robot = _robot(SessionLimits(max_speed=0.05, max_travel=0.001))
    q0 = robot.robot.measured_lengths()
    for _ in range(2):  # 2 x 0.4 mm: inside 1 mm
        robot.apply(np.full(6, 0.02), Actuation.VELOCITY, 0.02)
    with pytest.raises(SessionStop) as stop:
        robot.apply(np.full(6, 0.02), Actuation.VELOCITY, 0.02)
    assert stop.value.code is ServoExit.LIMIT
    assert stop.value.reason.startswith("--max-travel-mm 1 reached: leg 0 at ")
    assert "would move 1.200 mm" in stop.value.reason
    np.testing.assert_allclose(robot.robot.measured_lengths() - q0, 0.0008, atol=1e-12)


def _policy(**kw: float) -> tuple[DeadlinePolicy, list[str]]:
    said: list[str] = []
    return DeadlinePolicy(SessionLimits(max_speed=0.05, **kw), 0.02, said.append), said


def test_consecutive_missed_periods_stop_the_session() -> None:
    policy, said = _policy(max_missed_consecutive=3, max_missed_fraction=1.0)
    for step in range(4):  # isolated misses never stop it
        policy.update(step, step % 2 == 0, 0.03, 0.001)
    policy.update(4, True, 0.03, 0.001)
    policy.update(5, True, 0.03, 0.001)
    with pytest.raises(SessionStop, match="--max-missed-consecutive 3 reached: 3 periods in a "
                                          r"row missed their 20 ms deadline \(last: compute "
                                          r"30.0 ms \+ link 1.0 ms"):
        policy.update(6, True, 0.03, 0.001)
    assert len(said) == 1 and said[0].startswith("warning: 1 late period(s)")  # one a second


def test_a_fraction_of_missed_periods_stops_the_session() -> None:
    policy, _ = _policy(max_missed_consecutive=0, max_missed_fraction=0.25)
    late = [k % 3 == 0 for k in range(MISSED_WINDOW + 10)]  # 1 in 3, never 2 in a row
    with pytest.raises(SessionStop, match=r"--max-missed-fraction 0.25 reached: 17 of the "
                                          r"last 50 periods") as stop:
        for step, missed in enumerate(late):
            policy.update(step, missed, 0.01, 0.001)
    assert stop.value.code is ServoExit.LIMIT


def test_a_policy_of_never_stops_never() -> None:
    policy, _ = _policy(max_missed_consecutive=0, max_missed_fraction=1.0)
    for step in range(3 * MISSED_WINDOW):
        policy.update(step, True, 0.05, 0.001)
    assert policy.total == 3 * MISSED_WINDOW
