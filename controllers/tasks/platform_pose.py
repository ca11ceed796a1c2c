"""Platform-pose task (the model-based baseline's error, ``docs/math.md`` section 6):
``e = (t - t*, log(R R*^T))`` with the twist ``(v, w)`` in the frame of the pose, at its
origin (``t_dot = v + w x t``, ``R_dot = [w]_x R``):

``L = [[I, -[t]_x], [0, J_l^-1(phi)]]`` with ``phi = log(R R*^T)`` and the inverse left
Jacobian of SO(3) ``J_l^-1(phi) = I - [phi]_x / 2 + (1/theta^2 - (1 + cos theta) /
(2 theta sin theta)) [phi]_x^2``. Valid away from a half-turn of orientation error.
"""

from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np

from controllers.tasks.base import (
    Task,
    TaskState,
    map_blocks,
    reference_function,
    second_order_function,
)
from controllers.tasks.feature_kind import BuiltinFeature
from hexapod.compiled import Layout, Shape
from hexapod.se3 import log_so3, skew


def _log_so3(R: ca.SX) -> ca.SX:
    """:func:`hexapod.se3.log_so3` away from a half-turn, as an expression (its series
    ``theta / (2 sin theta) = 1/2 + sin^2 theta / 12`` near zero, where the closed form
    and its derivatives are 0/0)."""
    cos = (R[0, 0] + R[1, 1] + R[2, 2] - 1.0) / 2.0
    v = ca.vertcat(R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1])
    sin2 = ca.dot(v, v) / 4.0
    theta = ca.atan2(ca.sqrt(sin2), cos)
    factor = ca.if_else(sin2 < 1e-10, 0.5 + sin2 / 12.0, theta / (2.0 * ca.sin(theta)))
    return factor * v


def pose_error(s: ca.SX, p: ca.SX) -> ca.SX:
    """The block error of the state ``s = (R row-major, t)`` (12) towards the parameters
    ``p = (R* row-major, t*)`` (12), as an expression."""
    R = ca.reshape(s[:9], 3, 3).T
    Rs = ca.reshape(p[:9], 3, 3).T
    return ca.vertcat(s[9:12] - p[9:12], _log_so3(R @ Rs.T))


def pose_rate(s: ca.SX, p: ca.SX, tau: ca.SX) -> ca.SX:
    """``s_dot`` of the state ``(R row-major, t)`` moved by the twist ``tau`` of the
    module docstring (``t_dot = v + w x t``, ``R_dot = [w]_x R``)."""
    R = ca.reshape(s[:9], 3, 3).T
    w = tau[3:]
    Rdot = ca.skew(w) @ R
    return ca.vertcat(ca.reshape(Rdot.T, 9, 1), tau[:3] + ca.cross(w, s[9:12]))


def pose_motion(R: np.ndarray, twist: np.ndarray, twist_rate: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """``p_dot`` and ``p_ddot`` (n, 12) of desired poses ``(R*, t*)`` (n, 3, 3) moving
    with a reference's twist ``(v*, w*)`` (n, 6) and its rate (n, 6) (base frame,
    ``v*`` the origin's velocity: ``t*_dot = v*``, ``R*_dot = [w*]_x R*``, so
    ``R*_ddot = ([alpha*]_x + [w*]_x^2) R*``), rotations row-major."""
    R = np.asarray(R, dtype=float)
    n = len(R)
    W = skew(np.asarray(twist, dtype=float)[:, 3:])
    Rd = W @ R
    Rdd = (skew(np.asarray(twist_rate, dtype=float)[:, 3:]) + W @ W) @ R
    return (np.concatenate([Rd.reshape(n, 9), twist[:, :3]], axis=1),
            np.concatenate([Rdd.reshape(n, 9), twist_rate[:, :3]], axis=1))


@lru_cache(maxsize=1)
def _second_order() -> ca.Function:
    # state (R row-major, t), parameters (R* row-major, t*)
    return second_order_function("platform_pose_second_order", 12, 12, pose_error,
                                 pose_rate)


@lru_cache(maxsize=1)
def _reference() -> ca.Function:
    return reference_function("platform_pose_reference", 12, 12, pose_error, pose_rate)


def inverse_left_jacobian(phi: np.ndarray) -> np.ndarray:
    """``J_l^-1(phi)`` (..., 3, 3) of rotation vectors (..., 3): ``phi_dot = J_l^-1 w`` for
    ``R_dot = [w]_x R``."""
    theta = np.linalg.norm(phi, axis=-1)[..., None, None]
    K = skew(phi)
    small = theta < 1e-4
    th = np.where(small, 1.0, theta)
    c = np.where(small, 1.0 / 12.0 + theta**2 / 720.0,
                 1.0 / th**2 - (1.0 + np.cos(th)) / (2.0 * th * np.sin(th)))
    return np.eye(3) - 0.5 * K + c * (K @ K)


class PlatformPoseTask(Task):
    """The platform pose towards a desired pose.

    Args:
        rotation: (3, 3) or (n, 3, 3) desired orientation ``R*``.
        translation: (3,) or (n, 3) desired position ``t*`` [m].
    """

    name = "platform-pose"
    block = 6

    def __init__(self, rotation: np.ndarray, translation: np.ndarray) -> None:
        self.rotation = np.asarray(rotation, dtype=float)
        self.translation = np.asarray(translation, dtype=float)

    def _pose(self, state: TaskState) -> tuple[np.ndarray, np.ndarray]:
        if state.rotation is None or state.translation is None:
            raise ValueError("PlatformPoseTask needs the state's rotation and translation")
        return state.rotation, state.translation

    def _phi(self, R: np.ndarray) -> np.ndarray:
        return log_so3(R @ np.swapaxes(np.broadcast_to(self.rotation, R.shape), -1, -2))

    def error(self, state: TaskState) -> np.ndarray:
        R, t = self._pose(state)
        return np.concatenate([t - self.translation, self._phi(R)], axis=-1)

    def jacobian(self, state: TaskState) -> np.ndarray:
        R, t = self._pose(state)
        n = len(t)
        L = np.zeros((n, 6, 6))
        L[:, :3, :3] = np.eye(3)
        L[:, :3, 3:] = -skew(t)
        L[:, 3:, 3:] = inverse_left_jacobian(self._phi(R))
        return L

    def _rows(self, state: TaskState) -> tuple[np.ndarray, np.ndarray]:
        R, t = self._pose(state)
        n = len(t)
        s = np.concatenate([R.reshape(n, 9), t], axis=1)
        p = np.concatenate([np.broadcast_to(self.rotation, (n, 3, 3)).reshape(n, 9),
                            np.broadcast_to(self.translation, (n, 3))], axis=1)
        return s, p

    def jacobian_dot_twist(self, state: TaskState, twist: np.ndarray) -> np.ndarray:
        s, p = self._rows(state)
        tau = np.asarray(twist, float).reshape(len(s), 6)
        return map_blocks(_second_order(), s, p, tau)[0].reshape(len(s), 6)

    def reference_terms(self, state: TaskState, twist: np.ndarray, rate: np.ndarray,
                        acceleration: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``e_t``, ``e_tt`` (n, 6) of the desired pose moving with the reference's twist
        ``rate`` (n, 6) ``(v*, w*)`` and its rate ``acceleration`` (n, 6) (base frame,
        :func:`pose_motion`)."""
        s, p = self._rows(state)
        n = len(s)
        Rs = np.broadcast_to(self.rotation, (n, 3, 3))
        pd, pdd = pose_motion(Rs, np.asarray(rate, float).reshape(n, 6),
                              np.asarray(acceleration, float).reshape(n, 6))
        e_t, e_tt = map_blocks(_reference(), s, p, np.asarray(twist, float).reshape(n, 6), pd,
                               pdd)
        return e_t.reshape(n, 6), e_tt.reshape(n, 6)


#: A reference pose row: ``R*`` (row-major), ``t*``, the twist and its rate (the pose
#: task's input of a compiled computed-torque step).
REFERENCE = Layout([("R", (3, 3)), ("t", 3), ("twist", 6), ("twist_rate", 6)],
                   "reference pose")


def _row_major(R: ca.SX) -> ca.SX:
    return ca.reshape(R.T, 9, 1)


def _pose_block() -> ca.Function:
    """``(s, p) -> (e, L)`` of the pose task, ``L`` the derivative of ``e`` along
    :func:`pose_rate` (the module's closed form)."""
    s, p, tau = ca.SX.sym("s", 12), ca.SX.sym("p", 12), ca.SX.sym("tau", 6)
    e = pose_error(s, p)
    L = ca.jacobian(ca.jtimes(e, s, pose_rate(s, p, tau)), tau)
    return ca.Function("pose_block", [s, p], [e, L])


class PlatformPose(BuiltinFeature):
    """The platform pose as a feature object
    (:class:`~controllers.tasks.feature_kind.BuiltinFeature`): the square pose task of
    ``cartesian-ctc`` and ``vision-ctc`` (base frame, no hidden rows) and the features of
    ``pose-force-mpc`` (``(t, R column-major)``, 12)."""

    kind = ctc_name = "pose"
    task_rows = 6
    camera_task = False
    visual_pose = True
    force_mpc_name = "hexapod_force_pose_mpc"
    stage_features = 12

    def ctc_blocks(self, fk: bool) -> tuple[tuple[str, Shape], ...]:
        """The ``reference`` pose row (:data:`REFERENCE`); for the visual pose
        (``fk=False``) the legs' ``directions`` (6 x 3), the estimated ``base`` points
        (6 x 3, camera frame), the ``frame`` (the base from the camera, ``R``
        row-major, ``p``: 12) and the legs ``seen`` (6: 1.0 for a leg the fit takes, 0.0
        for a hidden one)."""
        visual = (("directions", (6, 3)), ("base", (6, 3)), ("frame", 12), ("seen", 6)) \
            if not fk else ()
        return (("reference", REFERENCE.size), *visual)

    def sx_ctc_task(self, v: dict[str, ca.SX], q: ca.SX, R: ca.SX, t: ca.SX, tau_s: ca.SX
                    ) -> tuple[ca.SX, ca.SX, ca.SX, ca.SX, ca.SX]:
        ref = v["reference"]
        s = ca.vertcat(_row_major(R), t)
        Rs = ca.reshape(ref[0:9], 3, 3).T
        p = ref[0:12]
        w, alpha = ref[15:18], ref[21:24]
        W = ca.skew(w)
        pd = ca.vertcat(_row_major(W @ Rs), ref[12:15])
        pdd = ca.vertcat(_row_major((ca.skew(alpha) + W @ W) @ Rs), ref[18:21])
        e, L = _pose_block()(s, p)
        e_t, e_tt = _reference()(s, p, tau_s, pd, pdd)
        return e, L, _second_order()(s, p, tau_s), e_t, e_tt

    def sx_stage_features(self, t: ca.SX, R_column_major: ca.SX, normals: list[ca.SX]
                          ) -> ca.SX:
        return ca.vertcat(t, R_column_major)


#: The platform pose.
PLATFORM_POSE = PlatformPose()
