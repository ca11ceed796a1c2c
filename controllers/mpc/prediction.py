"""Prediction models of the visual predictive controllers (Allibert, Courtial & Chaumette
2010; ``docs/math.md`` section 6, "Predictive variant"), from the controller's estimates
only: the **local** model propagates the error with the interaction matrix and the
lengths with the inverse Jacobian; the **global** model fits the platform pose to ``B_i
= A_i + q_i u_i`` (:func:`fit_pose`), moves it by ``exp(dt tau)`` (:func:`sx_exp_se3`) and
predicts the features through the estimated camera (:func:`sx_legs`, the feature's
``sx_of_legs``). The CasADi SX blocks of :mod:`controllers.mpc.problem`.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from controllers.tasks.leg_direction import LEG_DIRECTIONS
from controllers.tasks.leg_edge import EDGE_LINES, EDGE_NORMALS

#: The features the predictive controllers predict: image lines (perspective edges),
#: edge normals, leg directions.
FEATURE_KINDS = (EDGE_LINES, EDGE_NORMALS, LEG_DIRECTIONS)

__all__ = ["FEATURE_KINDS", "fit_pose", "sx_exp_se3", "sx_legs", "sx_pixel"]


def fit_pose(points: np.ndarray, model_points: np.ndarray,
             weights: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Rigid fit ``(R, t) = argmin sum_i w_i |R m_i + t - p_i|^2`` [m] (Kabsch, a proper
    rotation) of model points ``m_i`` (n, 3) to points ``p_i`` (n, 3), the weights (n,)
    non-negative (default: ones; three non-collinear points of positive weight)."""
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
    K = ca.skew(w)
    K2 = K @ K
    eye = ca.SX.eye(3)
    return eye + a * K + b * K2, (eye + b * K + c * K2) @ v


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


def sx_pixel(X: ca.SX, K: ca.SX) -> ca.SX:
    """Pinhole pixel ``(u, v)`` of a camera-frame point, ``p ~ K X`` [px]."""
    return ca.vertcat(K[0, 0] * X[0] / X[2] + K[0, 1] * X[1] / X[2] + K[0, 2],
                      K[1, 1] * X[1] / X[2] + K[1, 2])
