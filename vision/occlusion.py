"""Occlusion of edge points by the leg cylinders, compiled to C.

The test is the one of :func:`vision.legs.occluded_by_legs` (the segment from
the projection centre to a point crosses a solid finite cylinder of another
leg: intersection of three intervals of the ray parameter), written once as a
CasADi expression for one point against the six legs and compiled to C by
:mod:`hexapod.compiled`; the batch of points is looped over in C. It is about
ten times faster than the numpy broadcast, and tested equal to it.
"""

from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np

from hexapod.compiled import CompiledFunction

#: Input layout of the compiled test: P (3), own leg index (1), radius (1),
#: then per leg A (3), u (3), q (1).
N_IN = 5 + 6 * 7


def _expression() -> ca.Function:
    x = ca.SX.sym("x", N_IN)
    P = x[0:3]
    own = x[3]
    r = x[4]
    hits = []
    for j in range(6):
        base = 5 + 7 * j
        A = x[base:base + 3]
        u = x[base + 3:base + 6]
        q = x[base + 6]
        Pu = ca.dot(P, u)
        Au = ca.dot(A, u)
        Pp = P - Pu * u
        Ap = A - Au * u
        a = ca.dot(Pp, Pp)
        b = -2.0 * ca.dot(Pp, Ap)
        c = ca.dot(Ap, Ap) - r * r
        disc = b * b - 4.0 * a * c
        sq = ca.sqrt(ca.fmax(disc, 0.0))
        a_safe = ca.if_else(a > 0, a, 1.0)
        par = a <= 1e-300
        s1 = ca.if_else(par, ca.if_else(c < 0, -ca.inf, ca.inf), (-b - sq) / (2.0 * a_safe))
        s2 = ca.if_else(par, ca.if_else(c < 0, ca.inf, -ca.inf), (-b + sq) / (2.0 * a_safe))
        hit_cyl = ca.logic_or(disc > 0, par)
        Pu_safe = ca.if_else(Pu != 0, Pu, 1.0)
        t0 = Au / Pu_safe
        t1 = (Au + q) / Pu_safe
        flat = Pu == 0
        inside_ax = ca.logic_and(-Au >= 0, -Au <= q)
        lo_ax = ca.if_else(flat, ca.if_else(inside_ax, -ca.inf, ca.inf),
                           ca.if_else(Pu > 0, t0, t1))
        hi_ax = ca.if_else(flat, ca.if_else(inside_ax, ca.inf, -ca.inf),
                           ca.if_else(Pu > 0, t1, t0))
        lo = ca.fmax(ca.fmax(s1, lo_ax), 0.0)
        hi = ca.fmin(ca.fmin(s2, hi_ax), 1.0 - 1e-9)
        hits.append(ca.logic_and(ca.logic_and(hit_cyl, lo < hi), own != j))
    out = hits[0]
    for h in hits[1:]:
        out = ca.logic_or(out, h)
    return ca.Function("hexapod_leg_occlusion", [x], [out])


@lru_cache(maxsize=1)
def _compiled() -> CompiledFunction:
    return CompiledFunction(_expression())


def occluded_by_legs_compiled(
    points: np.ndarray,
    base_points: np.ndarray,
    directions: np.ndarray,
    lengths: np.ndarray,
    radius: float,
) -> np.ndarray:
    """Whether the segments from the projection centre to edge points cross another leg.

    Same contract as :func:`vision.legs.occluded_by_legs` with ``exclude_own=True``.

    Args:
        points: (..., 6, 2, N, 3) points on the edges of leg ``i`` (camera frame) [m].
        base_points: (..., 6, 3) [m]; directions: (..., 6, 3); lengths: (..., 6) [m].
        radius: Leg radius [m].

    Returns:
        (..., 6, 2, N) bool.
    """
    P = np.asarray(points, dtype=float)
    lead = P.shape[:-4]
    n = P.shape[-2]
    legs = np.concatenate([np.broadcast_to(base_points, (*lead, 6, 3)),
                           np.broadcast_to(directions, (*lead, 6, 3)),
                           np.broadcast_to(lengths, (*lead, 6))[..., None]], axis=-1)
    rows = np.empty((*lead, 6, 2, n, N_IN))
    rows[..., 0:3] = P
    rows[..., 3] = np.arange(6)[:, None, None]
    rows[..., 4] = radius
    rows[..., 5:] = legs.reshape(*lead, 1, 1, 1, 42)
    out = _compiled().batch(rows.reshape(-1, N_IN))
    return out.reshape(*lead, 6, 2, n) > 0.5
