"""The leg-edge law's per-step core (all twelve edges visible, CURRENT interaction), in C.

From the measured features (pixel lines or normals), the desired ones, the
estimated base points and the measured lengths, one call computes the error
``e = f x f*`` (36,), the normal equations ``N = L^T L`` (6, 6) and ``b = L^T e``
(6,) of the stacked rank-one edge blocks (``L_ij = a g^T``, see
:func:`controllers.interaction.edge_line_factors` and
:func:`~controllers.interaction.edge_normal_factors`), and the leg directions
rebuilt from the edges. It is the same arithmetic as the numpy path of
:class:`controllers.leg_edge.LegEdgeController` (tested equal), written once as a
CasADi expression and compiled to C by :mod:`hexapod.compiled`: one call of a
few microseconds instead of some sixty numpy calls.

Input layout (114): features (12 x 3), desired features (12 x 3), the line
matrix ``K`` and ``K^-1`` (3 x 3 each, row-major; identities for normals), base
points (6 x 3), lengths (6). Output (96): ``e`` (36), ``N`` (36, row-major),
``b`` (6), directions (6 x 3).
"""

from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np

from hexapod.compiled import CompiledFunction

N_IN = 36 + 36 + 9 + 9 + 18 + 6
N_OUT = 36 + 36 + 6 + 18


def _unit(v: ca.SX) -> ca.SX:
    return v / ca.sqrt(ca.dot(v, v))


def _expression(use_lines: bool) -> ca.Function:
    x = ca.SX.sym("x", N_IN)
    feat = [x[3 * k:3 * k + 3] for k in range(12)]
    star = [x[36 + 3 * k:36 + 3 * k + 3] for k in range(12)]
    Kt = ca.reshape(x[72:81], 3, 3)  # column-major read of a row-major K: K^T
    Kinv_t = ca.reshape(x[81:90], 3, 3)  # (K^-1)^T
    A = [x[90 + 3 * i:90 + 3 * i + 3] for i in range(6)]
    q = [x[108 + i] for i in range(6)]
    n = [_unit(Kt @ f) if use_lines else f for f in feat]
    u = [_unit(ca.cross(n[2 * i + 1], n[2 * i])) for i in range(6)]
    e = [ca.cross(feat[k], star[k]) for k in range(12)]
    N = ca.SX.zeros(6, 6)
    b = ca.SX.zeros(6, 1)
    for k in range(12):
        i = k // 2
        nk, ui, Ai, qi = n[k], u[i], A[i], q[i]
        w = ca.cross(ui, nk)
        z = ui - w * (ca.dot(Ai, ui) / ca.dot(Ai, w))
        r = nk - ca.dot(nk, ui) * ui
        B = Ai + qi * ui
        g = ca.vertcat(r / qi, ca.cross(B, r) / qi)
        if use_lines:
            lk = feat[k]
            y = Kinv_t @ z
            y = y - lk * ca.dot(lk, y)
            y = y * ca.sqrt(ca.dot(Kt @ lk, Kt @ lk))
            a = ca.cross(star[k], y)
        else:
            a = ca.cross(star[k], z)
        N += ca.dot(a, a) * (g @ g.T)
        b += ca.dot(a, e[k]) * g
    out = ca.vertcat(*e, ca.reshape(N.T, 36, 1), b, *u)
    name = "hexapod_edge_law_lines" if use_lines else "hexapod_edge_law_normals"
    return ca.Function(name, [x], [out])


@lru_cache(maxsize=2)
def edge_kernel(use_lines: bool) -> CompiledFunction:
    """The compiled kernel for pixel lines (True) or normals (False)."""
    return CompiledFunction(_expression(use_lines))


def pack(features: np.ndarray, desired: np.ndarray, K: np.ndarray, K_inv: np.ndarray,
         base_points: np.ndarray, lengths: np.ndarray, out: np.ndarray | None = None
         ) -> np.ndarray:
    """The input vector (114,) of the kernel."""
    x = np.empty(N_IN) if out is None else out
    x[0:36] = features.reshape(36)
    x[36:72] = desired.reshape(36)
    x[72:81] = K.reshape(9)
    x[81:90] = K_inv.reshape(9)
    x[90:108] = base_points.reshape(18)
    x[108:114] = lengths
    return x
