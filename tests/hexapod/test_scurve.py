"""The jerk-limited move (hexapod.scurve) and the time-scaled closed curves
(``peak_acceleration`` of hexapod.trajectory): limits held (finite differences), the end
reached exactly, and the closed-form minimal times."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hexapod.exceptions import TrajectoryError
from hexapod.scurve import SCurve
from hexapod.se3 import exp_so3
from hexapod.trajectory import PoseTrajectory

#: (distance, speed, acceleration, jerk): speed reached; acceleration reached but not the
#: speed; neither (pure jerk); the speed reached without the acceleration.
CASES = [(1.0, 0.5, 2.0, 20.0), (1.0, 5.0, 2.0, 20.0), (0.01, 5.0, 2.0, 20.0),
         (1.0, 0.1, 2.0, 20.0)]


def _sampled(curve: SCurve, n: int = 400_001) -> tuple[np.ndarray, ...]:
    t = np.linspace(0.0, curve.duration, n)
    return (t, *curve(t))


@pytest.mark.parametrize(("d", "v", "a", "j"), CASES)
def test_limits_held_by_finite_differences_and_end_exact(d: float, v: float, a: float,
                                                         j: float) -> None:
    curve = SCurve.fit(d, v, a, j)
    t, s, sd, sdd = _sampled(curve)
    h = t[1] - t[0]
    # each derivative the finite difference of the one below (of the position itself for
    # the speed): the formulas agree with each other and hold the limits
    speed = np.diff(s) / h
    accel = np.diff(sd) / h
    jerk = np.diff(sdd) / h
    assert np.abs(speed).max() <= v * (1 + 1e-6)
    assert np.abs(accel).max() <= a * (1 + 1e-6)
    assert np.abs(jerk).max() <= j * (1 + 1e-6)
    # (to one sample's change at the corners, where the next derivative jumps)
    np.testing.assert_allclose(0.5 * (sd[1:] + sd[:-1]), speed, atol=a * h)
    np.testing.assert_allclose(0.5 * (sdd[1:] + sdd[:-1]), accel, atol=j * h)
    assert s[0] == 0.0 and s[-1] == d  # exactly
    end = curve(np.array([curve.duration, curve.duration + 1.0, -1.0]))
    assert list(end[0]) == [d, d, 0.0] and not np.any(end[1]) and not np.any(end[2])
    assert np.all(np.diff(s) >= 0)  # never back


def test_closed_form_minimal_times() -> None:
    d, v, a, j = CASES[0]  # every limit reached: D / V + V / A + A / J
    assert SCurve.fit(d, v, a, j).duration == pytest.approx(d / v + v / a + a / j, rel=1e-14)
    d, v, a, j = CASES[2]  # bang-bang jerk only: (32 D / J)^(1/3)
    assert SCurve.fit(d, v, a, j).duration == pytest.approx((32 * d / j) ** (1 / 3),
                                                            rel=1e-14)
    d, v, a, j = CASES[1]  # the acceleration reached, not the speed: D = w (w / A + A / J)
    curve = SCurve.fit(d, v, a, j)
    w = curve.peak
    assert w < v and w * (w / a + a / j) == pytest.approx(d, rel=1e-14)
    assert curve.duration == pytest.approx(2 * (w / a + a / j), rel=1e-14)
    # the jerk unbounded in effect: the trapezoid's 1 / V + V / A
    assert SCurve.fit(1.0, 0.5, 2.0, 1e9).duration == pytest.approx(1 / 0.5 + 0.5 / 2,
                                                                    rel=1e-8)


@pytest.mark.parametrize(("d", "v", "a", "j"), CASES)
def test_no_faster_move_within_the_limits(d: float, v: float, a: float, j: float) -> None:
    """A move 1 % shorter in time, time-scaled from the optimum, breaks a limit that binds
    (the optimum reaches its binding limits: it cannot be scaled down)."""
    curve = SCurve.fit(d, v, a, j)
    _, _, sd, sdd = _sampled(curve, 40_001)
    reached = max(np.abs(sd).max() / v, np.abs(sdd).max() / a, curve.jerk / j)
    assert reached == pytest.approx(1.0, abs=1e-3)


def test_bad_limits_refused() -> None:
    with pytest.raises(ValueError, match="jerk"):
        SCurve.fit(1.0, 1.0, 1.0, math.inf)
    with pytest.raises(ValueError, match="acceleration"):
        SCurve.fit(1.0, 1.0, -1.0, 1.0)
    with pytest.raises(TrajectoryError) as info:
        PoseTrajectory("circle", "s-curve", np.eye(3), np.zeros(3), 0.1, 1.0, radius=0.02)
    assert info.value.field == "jerk"


@pytest.mark.parametrize("shape", ["circle", "lemniscate", "line"])
@pytest.mark.parametrize("profile", ["quintic", "trapezoidal", "s-curve"])
def test_peak_acceleration_scales_the_motion(shape: str, profile: str) -> None:
    R0, p0 = exp_so3(np.array([0.02, 0.0, 0.1])), np.array([0.0, 0.01, 0.3])
    kw = {"radius": 0.015, "laps": 2, "plane": "xy", "jerk": 5.0} if shape != "line" else {
        "goal_rotation": R0, "goal_translation": p0 + np.array([0.03, 0.0, -0.02]),
        "jerk": 5.0}

    def make(peak: float | None) -> PoseTrajectory:
        return PoseTrajectory(shape, profile, R0, p0, 0.05, 0.5, peak_acceleration=peak,
                              **kw)  # type: ignore[arg-type]

    base, fast, faster = make(None), make(30.0), make(120.0)
    assert faster.duration == pytest.approx(fast.duration / 2, rel=1e-12)
    for traj, peak in ((fast, 30.0), (faster, 120.0)):
        t = np.linspace(0.0, traj.duration, 200_001)
        h = t[1] - t[0]
        ref = traj.at(t)
        acc_fd = np.gradient(ref.velocity, h, axis=0)  # of the velocity sampled
        inner = slice(2, -2)
        if profile != "trapezoidal":  # (its acceleration jumps at the corners)
            np.testing.assert_allclose(ref.acceleration[inner], acc_fd[inner],
                                       atol=2e-3 * peak)
        reached = np.linalg.norm(ref.acceleration, axis=1).max()
        assert peak * (1 - 1e-4) <= reached <= peak * (1 + 1e-9)  # (to the sampling)
        np.testing.assert_allclose(ref.translation[-1], base.end_translation, atol=1e-15)
        assert not np.any(traj.at(traj.duration).twist)
