"""The numpy oracle of the model-based pose servo (:mod:`controllers.model_based`).

The controller computes its command with one CasADi function
(:func:`controllers.model_based.pose_servo_kernel`); this module is the numpy step it
replaced (``hexapod.se3.log_so3`` with its half-turn branch, the gain, the twist, the
nominal inverse Jacobian, ``np.linalg.cond`` and ``twist_to_frame``), kept as the
reference the kernel is tested against.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from controllers.law_tools import Gain
from hexapod.kinematics import Transform, twist_to_frame
from hexapod.se3 import log_so3


@dataclass
class ServoStep:
    """The oracle's command.

    Attributes:
        velocities: (6,) leg velocities [m/s].
        twist: (6,) the twist in the camera frame [m/s, rad/s], or None without a camera.
        error: (6,) pose error ``(t - t*, -log(R* R^T))`` [m, rad].
        error_norm: ``|error|``.
        condition: Condition number of the nominal inverse Jacobian.
    """

    velocities: np.ndarray
    twist: np.ndarray | None
    error: np.ndarray
    error_norm: float
    condition: float


def numpy_pose_servo(R: np.ndarray, t: np.ndarray, R_star: np.ndarray, t_star: np.ndarray,
                     base_points: np.ndarray, platform_points: np.ndarray, gain: Gain,
                     camera_from_base: Transform | None) -> ServoStep:
    """The pose servo at the estimated pose ``(R, t)`` toward ``(R*, t*)`` (base frame).

    Args:
        R, t: The forward kinematics' pose [m].
        R_star, t_star: The goal pose [m].
        base_points: (6, 3) nominal ``A_i`` [m].
        platform_points: (6, 3) nominal ``E_i`` in the platform frame [m].
        gain: The controller's gain.
        camera_from_base: Where the twist is also expressed, or None.
    """
    rot = log_so3(R_star @ R.T)
    dp = t_star - t
    e = np.concatenate([-dp, -rot])
    lam = gain(float(np.abs(e).max()))
    w = lam * rot
    v = lam * dp - np.cross(w, t)
    tau = np.concatenate([v, w])
    legs = platform_points @ R.T + t - base_points
    u = legs / np.linalg.norm(legs, axis=1, keepdims=True)
    J = np.hstack([u, np.cross(base_points, u)])
    twist = None if camera_from_base is None else twist_to_frame(tau, camera_from_base)
    return ServoStep(J @ tau, twist, e, math.sqrt(float(e @ e)), float(np.linalg.cond(J)))
