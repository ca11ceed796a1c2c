"""Prediction models of the visual predictive controllers (Allibert, Courtial & Chaumette 2010).

Two models predict the leg features over the horizon from what a controller knows
(the :class:`~controllers.base.ControllerContext` estimates and the current
:class:`~controllers.base.Observation`), never from the simulator's truth:

- **local** (Allibert's local model): the stacked error is propagated linearly with
  the interaction matrix of the current (or desired) features,
  ``e_k = e_0 + L s_k`` with the twist displacement ``s_k = dt sum_{j<k} tau_j``
  (``docs/math.md`` section 6), and the leg lengths with the inverse Jacobian of the
  measured directions, ``q_k = q_0 + J_inv s_k`` (section 3). Exact to first order
  in the motion; its error grows with the displacement (quadratically).
- **global**: the platform pose in the camera frame is reconstructed from the
  estimated base points ``A_i``, the measured lengths ``q_i`` and the observed
  directions ``u_i``: each leg gives ``B_i = A_i + q_i u_i`` (section 1) and the pose
  ``(R, t)`` is the rigid fit (Kabsch) of the nominal platform points ``eB_i`` onto
  them. It is propagated with the nominal kinematics, the twist integrated on SE(3)
  (left product with ``exp(dt tau)``, section 2), and the features are predicted from
  it by the estimated camera model: leg directions and lengths from
  ``q_i u_i = R eB_i + t - A_i``, edge normals by section 4, image lines by
  section 5 (``l = Kt^-T n / |Kt^-T n|`` with the camera's ``line_matrix`` ``Kt``). In
  a world without calibration error it reproduces the true features to rounding.

The expressions are CasADi SX, shared by the tests (:class:`GlobalModel`,
:class:`LocalModel`, evaluated by the CasADi virtual machine) and by the compiled
problem kernel of :mod:`controllers.mpc.problem`.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import casadi as ca
import numpy as np

from controllers.tasks.base import sx_skew
from controllers.tasks.feature_kind import BuiltinFeature
from controllers.tasks.leg_direction import LEG_DIRECTIONS
from controllers.tasks.leg_edge import EDGE_LINES, EDGE_NORMALS, sx_edge_normals

#: The features the predictive controllers predict: image lines (perspective edges),
#: edge normals, leg directions.
FEATURE_KINDS = (EDGE_LINES, EDGE_NORMALS, LEG_DIRECTIONS)

__all__ = ["FEATURE_KINDS", "GlobalModel", "LocalModel", "fit_pose",
           "platform_points_from_legs", "sx_edge_normals", "sx_exp_se3", "sx_legs",
           "sx_limb_ends", "sx_pixel", "sx_step_pose"]


# --------------------------------------------------------------------------- numpy
def fit_pose(points: np.ndarray, model_points: np.ndarray,
             weights: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Rigid fit ``(R, t) = argmin sum_i w_i |R m_i + t - p_i|^2`` (Kabsch, proper rotation).

    Args:
        points: (n, 3) target points ``p_i`` (camera frame) [m].
        model_points: (n, 3) model points ``m_i`` (body frame) [m].
        weights: (n,) non-negative weights (default: ones); at least three points
            with positive weight, not collinear.

    Returns:
        ``R`` (3, 3) and ``t`` (3,) [m].
    """
    p = np.asarray(points, dtype=float)
    m = np.asarray(model_points, dtype=float)
    w = np.ones(len(p)) if weights is None else np.asarray(weights, dtype=float)
    sw = float(w.sum())
    pc = (w @ p) / sw
    mc = (w @ m) / sw
    C = ((p - pc) * w[:, None]).T @ (m - mc)
    U, _, Vt = np.linalg.svd(C)
    D = np.diag([1.0, 1.0, float(np.sign(np.linalg.det(U @ Vt)) or 1.0)])
    R = U @ D @ Vt
    return R, pc - R @ mc


def platform_points_from_legs(base_points: np.ndarray, lengths: np.ndarray,
                              directions: np.ndarray) -> np.ndarray:
    """``B_i = A_i + q_i u_i`` (6, 3) in the camera frame [m] (``docs/math.md`` section 1)."""
    return np.asarray(base_points) + np.asarray(lengths)[:, None] * np.asarray(directions)


# --------------------------------------------------------------------------- SX blocks
def sx_exp_se3(v: ca.SX, w: ca.SX) -> tuple[ca.SX, ca.SX]:
    """SE(3) exponential of the twist displacement ``(v, w)`` [m, rad] (``hexapod.se3``).

    ``R = I + a K + b K^2``, ``p = (I + b K + c K^2) v`` with ``K = [w]_x``,
    ``a = sin(th)/th``, ``b = (1 - cos(th))/th^2``, ``c = (th - sin(th))/th^3``; Taylor
    series below ``th = 1e-3`` rad (truncation below 1e-16 there).
    """
    th2 = ca.dot(w, w)
    th = ca.sqrt(th2)
    small = th < 1e-3
    ths = ca.if_else(small, 1.0, th)
    a = ca.if_else(small, 1 - th2 / 6 + th2 * th2 / 120, ca.sin(ths) / ths)
    b = ca.if_else(small, 0.5 - th2 / 24 + th2 * th2 / 720, (1 - ca.cos(ths)) / (ths * ths))
    c = ca.if_else(small, 1.0 / 6 - th2 / 120 + th2 * th2 / 5040,
                   (ths - ca.sin(ths)) / (ths * ths * ths))
    K = sx_skew(w)
    K2 = K @ K
    eye = ca.SX.eye(3)
    return eye + a * K + b * K2, (eye + b * K + c * K2) @ v


def sx_step_pose(R: ca.SX, t: ca.SX, tau: ca.SX, dt: ca.SX | float) -> tuple[ca.SX, ca.SX]:
    """Pose after a constant twist ``tau = (v, w)`` (camera frame) during ``dt``:
    ``exp(dt tau) (R, t)`` (``docs/math.md`` section 2)."""
    dR, dp = sx_exp_se3(dt * tau[:3], dt * tau[3:])
    return dR @ R, dR @ t + dp


def sx_legs(R: ca.SX, t: ca.SX, A: list[ca.SX], E: list[ca.SX]
            ) -> tuple[list[ca.SX], list[ca.SX], list[ca.SX]]:
    """Lengths, unit directions and platform points of the six legs at the pose ``(R, t)``.

    ``B_i = R eB_i + t``, ``q_i = |B_i - A_i|``, ``u_i = (B_i - A_i) / q_i``.
    """
    qs, us, Bs = [], [], []
    for Ai, Ei in zip(A, E, strict=True):
        B = R @ Ei + t
        d = B - Ai
        q = ca.sqrt(ca.dot(d, d))
        qs.append(q)
        us.append(d / q)
        Bs.append(B)
    return qs, us, Bs


def sx_limb_ends(A: ca.SX, B: ca.SX, n: ca.SX, r: ca.SX | float) -> tuple[ca.SX, ca.SX]:
    """Ends of an edge segment ``A + r n`` and ``B + r n`` (``vision.legs.limb_points``)."""
    return A + r * n, B + r * n


def sx_pixel(X: ca.SX, K: ca.SX) -> ca.SX:
    """Pinhole pixel ``(u, v)`` of a camera-frame point, ``p ~ K X`` [px]."""
    return ca.vertcat(K[0, 0] * X[0] / X[2] + K[0, 1] * X[1] / X[2] + K[0, 2],
                      K[1, 1] * X[1] / X[2] + K[1, 2])


# --------------------------------------------------------------------------- models
@lru_cache(maxsize=16)
def _rollout_function(feature: BuiltinFeature, steps: int) -> ca.Function:
    """Features and lengths after each of ``steps`` periods (global model), one SX function.

    Inputs: ``R0`` (3, 3), ``t0`` (3), ``taus`` (6, steps), ``dt``, ``A`` (3, 6),
    ``E`` (3, 6), ``r``, ``Kit`` (3, 3). Outputs: features (3 * nf, steps + 1) and
    lengths (6, steps + 1), column 0 at the fitted pose.
    """
    R = ca.SX.sym("R", 3, 3)
    t = ca.SX.sym("t", 3)
    taus = ca.SX.sym("taus", 6, steps)
    dt = ca.SX.sym("dt")
    Am = ca.SX.sym("A", 3, 6)
    Em = ca.SX.sym("E", 3, 6)
    r = ca.SX.sym("r")
    Kit = ca.SX.sym("Kit", 3, 3)
    A = [Am[:, i] for i in range(6)]
    E = [Em[:, i] for i in range(6)]
    feats, lens = [], []
    Rk, tk = R, t
    for k in range(steps + 1):
        q, u, _ = sx_legs(Rk, tk, A, E)
        feats.append(ca.vertcat(*feature.sx_of_legs(u, A, r, Kit)))
        lens.append(ca.vertcat(*q))
        if k < steps:
            Rk, tk = sx_step_pose(Rk, tk, taus[:, k], dt)
    return ca.Function(f"mpc_rollout_{feature.kind}_{steps}", [R, t, taus, dt, Am, Em, r, Kit],
                       [ca.horzcat(*feats), ca.horzcat(*lens)])


@dataclass
class GlobalModel:
    """The global prediction model: pose fit, SE(3) integration, features by the camera model.

    Attributes:
        feature: One of :data:`FEATURE_KINDS`.
        base_points: (6, 3) estimated ``A_i`` in the camera frame [m].
        platform_points: (6, 3) nominal ``eB_i`` in the platform frame [m].
        radius: Nominal leg radius [m].
        line_matrix: ``Kt`` (3, 3) of the estimated perspective camera (lines only).
    """

    feature: BuiltinFeature
    base_points: np.ndarray
    platform_points: np.ndarray
    radius: float
    line_matrix: np.ndarray | None = None

    @property
    def line_inv_t(self) -> np.ndarray:
        """``Kt^-T`` (identity when the features are not lines)."""
        if self.line_matrix is None:
            return np.eye(3)
        return self.feature.line_inv_t(self.line_matrix)

    def fit(self, lengths: np.ndarray, directions: np.ndarray,
            known: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Platform pose ``(R, t)`` in the camera frame from ``B_i = A_i + q_i u_i``.

        Args:
            lengths: (6,) measured lengths [m].
            directions: (6, 3) observed leg directions.
            known: (6,) legs whose direction is known (at least three).
        """
        B = platform_points_from_legs(self.base_points, lengths, directions)
        w = np.ones(6) if known is None else np.asarray(known, dtype=float)
        B = np.where(w[:, None] > 0, B, 0.0)
        return fit_pose(B, self.platform_points, w)

    def rollout(self, rotation: np.ndarray, translation: np.ndarray, taus: np.ndarray,
                dt: float) -> tuple[np.ndarray, np.ndarray]:
        """Features and lengths predicted after each period of a twist sequence.

        Args:
            rotation: (3, 3) fitted platform orientation in the camera frame.
            translation: (3,) fitted platform position in the camera frame [m].
            taus: (k, 6) twists ``(v [m/s], w [rad/s])`` in the camera frame.
            dt: Period [s].

        Returns:
            Features (k + 1, nf, 3) and lengths (k + 1, 6) [m], index 0 at the given pose.
        """
        taus = np.atleast_2d(np.asarray(taus, dtype=float))
        f = _rollout_function(self.feature, len(taus))
        feats, lens = f(rotation, translation, taus.T, dt, self.base_points.T,
                        self.platform_points.T, self.radius, self.line_inv_t)
        nf = self.feature.units
        return (np.asarray(feats).T.reshape(len(taus) + 1, nf, 3),
                np.asarray(lens).T.reshape(len(taus) + 1, 6))


@dataclass
class LocalModel:
    """Allibert's local model: ``e_k = e_0 + L s_k``, ``q_k = q_0 + J_inv s_k``,
    ``s_k = dt sum_{j<k} tau_j`` with ``L`` and ``J_inv`` frozen at the current (or
    desired) features.

    Attributes:
        interaction: (m, 6) stacked interaction matrix ``L`` of the error.
        inverse_jacobian: (6, 6) ``J_inv`` of the measured directions.
    """

    interaction: np.ndarray
    inverse_jacobian: np.ndarray

    def rollout(self, error: np.ndarray, lengths: np.ndarray, taus: np.ndarray, dt: float
                ) -> tuple[np.ndarray, np.ndarray]:
        """Errors (k + 1, m) and lengths (k + 1, 6) after each period (index 0: now)."""
        taus = np.atleast_2d(np.asarray(taus, dtype=float))
        s = np.vstack([np.zeros(6), dt * np.cumsum(taus, axis=0)])
        return (np.asarray(error).reshape(-1) + s @ self.interaction.T,
                np.asarray(lengths) + s @ self.inverse_jacobian.T)
