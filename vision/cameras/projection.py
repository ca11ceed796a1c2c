"""The central projections of the camera models on normalised coordinates, and their
derivatives (``docs/math.md`` section 5).

The unified model (Geyer-Daniilidis / Mei) with mirror parameter ``xi``: a point ``X``
of the camera frame is imaged through the unit sphere, ``X_s = X / |X|``, then
``m = (X_s,x, X_s,y) / (X_s,z + xi)``; ``xi = 0`` is the pinhole ``m = (X/Z, Y/Z)``
(computed by the same expressions, bit for bit). Lens distortion
(:mod:`vision.cameras.distortion`) and the intrinsics ``K`` act after these functions.
"""

from __future__ import annotations

import numpy as np

from vision.cameras.checks import unit


def cos_limit(xi: float) -> float:
    """``min(xi, 1/xi)``: a direction is imaged iff ``X_s,z > -cos_limit`` (0 for xi = 0)."""
    return 0.0 if xi == 0 else min(xi, 1.0 / xi)


def domain_radius(xi: float) -> float:
    """Largest ``|m|`` the model reaches: ``1/sqrt(xi^2 - 1)`` for ``xi > 1``, else inf."""
    return float(1.0 / np.sqrt(xi * xi - 1.0)) if xi > 1 else float("inf")


def normalised(X: np.ndarray, xi: float) -> tuple[np.ndarray, np.ndarray]:
    """Normalised coordinates (..., 2) of camera points (..., 3) and the validity mask.

    ``m = X_xy / (X_z + xi |X|)``: the same as ``X_s,xy / (X_s,z + xi)``, and exactly
    ``X_xy / X_z`` (the pinhole) when ``xi = 0``. Invalid: behind the camera (pinhole)
    or not imaged by the mirror; ``m`` is then meaningless (NaN or inf).
    """
    if xi == 0:
        z = X[..., 2]
        valid = z > 0
    else:
        rho = np.linalg.norm(X, axis=-1)
        z = X[..., 2] + xi * rho
        with np.errstate(invalid="ignore"):
            valid = (X[..., 2] > -cos_limit(xi) * rho) & (rho > 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        m = X[..., :2] / z[..., None]
    return m, valid


def normalised_jacobian(X: np.ndarray, xi: float) -> np.ndarray:
    """``dm/dX`` (..., 2, 3) of :func:`normalised` (NaN where the point is not imaged).

    With ``d = X_z + xi |X|``: ``dm_i/dX_j = delta_ij / d - m_i (e_z + xi X / |X|)_j / d``.
    """
    m, valid = normalised(X, xi)
    with np.errstate(invalid="ignore", divide="ignore"):
        if xi == 0:
            d = X[..., 2]
            dd = np.zeros(X.shape)
            dd[..., 2] = 1.0
        else:
            rho = np.linalg.norm(X, axis=-1)
            d = X[..., 2] + xi * rho
            dd = xi * X / rho[..., None]
            dd[..., 2] += 1.0
        J = np.zeros((*X.shape[:-1], 2, 3))
        J[..., 0, 0] = 1.0 / d
        J[..., 1, 1] = 1.0 / d
        J -= m[..., :, None] * dd[..., None, :] / d[..., None, None]
    return np.where(valid[..., None, None], J, np.nan)


def lift(m: np.ndarray, xi: float) -> np.ndarray:
    """Unit vectors (..., 3) from normalised coordinates (..., 2).

    ``X_s = (lam m, lam - xi)`` with ``lam = (xi + sqrt(1 + (1 - xi^2) |m|^2)) /
    (|m|^2 + 1)``: the point of the unit sphere; ``(m, 1) / |(m, 1)|`` for ``xi = 0``.
    NaN beyond the model's reach (``|m| > 1/sqrt(xi^2 - 1)``, ``xi > 1``).
    """
    if xi == 0:
        mh = np.concatenate([m, np.ones((*m.shape[:-1], 1))], axis=-1)
        return unit(mh)
    r2 = np.sum(m * m, axis=-1)
    with np.errstate(invalid="ignore"):
        lam = (xi + np.sqrt(1.0 + (1.0 - xi * xi) * r2)) / (r2 + 1.0)
    return np.stack([lam * m[..., 0], lam * m[..., 1], lam - xi], axis=-1)


def lift_jacobian(m: np.ndarray, xi: float) -> np.ndarray:
    """``dX_s/dm`` (..., 3, 2) of :func:`lift` (NaN beyond the model's reach)."""
    if xi == 0:
        mh = np.concatenate([m, np.ones((*m.shape[:-1], 1))], axis=-1)
        norm = np.linalg.norm(mh, axis=-1)
        s = mh / norm[..., None]
        P = np.eye(3) - s[..., :, None] * s[..., None, :]
        return np.asarray(P[..., :, :2] / norm[..., None, None])
    r2 = np.sum(m * m, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        S = np.sqrt(1.0 + (1.0 - xi * xi) * r2)
        lam = (xi + S) / (r2 + 1.0)
        dlam = ((1.0 - xi * xi) / (2.0 * S) - lam) / (r2 + 1.0)  # d lam / d r^2
    g = 2.0 * dlam[..., None] * m  # d lam / d m
    J = np.zeros((*m.shape[:-1], 3, 2))
    J[..., :2, :] = m[..., :, None] * g[..., None, :]
    J[..., 0, 0] += lam
    J[..., 1, 1] += lam
    J[..., 2, :] = g
    return J


def omega(n: np.ndarray, xi: float) -> np.ndarray:
    """The conic ``Ω`` (..., 3, 3) of the great circle ``n^T X_s = 0`` in normalised
    coordinates (``docs/math.md`` section 5), not normalised."""
    k = 1.0 - xi**2
    x2 = xi**2
    nx, ny, nz = n[..., 0], n[..., 1], n[..., 2]
    return np.stack(
        [
            np.stack([k * nx * nx - x2 * nz * nz, k * nx * ny, nx * nz], axis=-1),
            np.stack([k * nx * ny, k * ny * ny - x2 * nz * nz, ny * nz], axis=-1),
            np.stack([nx * nz, ny * nz, nz * nz], axis=-1),
        ],
        axis=-2,
    )
