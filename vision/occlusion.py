"""Occlusion of edge points by the leg cylinders and the platform disc.

:func:`occluded_by_legs` and :func:`occluded_by_disc` are the numpy tests (the segment
from the projection centre to a point crosses a solid finite cylinder of another leg:
intersection of three intervals of the ray parameter; or crosses the platform disc),
re-exported by :mod:`vision.legs`. :func:`occluded_by_legs_compiled` is the leg test
written once as a CasADi expression for one point against the six legs and compiled to
C by :mod:`hexapod.compiled`; the batch of points is looped over in C. It is about ten
times faster than the numpy broadcast, and tested equal to it.
"""

from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np

from hexapod.compiled import CompiledFunction, Layout

#: One leg in the compiled test's input: its base point ``A`` [m], direction ``u`` and
#: length ``q`` [m] (camera frame).
LEG = Layout([("A", 3), ("u", 3), ("q", ())], "leg")
#: The compiled test's input row: the point ``P`` (camera frame) [m], the index of its
#: own leg, the leg radius [m], then the six legs (:data:`LEG`).
INPUTS = Layout([("P", 3), ("own", ()), ("radius", ()), ("legs", (6, LEG.size))],
                "leg occlusion input")
#: Its output: 1 where the segment crosses another leg, else 0.
OUTPUTS = Layout([("occluded", ())], "leg occlusion output")


def _expression() -> ca.Function:
    x = ca.SX.sym("x", INPUTS.size)
    row = INPUTS.split(x)
    P, own, r, legs = row["P"], row["own"], row["radius"], row["legs"]
    hits = []
    for j in range(6):
        leg = LEG.split(legs[j * LEG.size:(j + 1) * LEG.size])
        A, u, q = leg["A"], leg["u"], leg["q"]
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
    return CompiledFunction(_expression(), inputs=INPUTS, outputs=OUTPUTS)


def occluded_by_legs_compiled(
    points: np.ndarray,
    base_points: np.ndarray,
    directions: np.ndarray,
    lengths: np.ndarray,
    radius: float,
) -> np.ndarray:
    """Whether the segments from the projection centre to edge points cross another leg.

    Same contract as :func:`occluded_by_legs` with ``exclude_own=True``.

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
    rows = np.empty((*lead, 6, 2, n, INPUTS.size))
    row = INPUTS.views(rows)
    row["P"][...] = P
    row["own"][...] = np.arange(6)[:, None, None]
    row["radius"][...] = radius
    row["legs"][...] = legs.reshape(*lead, 1, 1, 1, 6, LEG.size)
    out = _compiled().batch(rows.reshape(-1, INPUTS.size))
    return out.reshape(*lead, 6, 2, n) > 0.5


def occluded_by_legs(
    points: np.ndarray,
    base_points: np.ndarray,
    directions: np.ndarray,
    lengths: np.ndarray,
    radius: float,
    exclude_own: bool = True,
) -> np.ndarray:
    """Whether the segments from the projection centre to points cross a leg.

    Each leg is a solid finite cylinder of radius ``r`` around the segment
    ``A_j .. A_j + q_j u_j``. The intersection of the open segment ``s' P``,
    ``s'`` in ``(0, 1)``, with it is the intersection of three intervals of ``s'``:
    inside the infinite cylinder (a quadratic), between the two end planes, and
    ``(0, 1)``.

    Args:
        points: (..., 6, 2, N, 3) points of the edges of leg ``i`` (camera frame).
        base_points, directions, lengths: the legs, (..., 6, 3), (..., 6, 3), (..., 6).
        radius: Leg radius [m].
        exclude_own: Skip leg ``i`` for the points of leg ``i`` (its limbs are
            tangent to it, never hidden by it).

    Returns:
        (..., 6, 2, N) bool.
    """
    P = np.asarray(points, float)[..., None, :]  # (..., 6i, 2, N, 1, 3)
    lead = P.shape[:-5]
    A = np.broadcast_to(base_points, (*lead, 6, 3)).reshape(*lead, 1, 1, 1, 6, 3)
    u = np.broadcast_to(directions, (*lead, 6, 3)).reshape(*lead, 1, 1, 1, 6, 3)
    q = np.broadcast_to(lengths, (*lead, 6)).reshape(*lead, 1, 1, 1, 6)
    Pu = np.sum(P * u, axis=-1)  # (..., 6i, 2, N, 6j)
    Au = np.sum(A * u, axis=-1)  # (..., 1, 1, 1, 6j)
    Pp = P - Pu[..., None] * u
    Ap = A - Au[..., None] * u
    a = np.sum(Pp * Pp, axis=-1)
    b = -2.0 * np.sum(Pp * Ap, axis=-1)
    c = np.sum(Ap * Ap, axis=-1) - radius * radius
    disc = b * b - 4.0 * a * c
    with np.errstate(invalid="ignore", divide="ignore"):
        sq = np.sqrt(np.where(disc > 0, disc, 0.0))
        a_safe = np.where(a > 0, a, 1.0)
        s1 = (-b - sq) / (2.0 * a_safe)
        s2 = (-b + sq) / (2.0 * a_safe)
        # Ray parallel to the axis (a == 0): inside for every s' iff c < 0.
        par = a <= 1e-300
        s1 = np.where(par, np.where(c < 0, -np.inf, np.inf), s1)
        s2 = np.where(par, np.where(c < 0, np.inf, -np.inf), s2)
        hit_cyl = (disc > 0) | par
        # Axial interval: 0 <= s' Pu - Au <= q.
        Pu_safe = np.where(Pu != 0, Pu, 1.0)
        t0 = Au / Pu_safe
        t1 = (Au + q) / Pu_safe
        lo_ax = np.where(Pu > 0, t0, t1)
        hi_ax = np.where(Pu > 0, t1, t0)
        flat = Pu == 0
        inside_ax = (-Au >= 0) & (-Au <= q)
        lo_ax = np.where(flat, np.where(inside_ax, -np.inf, np.inf), lo_ax)
        hi_ax = np.where(flat, np.where(inside_ax, np.inf, -np.inf), hi_ax)
    lo = np.maximum(np.maximum(s1, lo_ax), 0.0)
    hi = np.minimum(np.minimum(s2, hi_ax), 1.0 - 1e-9)
    hit = hit_cyl & (lo < hi)
    if exclude_own:
        hit &= ~np.eye(6, dtype=bool)[:, None, None, :]
    return np.any(hit, axis=-1)


def occluded_by_disc(
    points: np.ndarray, centre: np.ndarray, normal: np.ndarray, disc_radius: float
) -> np.ndarray:
    """Whether the segments from the projection centre to points cross a disc.

    Args:
        points: (..., 6, 2, N, 3) camera-frame points.
        centre: (..., 3) disc centre.
        normal: (..., 3) unit disc normal.
        disc_radius: [m].

    Returns:
        (..., 6, 2, N) bool.
    """
    P = np.asarray(points, float)
    c = np.asarray(centre, float)[..., None, None, None, :]
    nd = np.asarray(normal, float)[..., None, None, None, :]
    den = np.sum(nd * P, axis=-1)
    num = np.sum(nd * c, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        s = num / np.where(den != 0, den, np.nan)
    X = s[..., None] * P
    d2 = np.sum((X - c) ** 2, axis=-1)
    with np.errstate(invalid="ignore"):
        return (s > 0) & (s < 1.0 - 1e-9) & (d2 <= disc_radius**2)
