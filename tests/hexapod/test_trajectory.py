"""Reference trajectories: derivatives against finite differences, limits respected and
reached, rest at both ends, bad parameters refused."""

from __future__ import annotations

import re

import numpy as np
import pytest

from hexapod.exceptions import TrajectoryError
from hexapod.se3 import exp_so3, log_so3
from hexapod.trajectory import PROFILES, PoseTrajectory, TimingLaw

R0 = exp_so3(np.array([0.05, -0.02, 0.1]))
P0 = np.array([0.01, -0.02, 0.3])


def _make(shape: str, profile: str, **kw: object) -> PoseTrajectory:
    if profile == "s-curve":  # (its jerk limits: the others' tests hold it alike)
        kw = {"jerk": 8.0, "angular_jerk": 60.0, **kw}
    if shape == "line":
        return PoseTrajectory("line", profile, R0, P0, 0.05, 0.4,
                              goal_rotation=exp_so3(np.array([0.1, 0.15, -0.05])) @ R0,
                              goal_translation=P0 + np.array([0.04, -0.03, 0.02]),
                              angular_speed=0.5, angular_acceleration=3.0, **kw)
    return PoseTrajectory(shape, profile, R0, P0, 0.05, 0.4, radius=0.02, laps=2,
                          plane="xz", **kw)


CASES = [(s, p) for s in ("line", "circle", "lemniscate") for p in PROFILES]


@pytest.mark.parametrize(("shape", "profile"), CASES)
def test_derivatives_match_finite_differences(shape: str, profile: str) -> None:
    traj = _make(shape, profile)
    T = traj.duration
    # avoid the trapezoid's corners, where the acceleration jumps
    t = np.linspace(0.013, T - 0.011, 97)
    if profile == "trapezoidal":
        ta = traj.timing.ramp
        t = t[(np.abs(t - ta) > 1e-3) & (np.abs(t - (T - ta)) > 1e-3)]
    h = 1e-6
    a, b, c = traj.at(t - h), traj.at(t), traj.at(t + h)
    v_fd = (c.translation - a.translation) / (2 * h)
    np.testing.assert_allclose(b.velocity, v_fd, atol=1e-8)
    acc_fd = (c.velocity - a.velocity) / (2 * h)
    np.testing.assert_allclose(b.acceleration, acc_fd, atol=1e-6)
    # angular velocity in the base frame: R(t+h) R(t-h)^T = exp(2 h [w]_x)
    w_fd = log_so3(c.rotation @ np.swapaxes(a.rotation, -1, -2)) / (2 * h)
    np.testing.assert_allclose(b.angular_velocity, w_fd, atol=1e-7)
    dw_fd = (c.angular_velocity - a.angular_velocity) / (2 * h)
    np.testing.assert_allclose(b.angular_acceleration, dw_fd, atol=1e-6)
    assert b.twist.shape == (len(t), 6) and b.twist_rate.shape == (len(t), 6)


@pytest.mark.parametrize(("shape", "profile"), CASES)
def test_limits_respected_and_reached(shape: str, profile: str) -> None:
    traj = _make(shape, profile)
    t = np.linspace(0.0, traj.duration, 20001)
    ref = traj.at(t)
    speed = np.linalg.norm(ref.velocity, axis=1)
    assert speed.max() <= traj.speed * (1 + 1e-9)
    if shape == "line":
        accel = np.linalg.norm(ref.acceleration, axis=1)
        ang = np.linalg.norm(ref.angular_velocity, axis=1)
        ang_acc = np.linalg.norm(ref.angular_acceleration, axis=1)
        assert accel.max() <= traj.acceleration * (1 + 1e-9)
        assert ang.max() <= 0.5 * (1 + 1e-9) and ang_acc.max() <= 3.0 * (1 + 1e-9)
        # the fastest law: one of the four limits is reached (to the sampling)
        ratios = [speed.max() / traj.speed, accel.max() / traj.acceleration,
                  ang.max() / 0.5, ang_acc.max() / 3.0]
        assert max(ratios) > 0.999
    else:
        # the tangential acceleration: the component along the velocity
        unit = ref.velocity / np.maximum(speed, 1e-300)[:, None]
        tangential = np.abs(np.einsum("ij,ij->i", ref.acceleration, unit))
        assert tangential.max() <= traj.acceleration * (1 + 1e-9)
        assert max(speed.max() / traj.speed, tangential.max() / traj.acceleration) > 0.999


@pytest.mark.parametrize(("shape", "profile"), CASES)
def test_rest_at_both_ends(shape: str, profile: str) -> None:
    traj = _make(shape, profile)
    ref = traj.at(np.array([-1.0, 0.0, traj.duration, traj.duration + 1.0]))
    np.testing.assert_allclose(ref.translation[0], P0, atol=1e-15)
    np.testing.assert_allclose(ref.rotation[1], R0, atol=1e-15)
    np.testing.assert_allclose(ref.translation[2:], [traj.end_translation] * 2, atol=1e-12)
    np.testing.assert_allclose(ref.rotation[2:], [traj.end_rotation] * 2, atol=1e-12)
    assert not np.any(ref.twist) and not np.any(ref.twist_rate)
    if shape != "line":  # whole laps: back to the start
        np.testing.assert_allclose(traj.end_translation, P0, atol=1e-15)
    else:
        np.testing.assert_allclose(traj.end_translation, P0 + np.array([0.04, -0.03, 0.02]),
                                   atol=1e-15)


def test_trapezoid_cruise_and_triangle() -> None:
    # cruise: peak speed 1/s reached, duration 1/v + v/a
    law = TimingLaw.fit("trapezoidal", 1.0, 4.0)
    assert law.duration == pytest.approx(1.25) and law.peak == 1.0
    # triangle: too short to reach the speed, peak sqrt(a)
    law = TimingLaw.fit("trapezoidal", 10.0, 4.0)
    assert law.duration == pytest.approx(1.0) and law.peak == pytest.approx(2.0)
    s, sd, sdd = law(np.linspace(0, 1, 1001))
    assert s[-1] == pytest.approx(1.0) and sd.max() <= 2.0 + 1e-12 and np.abs(sdd).max() == 4.0
    # the position is the integral of the speed (trapezoid rule)
    t = np.linspace(0, 1, 100001)
    s, sd, _ = law(t)
    np.testing.assert_allclose(s, np.concatenate([[0], np.cumsum(0.5 * (sd[1:] + sd[:-1])
                                                                 * np.diff(t))]), atol=1e-9)


def test_no_motion_line_has_zero_duration() -> None:
    traj = PoseTrajectory("line", "quintic", R0, P0, 0.1, 1.0, goal_rotation=R0,
                          goal_translation=P0)
    assert traj.duration == 0.0
    np.testing.assert_allclose(traj.at(0.5).translation[0], P0)


@pytest.mark.parametrize(("kwargs", "field"), [
    ({"shape": "spiral"}, "shape"),
    ({"profile": "cubic"}, "profile"),
    ({"speed": -1.0}, "speed"),
    ({"acceleration": float("nan")}, "acceleration"),
    ({"radius": 0.0}, "radius"),
    ({"laps": 0}, "laps"),
    ({"laps": 1.5}, "laps"),
    ({"plane": "xw"}, "plane"),
])
def test_bad_parameters_name_the_field(kwargs: dict[str, object], field: str) -> None:
    args: dict[str, object] = {"shape": "circle", "profile": "quintic", "speed": 0.1,
                               "acceleration": 1.0, "radius": 0.02, "laps": 1, "plane": "xy"}
    args.update(kwargs)
    with pytest.raises(TrajectoryError) as info:
        PoseTrajectory(args.pop("shape"), args.pop("profile"), R0, P0,  # type: ignore[arg-type]
                       args.pop("speed"), args.pop("acceleration"), **args)  # type: ignore[arg-type]
    assert info.value.field == field


def test_line_rotation_needs_angular_limits() -> None:
    with pytest.raises(TrajectoryError, match="angular_speed"):
        PoseTrajectory("line", "quintic", R0, P0, 0.1, 1.0,
                       goal_rotation=exp_so3(np.array([0.0, 0.0, 0.1])) @ R0,
                       goal_translation=P0)


@pytest.mark.parametrize(("pose", "field", "says"), [
    # a NaN goal gave a line of 0 s ending at NaN, a scaled one a reference of no robot
    ({"goal_translation": np.array([np.nan, 0.0, 0.36])}, "goal_translation", "finite (3,)"),
    ({"goal_translation": np.zeros(2)}, "goal_translation", "finite (3,)"),
    ({"goal_rotation": 2 * np.eye(3)}, "goal_rotation", "not a rotation"),
    ({"goal_rotation": np.ones(3)}, "goal_rotation", "got shape (3,)"),
    ({"start_rotation": np.diag([1.0, 1.0, -1.0])}, "start_rotation", "det from -1 to -1"),
])
def test_a_pose_that_is_not_one_names_its_argument(pose: dict[str, np.ndarray], field: str,
                                                    says: str) -> None:
    args = {"start_rotation": R0, "start_translation": P0, "goal_rotation": R0,
            "goal_translation": P0 + np.array([0.01, 0.0, 0.0]), **pose}
    with pytest.raises(TrajectoryError, match=f"{field}: .*{re.escape(says)}") as info:
        PoseTrajectory("line", "quintic", args.pop("start_rotation"),
                       args.pop("start_translation"), 0.1, 1.0, **args)
    assert info.value.field == field
