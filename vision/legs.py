"""Cylindrical legs as image features (``MATH.md`` section 4).

Leg ``i`` is a cylinder of radius ``r`` whose axis passes through ``A_i`` with
unit direction ``u_i`` (both in the camera frame). Its two apparent edges define
interpretation planes through the projection centre with unit normals
``n1, n2``:

``h = A x u``, ``h_hat = h / |h|``, ``w = u x h_hat``, ``sin(theta) = r / |h|``,
``n1 = cos(theta) h_hat - sin(theta) w``, ``n2 = -cos(theta) h_hat - sin(theta) w``.

Both satisfy ``n.A = -r``, ``n.u = 0``, ``|n| = 1``, and
``u = (n2 x n1) / |n2 x n1|``. This order and orientation is the convention of the
whole project (simulation, estimation and control).
"""

from __future__ import annotations

import numpy as np


def leg_edges(
    base_points: np.ndarray, directions: np.ndarray, radius: float | np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Edge normals of cylindrical legs.

    Args:
        base_points: (..., 6, 3) points ``A_i`` on the leg axes, in the camera frame [m].
        directions: (..., 6, 3) unit leg directions ``u_i`` in the camera frame.
        radius: Leg radius [m] (scalar or broadcastable to (..., 6)).

    Returns:
        ``normals`` (..., 6, 2, 3) and ``exists`` (..., 6): False where the
        projection centre is inside (or on) the cylinder, so that the edges do not
        exist; the normals there are NaN.
    """
    A = np.asarray(base_points, dtype=float)
    u = np.asarray(directions, dtype=float)
    r = np.asarray(radius, dtype=float)
    h = np.cross(A, u)
    hn = np.linalg.norm(h, axis=-1)
    exists = hn > r
    with np.errstate(invalid="ignore", divide="ignore"):
        h_hat = h / hn[..., None]
        w = np.cross(u, h_hat)
        s = (r / hn)[..., None]
        c = np.sqrt(np.clip(1.0 - s**2, 0.0, None))
    n1 = c * h_hat - s * w
    n2 = -c * h_hat - s * w
    normals = np.stack([n1, n2], axis=-2)
    normals = np.where(exists[..., None, None], normals, np.nan)
    return normals, exists


def directions_from_edges(normals: np.ndarray) -> np.ndarray:
    """Leg directions ``u = (n2 x n1) / |n2 x n1|`` from edge normals (..., 2, 3) -> (..., 3)."""
    n = np.asarray(normals, dtype=float)
    d = np.cross(n[..., 1, :], n[..., 0, :])
    return d / np.linalg.norm(d, axis=-1, keepdims=True)
