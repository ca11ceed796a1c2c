"""What the computed-torque task laws (:mod:`controllers.task_ctc`) read and build
around their loop: why an observation's encoder readings cannot be used
(:func:`encoder_readings`), the checked goal pose and camera with base points of a
context, and the quintic line to a fixed goal (:func:`line_to`).
"""

from __future__ import annotations

import math

import numpy as np

from controllers.base import ControllerContext, Goal, Observation
from controllers.exceptions import ContextError
from controllers.law_tools import base_points_of
from controllers.plausible import implausible_lengths, implausible_pose
from hexapod.exceptions import ShapeError
from hexapod.geometry import HexapodGeometry
from hexapod.kinematics import Transform, check_rotations, inverse_kinematics
from hexapod.se3 import log_so3
from hexapod.trajectory import PoseTrajectory

__all__ = [
    "QUINTIC_PEAK_ACCELERATION",
    "QUINTIC_PEAK_SPEED",
    "camera_and_base_points",
    "encoder_readings",
    "goal_pose_of",
    "line_to",
]

#: Peak of the quintic's speed over its mean speed.
QUINTIC_PEAK_SPEED = 15.0 / 8.0
#: Peak of the quintic's acceleration times ``T^2`` over the distance.
QUINTIC_PEAK_ACCELERATION = 10.0 / math.sqrt(3.0)


def line_to(context: ControllerContext, R0: np.ndarray, t0: np.ndarray, R1: np.ndarray,
            t1: np.ndarray) -> PoseTrajectory:
    """A quintic line from ``(R0, t0)`` to ``(R1, t1)`` (base frame) timed so that no leg's
    nominal speed exceeds ``context.max_speed`` (the peak of the quintic is 15/8 of the
    mean)."""
    dq = inverse_kinematics(context.geometry, R1, t1) - inverse_kinematics(
        context.geometry, R0, t0)
    T = max(QUINTIC_PEAK_SPEED * float(np.abs(dq).max()) / context.max_speed, 1e-3)
    length = float(np.linalg.norm(t1 - t0))
    angle = float(np.linalg.norm(log_so3(R0.T @ R1)))

    def limits(d: float) -> tuple[float, float]:  # speed and acceleration giving T
        if d <= 0.0:
            return 1.0, 1.0
        return QUINTIC_PEAK_SPEED * d / T, 2.0 * QUINTIC_PEAK_ACCELERATION * d / T**2

    v, a = limits(length)
    w, alpha = limits(angle)
    return PoseTrajectory("line", "quintic", R0, t0, v, a, goal_rotation=R1,
                          goal_translation=t1, angular_speed=w, angular_acceleration=alpha)


def encoder_readings(observation: Observation, stroke: tuple[float, float] | None = None
                     ) -> tuple[float, np.ndarray, np.ndarray] | str:
    """The time [s], lengths [m] and leg velocities [m/s] of an observation, or why they
    cannot be used (missing leg velocities, not 6 values, a non-finite value, and with
    the nominal robot's ``stroke`` [m] lengths no leg of it can have:
    :func:`controllers.plausible.implausible_lengths`)."""
    t = float(observation.t)
    q = np.asarray(observation.lengths, dtype=float)
    if observation.q_dot is None:
        return ("needs the measured leg velocities (Observation.q_dot), which only the "
                "dynamic world gives")
    qd = np.asarray(observation.q_dot, dtype=float)
    if q.shape != (6,) or qd.shape != (6,):
        return (f"lengths and leg velocities: expected 6 values each, got shapes {q.shape} "
                f"and {qd.shape}")
    if not (math.isfinite(t) and math.isfinite(float(q @ q + qd @ qd))):
        # a NaN or inf makes the sum of squares so (as do values near overflow)
        for what, x in (("time", np.array([t])), ("lengths", q), ("leg velocities", qd)):
            if x.size == 0 or not np.isfinite(x).all():
                return f"measured {what} not finite: {x}"
    wrong = None if stroke is None else implausible_lengths(q, stroke)
    return (t, q, qd) if wrong is None else f"measured lengths: {wrong}"


def camera_and_base_points(controller: str, context: ControllerContext
                           ) -> tuple[Transform, np.ndarray]:
    """The estimated camera pose ``camera_from_base`` and base points (6, 3) [m].

    Raises:
        ContextError: No camera pose, or base points not (6, 3) finite or not
            plausible (:func:`~controllers.law_tools.base_points_of`).
    """
    cam = getattr(context.camera, "camera_from_base", None)
    if not isinstance(cam, Transform):
        raise ContextError(controller, "camera", "needs the estimated camera with its "
                           "camera_from_base pose")
    return cam, base_points_of(controller, context)


def goal_pose_of(controller: str, goal: Goal, geometry: HexapodGeometry | None = None
                 ) -> tuple[np.ndarray, np.ndarray]:
    """``goal.rotation`` and ``goal.translation``, checked: finite, a rotation (``R^T R``
    within :data:`hexapod.kinematics.ROTATION_TOLERANCE` of the identity, determinant
    positive) and, with the nominal ``geometry``, not a pose that puts a leg where none of
    the robot can be (:func:`controllers.plausible.implausible_pose`).

    Raises:
        ContextError: Missing, not finite, not a rotation, or not a pose of the robot.
    """
    if goal.rotation is None or goal.translation is None:
        raise ContextError(controller, "goal.rotation/translation", "missing")
    R = np.asarray(goal.rotation, dtype=float)
    t = np.asarray(goal.translation, dtype=float)
    if R.shape != (3, 3) or t.shape != (3,) or not (np.all(np.isfinite(R))
                                                    and np.all(np.isfinite(t))):
        raise ContextError(controller, "goal.rotation/translation",
                           f"expected a finite (3, 3) rotation and (3,) position, got "
                           f"{R.shape} and {t.shape}")
    try:
        check_rotations(R)
    except ShapeError as exc:
        raise ContextError(controller, "goal.rotation", f"not a rotation matrix ({exc.got})"
                           ) from None
    if geometry is not None and (problem := implausible_pose(geometry, R, t)) is not None:
        raise ContextError(controller, "goal.rotation/translation", problem)
    return R, t
