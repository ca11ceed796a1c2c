"""Curved edge predictions of the perspective tracker through a distorted lens.

With lens distortion the image of a leg's limb is a curve, not the straight line
``K^-T n`` of an ideal lens. The tracker then samples the prediction in 3D
(:func:`curved_samples`): the points ``X = A + r n + t q u`` of the predicted limb,
moved onto the plane of the predicted normal (``X - (n.X) n``, so that a prediction
whose normals come from a previous detection is sampled on the detected curve),
projected with the camera (distortion included); the search direction at each sample
is the image normal of the curve there, from :meth:`Camera.project_jacobian`: the
image tangent is ``J d`` for the direction ``d`` of the limb within the plane, and the
normal is turned to the side of ``J n`` (the limb lies at ``axis + r n``: ``+n``
leaves the leg). The occlusion gate works in the ideal (undistorted) image, where the
predicted bands of the legs are straight (``K m`` of the samples, lines ``K^-T n``),
with the margin scaled by the local magnification of the lens.

Edge points are lifted through the distortion (:func:`lift_near`): Newton's method on
``D(m) = K^-1 p`` started at the normalised point of the sample the point was found
from (a few pixels away), which converges to machine precision in 3 to 4 steps;
the camera's safeguarded solver (:meth:`Camera.undistort`) takes any point that does
not. The pixels per radian of each point (:func:`pixels_per_radian`) are the inverse
of the image gradient of ``n . X`` there, from the lift Jacobian.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vision.cameras import projection
from vision.cameras.base import Camera
from vision.detect.common import LegPrediction
from vision.detect.profiles import _pixel_lines

#: Newton steps of :func:`lift_near` at most.
LIFT_ITERATIONS = 6


@dataclass(frozen=True)
class CurvedSamples:
    """Samples of the twelve predicted edges through a distorted lens.

    Attributes:
        P: (6, 2, M, 2) raw pixels of the samples (on the predicted curves).
        out: (6, 2, M, 2) unit image normals of the curves at the samples, outwards
            (away from the leg).
        m: (6, 2, M, 2) undistorted normalised coordinates of the samples.
        gate: (6, 2, M, 2) the samples in the ideal image, ``K m`` [px].
        margin: (6, 2, M) occlusion margin in the ideal image [px].
        seg: (6, 2, 2, 2) ideal-image ends of the predicted edges (on ``lines``).
        lines: (6, 2, 3) ideal-image lines ``K^-T n`` with unit ``(a, b)``.
        md: (6, 2, M, 2) distorted normalised coordinates ``D(m)`` of the samples.
        jac: (6, 2, M, 4) the lens Jacobian ``(j11, j12, j21, j22)`` at ``m``.
    """

    P: np.ndarray
    out: np.ndarray
    m: np.ndarray
    gate: np.ndarray
    margin: np.ndarray
    seg: np.ndarray
    lines: np.ndarray
    md: np.ndarray | None = None
    jac: np.ndarray | None = None

    @property
    def edge_out(self) -> np.ndarray:
        """(6, 2, 2) one outward direction per edge: the mean of the samples' normals,
        normalised (NaN where no sample is imaged)."""
        fin = np.all(np.isfinite(self.out), axis=-1, keepdims=True)
        o = np.sum(np.where(fin, self.out, 0.0), axis=2)
        with np.errstate(invalid="ignore", divide="ignore"):
            o /= np.linalg.norm(o, axis=-1, keepdims=True)
        return np.where(np.any(fin, axis=2), o, np.nan)


def _min_singular(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Smallest singular value of the 2x2 matrices ``[[a, b], [c, d]]``."""
    s = a * a + b * b + c * c + d * d
    det = a * d - b * c
    with np.errstate(invalid="ignore"):
        return np.sqrt(np.maximum(0.5 * (s - np.sqrt(np.maximum(s * s - 4 * det * det, 0.0))),
                                  0.0))


def curved_samples(camera: Camera, prediction: LegPrediction, t: np.ndarray,
                   margin_px: float) -> CurvedSamples:
    """Sample the predicted edges as curves (see the module docstring).

    Args:
        camera: The (estimated, distorted) perspective camera (``xi = 0``).
        prediction: The predicted legs in its frame.
        t: (M,) positions along the legs (fractions of the length).
        margin_px: Occlusion margin in the raw image [px].

    Returns:
        A :class:`CurvedSamples`; NaN where a sample is behind the camera or the
        prediction has no normal.
    """
    A, u, q, r, n = (prediction.base_points, prediction.directions, prediction.lengths,
                     prediction.radius, prediction.normals)
    s = np.concatenate([t, [0.0, 1.0]])
    X = (A[:, None, None, :] + r * n[:, :, None, :]
         + (s[None, None, :, None] * q[:, None, None, None]) * u[:, None, None, :])
    X = X - np.sum(X * n[:, :, None, :], -1, keepdims=True) * n[:, :, None, :]
    Z = X[..., 2]
    with np.errstate(invalid="ignore", divide="ignore"):
        iz = np.where(Z > 0, 1.0 / Z, np.nan)
    x, y = X[..., 0] * iz, X[..., 1] * iz
    xd, yd, j11, j12, j21, j22 = camera.lens.parts(x, y)
    K = camera.K
    fx, sk, cx, fy, cy = K[0, 0], K[0, 1], K[0, 2], K[1, 1], K[1, 2]
    P = np.stack([fx * xd + sk * yd + cx, fy * yd + cy], -1)
    d = u[:, None, :] - np.sum(u[:, None, :] * n, -1, keepdims=True) * n  # in the plane

    def image_direction(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixel derivative (du, dv) of the projection along the 3D direction v (6, 2, 3)."""
        a = (v[:, :, None, 0] - x * v[:, :, None, 2]) * iz
        b = (v[:, :, None, 1] - y * v[:, :, None, 2]) * iz
        e, f = j11 * a + j12 * b, j21 * a + j22 * b
        return fx * e + sk * f, fy * f

    tu, tv = image_direction(d)
    ru, rv = image_direction(n)
    with np.errstate(invalid="ignore", divide="ignore"):
        norm = np.hypot(tu, tv)
        nu, nv = -tv / norm, tu / norm
        sgn = np.where(nu * ru + nv * rv < 0, -1.0, 1.0)
    out = np.stack([nu * sgn, nv * sgn], -1)
    m = np.stack([x, y], -1)
    gate = np.stack([fx * x + sk * y + cx, fy * y + cy], -1)
    # The ideal-to-raw pixel map K2 Jd K2^-1 and its smallest magnification.
    a11 = j11 + sk * j21 / fx
    a12 = (fx * j12 + sk * j22 - a11 * sk) / fy
    a21 = fy * j21 / fx
    a22 = j22 - a21 * sk / fy
    with np.errstate(invalid="ignore", divide="ignore"):
        margin = margin_px / _min_singular(a11, a12, a21, a22)
    lines = _pixel_lines(camera, n)
    ends = gate[:, :, -2:]
    dist = np.sum(lines[:, :, None, :2] * ends, -1) + lines[:, :, None, 2]
    seg = ends - dist[..., None] * lines[:, :, None, :2]
    M = t.size
    return CurvedSamples(P=P[:, :, :M], out=out[:, :, :M], m=m[:, :, :M],
                         gate=gate[:, :, :M], margin=margin[:, :, :M], seg=seg, lines=lines,
                         md=np.stack([xd, yd], -1)[:, :, :M],
                         jac=np.stack([j11, j12, j21, j22], -1)[:, :, :M])


def lift_near(camera: Camera, pixels: np.ndarray, m0: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
    """Lift pixels near known points through the distortion (perspective camera).

    Args:
        camera: The camera (``xi = 0``).
        pixels: (..., 2) raw pixels [px].
        m0: (..., 2) undistorted normalised coordinates near each pixel's pre-image
            (the sample it was found from), the start of Newton's method.

    Returns:
        Unit rays (..., 3) and the undistorted normalised coordinates ``m`` (..., 2)
        (:meth:`Camera.lift` to the rounding: residual of the distortion equation
        below ``1e-15 max(1, |m_d|)``); NaN where a pixel is not finite.
    """
    rays, m, _ = lift_near_parts(camera, pixels, m0)
    return rays, m


def lift_near_parts(camera: Camera, pixels: np.ndarray, m0: np.ndarray,
                    md0: np.ndarray | None = None, jac0: np.ndarray | None = None
                    ) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, ...] | None]:
    """:func:`lift_near`, and the lens Jacobian at the lifted points.

    With the distorted point ``md0`` and the lens Jacobian ``jac0`` (``(j11, j12, j21,
    j22)`` in the last axis) at ``m0`` (:class:`CurvedSamples` has them), the first
    Newton step costs no lens evaluation. Newton's method stops once the residual is at
    the rounding of the lens map, so the last evaluation gives the Jacobian at the
    returned point (for :func:`pixels_per_radian`).

    Returns:
        Rays (..., 3), ``m`` (..., 2) and ``(j11, j12, j21, j22)`` at ``m`` (None where
        a point needed the camera's safeguarded solver: recompute them).
    """
    md = camera.pixels_to_distorted(pixels)
    ux, uy = md[..., 0], md[..., 1]
    ok0 = np.isfinite(m0).all(-1)
    x = np.where(ok0, m0[..., 0], ux)
    y = np.where(ok0, m0[..., 1], uy)
    lens = camera.lens
    tol = 1e-15 * np.maximum(1.0, np.hypot(ux, uy))
    jac = None
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        if md0 is not None and jac0 is not None:
            a, b, c, d = jac0[..., 0], jac0[..., 1], jac0[..., 2], jac0[..., 3]
            fx_, fy_ = md0[..., 0] - ux, md0[..., 1] - uy
            det = a * d - b * c
            sx = (d * fx_ - b * fy_) / det
            sy = (a * fy_ - c * fx_) / det
            good = ok0 & np.isfinite(sx) & np.isfinite(sy)
            x, y = np.where(good, x - sx, x), np.where(good, y - sy, y)
        for _ in range(LIFT_ITERATIONS):
            xd, yd, j11, j12, j21, j22 = lens.parts(x, y)
            fx_, fy_ = xd - ux, yd - uy
            res = np.hypot(fx_, fy_)
            if not np.any(res > tol):
                jac = (j11, j12, j21, j22)
                break
            det = j11 * j22 - j12 * j21
            x = x - (j22 * fx_ - j12 * fy_) / det
            y = y - (j11 * fy_ - j21 * fx_) / det
        else:
            xd, yd, j11, j12, j21, j22 = lens.parts(x, y)
            res = np.hypot(xd - ux, yd - uy)
            jac = (j11, j12, j21, j22)
    m = np.stack([x, y], -1)
    finite = np.isfinite(md).all(-1)
    bad = finite & ~(res <= tol)
    if np.any(bad):
        m[bad] = camera.undistort(md[bad])
        jac = None
    m = np.where(finite[..., None], m, np.nan)
    return projection.lift(m, 0.0), m, jac


def pixels_per_radian(camera: Camera, m: np.ndarray, normals: np.ndarray,
                      jac: tuple[np.ndarray, ...] | None = None) -> np.ndarray:
    """Pixels per radian of ``n . X`` at points of a perspective image:
    ``1 / |n^T dX/dp|`` (``dX/dp`` the lift Jacobian, distortion included).

    Args:
        camera: The camera (``xi = 0``).
        m: (..., N, 2) undistorted normalised coordinates of the points (NaN allowed).
        normals: (..., 3) the plane normal of each row of points.
        jac: The lens Jacobian ``(j11, j12, j21, j22)`` at ``m`` when known
            (:func:`lift_near_parts`); computed otherwise.

    Returns:
        (..., N) the distance [px] of a point from the curve of ``n`` per radian of
        ``n . X`` (1 where ``m`` is not finite).
    """
    x, y = m[..., 0], m[..., 1]
    nn = np.asarray(normals, float)[..., None, :]
    h = np.sqrt(1.0 + x * x + y * y)
    ns = (nn[..., 0] * x + nn[..., 1] * y + nn[..., 2]) / h  # n . X_s
    # Gradient of n . X_s w.r.t. m, then through the inverse distortion and K.
    g0 = (nn[..., 0] - ns * x / h) / h
    g1 = (nn[..., 1] - ns * y / h) / h
    if jac is None:
        _, _, j11, j12, j21, j22 = camera.lens.parts(x, y)
    else:
        j11, j12, j21, j22 = jac
    K = camera.K
    with np.errstate(invalid="ignore", divide="ignore"):
        det = j11 * j22 - j12 * j21
        d0 = (g0 * j22 - g1 * j21) / det
        d1 = (g1 * j11 - g0 * j12) / det
        p0 = d0 / K[0, 0]
        p1 = (d1 - p0 * K[0, 1]) / K[1, 1]
        ppr = 1.0 / np.hypot(p0, p1)
    return np.where(np.isfinite(ppr), ppr, 1.0)
