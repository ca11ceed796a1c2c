"""The numpy oracle of the dynamic robots' compiled period: one physics step, readable.

:meth:`hexapod.dynamics.robots.DynamicRobots.advance` runs the period compiled to C
(:mod:`hexapod.dynamics.robots_compiled`, the one implementation); this is the same step
written out in numpy (module docstring of :mod:`hexapod.dynamics.robots`), which the
tests hold the compiled period equal to.
"""

from __future__ import annotations

import numpy as np

from hexapod.dynamics.robots import DynamicRobots, legs
from hexapod.se3 import exp_so3


def leg_bias(twist: np.ndarray, q: np.ndarray, u: np.ndarray, r: np.ndarray) -> np.ndarray:
    """``b = q_ddot - K tau_dot`` (n, 6) [m/s^2]: the legs' acceleration at zero platform
    acceleration, ``u_i . (w x (w x r_i)) + |B_dot_i - q_dot_i u_i|^2 / q_i``."""
    v, w = twist[:, None, :3], twist[:, None, 3:]
    wr = np.cross(w, r)
    b_dot = v + wr
    qd = np.einsum("nki,nki->nk", u, b_dot)
    perp = b_dot - qd[..., None] * u
    return np.einsum("nki,nki->nk", u, np.cross(w, wr)) + np.einsum(  # type: ignore[no-any-return]
        "nki,nki->nk", perp, perp) / q


def step_reference(robots: DynamicRobots, rows: np.ndarray, setpoints: np.ndarray,
                   h: float) -> None:
    """One step of ``rows`` of ``robots`` in numpy (their state advanced in place)."""
    R, t, tw = robots.R[rows], robots.t[rows], robots.twist[rows]
    M, hb, K, _, _ = robots.model.terms_batch(R, t, tw, **robots.rows(rows))
    qd = np.einsum("nij,nj->ni", K, tw)
    f = robots.drives.forces(rows, setpoints, qd, h)
    q, u, r = legs(R, t, robots.A[rows], robots.E[rows])
    m_r = robots.rotor[rows]
    lhs = M + np.einsum("nki,nk,nkj->nij", K, m_r - h * f.slope, K)
    rhs = np.einsum("nki,nk->ni", K, f.motor - f.friction - m_r * leg_bias(tw, q, u, r)) - hb
    acc = np.linalg.solve(lhs, rhs[..., None])[..., 0]
    tw = tw + h * acc
    robots.twist[rows] = tw
    robots.t[rows] = t + h * tw[:, :3]
    robots.R[rows] = exp_so3(h * tw[:, 3:]) @ R
    robots.forces[rows] = f.motor
    if robots.drives.mode == "velocity":
        err = np.abs(setpoints - qd)
        robots.track_sq[rows] += np.sum(err**2, axis=1)
        robots.track_count[rows] += 6
        robots.track_max[rows] = np.maximum(robots.track_max[rows], err.max(axis=1))
    robots.saturated_time[rows] += h * np.any(f.saturated, axis=1)
    robots.saturated_legs[rows] += h * f.saturated
    robots.force_max[rows] = np.maximum(robots.force_max[rows], np.abs(f.motor).max(axis=1))
