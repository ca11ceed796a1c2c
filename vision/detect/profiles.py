"""1D edge profiles of the tracker: bilinear sampling, gradient profiles, the
Theil-Sen line of the edge offsets, and the pixel lines of predicted normals."""

from __future__ import annotations

import numpy as np

from vision.cameras import Camera

#: Gradient value of a profile position that is not a candidate (numpy and C).
_NO_GRADIENT = -1e6


def _bilinear_zero(image: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Bilinear interpolation of a grey image at (x, y) [px] (float64), 0 where the point
    is outside ``[0, W-1] x [0, H-1]`` or not finite."""
    H, W = image.shape
    with np.errstate(invalid="ignore"):
        inside = (x >= 0) & (x <= W - 1) & (y >= 0) & (y <= H - 1)
    xc = np.where(inside, x, 0.0)
    yc = np.where(inside, y, 0.0)
    x0 = np.minimum(np.floor(xc), W - 2).astype(np.intp)
    y0 = np.minimum(np.floor(yc), H - 2).astype(np.intp)
    fx, fy = xc - x0, yc - y0
    flat = image.ravel()
    i00 = y0 * W + x0
    v00, v01 = flat[i00].astype(float), flat[i00 + 1].astype(float)
    v10, v11 = flat[i00 + W].astype(float), flat[i00 + W + 1].astype(float)
    v = (1 - fy) * ((1 - fx) * v00 + fx * v01) + fy * ((1 - fx) * v10 + fx * v11)
    return np.where(inside, v, 0.0)


def _gradient_profiles(image: np.ndarray, P: np.ndarray, out: np.ndarray, R: int
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Profiles through the samples ``P`` (..., M, 2) along ``out`` (..., 2) (one
    direction per edge) or (..., M, 2) (one per sample): the points ``Q`` (..., M,
    2R + 1, 2) at the integer offsets ``-R .. R`` [px] and the central differences
    (..., M, 2R - 1) of the bilinear signal at the offsets ``-(R-1) .. R-1`` (positive
    towards the bright side of an edge whose outside is along ``out``)."""
    offs = np.arange(-R, R + 1, dtype=float)
    o = out[..., :, None, :] if out.ndim == P.ndim else out[..., None, None, :]
    Q = P[..., :, None, :] + offs[:, None] * o
    prof = _bilinear_zero(image, Q[..., 0], Q[..., 1])
    return Q, 0.5 * (prof[..., 2:] - prof[..., :-2])


def _theil_sen_inliers(offset: np.ndarray, valid: np.ndarray, t: np.ndarray,
                       tolerance: float) -> np.ndarray:
    """The valid samples within ``tolerance`` of the Theil-Sen line through
    ``(t, offset)`` of each edge: slope = lower median of the pairwise slopes, intercept
    = lower median of ``offset - slope t`` (no line, no inlier, with fewer than 2)."""
    M = t.size
    off_v = np.where(valid, offset, np.nan)
    with np.errstate(invalid="ignore", divide="ignore"):
        slopes = (off_v[..., :, None] - off_v[..., None, :]) / (t[:, None] - t[None, :])
    iu = np.triu_indices(M, 1)
    b = _nan_median(slopes[..., iu[0], iu[1]])
    a = _nan_median(off_v - b[..., None] * t)
    with np.errstate(invalid="ignore"):
        return valid & (np.abs(off_v - (a[..., None] + b[..., None] * t)) <= tolerance)


def _nan_median(x: np.ndarray) -> np.ndarray:
    """Lower median over the last axis ignoring NaN (NaN where all are NaN); much
    faster than ``np.nanmedian`` on small arrays."""
    xs = np.sort(x, axis=-1)  # NaN last
    cnt = np.sum(np.isfinite(x), axis=-1)
    idx = np.maximum((cnt - 1) // 2, 0)
    med = np.take_along_axis(xs, idx[..., None], -1)[..., 0]
    return np.where(cnt > 0, med, np.nan)


def _pixel_lines(camera: Camera, normals: np.ndarray) -> np.ndarray:
    """Pixel lines ``l ~ K^-T n`` scaled so that ``(a, b)`` is a unit vector."""
    l = np.asarray(normals, float) @ np.linalg.inv(camera.K)
    with np.errstate(invalid="ignore", divide="ignore"):
        return l / np.linalg.norm(l[..., :2], axis=-1, keepdims=True)
