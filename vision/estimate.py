"""Estimation of interpretation-plane normals and leg directions from edge pixels.

Two estimators of the normal ``n`` of the plane through the projection centre
that contains a 3D line (a leg edge), from pixels of its image:

- :func:`fit_normal` (``docs/math.md`` section 5, the method of the project): lift
  every pixel to a unit vector (the normalised ray of a perspective camera, the
  point of the unit sphere of the unified model), then ``n`` minimises
  ``sum w_k (n^T X_k)^2`` under ``|n| = 1``: the right singular vector of the
  smallest singular value of the stacked ``sqrt(w_k) X_k``. Two parameters,
  no degenerate configuration.
- :func:`fit_normal_conic` (the alternative discussed in seed 003, section III-B):
  fit the image curve algebraically, then read ``n`` off its coefficients. For a
  unified camera (``xi > 0``) the conic ``m^T Ω m = 0`` in normalised coordinates
  ``m = K^-1 p`` (five parameters); for a perspective camera (or ``xi = 0``) the
  line ``l^T (x, y, 1) = 0`` in normalised pixel coordinates (seed 002).

Sign convention of the returned normals (a plane's normal is defined up to
sign), in order of priority:

1. ``reference`` given: ``n . reference >= 0`` (e.g. the previous or desired
   measurement, or a simulated normal);
2. ``base_point`` given: ``n . A <= 0``, the convention of :func:`vision.leg_edges`
   (``n . A = -r`` for the edges of a leg of base point ``A``); an approximate
   ``A`` (calibrated or CAD) is enough. The plane passes at ``r`` from ``A``, so
   the rule is reliable while the angular error of the fit (plus the error on
   ``A`` seen from the camera) stays below ``asin(r / |A|)`` (about 1 deg for the
   front camera, 3 deg for the omnidirectional one with a 15 mm leg radius);
3. otherwise the order of the points: ``(X_first x X_last) . n >= 0`` for the first
   and last valid points. (Points ordered from the base end to the platform end
   give edge 0 of :func:`vision.leg_edges` its own orientation and edge 1 the
   opposite one.)
"""

from __future__ import annotations

import warnings
from typing import NamedTuple

import numpy as np

from vision.cameras import Camera, PerspectiveCamera
from vision.exceptions import EstimationError
from vision.legs import directions_from_edges


class NormalFit(NamedTuple):
    """Result of a normal fit."""

    #: (..., 3) unit normals; NaN where too few points were valid.
    normal: np.ndarray
    #: (...) weighted RMS of ``n . X_k`` over the lifted points (sine of
    #: the angular distance of the rays to the plane; radians for small values).
    residual: np.ndarray
    #: (...) number of valid points used.
    n_points: np.ndarray


def _prepare(
    camera: Camera, pixels: np.ndarray, weights: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    p = np.asarray(pixels, dtype=float)
    if p.ndim < 2 or p.shape[-1] != 2:
        raise EstimationError(f"pixels: expected shape (..., N, 2), got {p.shape}")
    X = camera.lift(p)
    valid = np.all(np.isfinite(X), axis=-1)
    if weights is None:
        w = np.ones(p.shape[:-1])
    else:
        w = np.broadcast_to(np.asarray(weights, dtype=float), p.shape[:-1]).copy()
        if np.any(w < 0):
            raise EstimationError("weights must be >= 0")
        w[~np.isfinite(w)] = 0.0
    valid &= w > 0
    w = np.where(valid, w, 0.0)
    X = np.where(valid[..., None], X, 0.0)
    return X, w, valid


def _orient(
    n: np.ndarray,
    X: np.ndarray,
    valid: np.ndarray,
    reference: np.ndarray | None,
    base_point: np.ndarray | None,
) -> np.ndarray:
    if reference is not None:
        s = np.sum(n * np.asarray(reference, float), axis=-1)
        flip = s < 0
    elif base_point is not None:
        s = np.sum(n * np.asarray(base_point, float), axis=-1)
        flip = s > 0
    else:
        N = valid.shape[-1]
        first = np.argmax(valid, axis=-1)
        last = N - 1 - np.argmax(valid[..., ::-1], axis=-1)
        Xf = np.take_along_axis(X, first[..., None, None], axis=-2)[..., 0, :]
        Xl = np.take_along_axis(X, last[..., None, None], axis=-2)[..., 0, :]
        flip = np.sum(np.cross(Xf, Xl) * n, axis=-1) < 0
    return np.where(flip[..., None], -n, n)


def _residual(n: np.ndarray, X: np.ndarray, w: np.ndarray) -> np.ndarray:
    d = np.einsum("...k,...nk->...n", n, X)
    sw = np.sum(w, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.sqrt(np.sum(w * d * d, axis=-1) / sw)


def fit_normal(
    camera: Camera,
    pixels: np.ndarray,
    weights: np.ndarray | None = None,
    reference: np.ndarray | None = None,
    base_point: np.ndarray | None = None,
) -> NormalFit:
    """Interpretation-plane normal from pixels of an edge: SVD on lifted points.

    Args:
        camera: The camera (its intrinsics and, for the unified model, ``xi``).
        pixels: (..., N, 2) pixels of the edge; NaN rows are ignored.
        weights: Optional (..., N) non-negative weights (0 ignores a point, e.g.
            ``weights=visible``).
        reference: Optional (..., 3) normal the result is oriented like.
        base_point: Optional (..., 3) point ``A`` with ``n . A <= 0`` (leg convention).

    Returns:
        :class:`NormalFit`; the normal is NaN where fewer than 2 points are valid.
    """
    X, w, valid = _prepare(camera, pixels, weights)
    n = _smallest_vector(X * np.sqrt(w)[..., None])
    count = valid.sum(axis=-1)
    n = _orient(n, X, valid, reference, base_point)
    n = np.where((count >= 2)[..., None], n, np.nan)
    return NormalFit(n, _residual(n, X, w), count)


def _smallest_vector(D: np.ndarray) -> np.ndarray:
    """The right singular vector of the smallest singular value of ``D`` (..., N, k): a
    null vector when N < k (rows of zeros added first: the reduced SVD of fewer rows than
    columns gives no vector outside their span, and its last one lay in the plane of two
    points, 90 degrees from the normal)."""
    rows, cols = D.shape[-2:]
    if rows < cols:
        D = np.concatenate([D, np.zeros((*D.shape[:-2], cols - rows, cols))], axis=-2)
    _, _, Vh = np.linalg.svd(D, full_matrices=False)
    return Vh[..., -1, :]


def _batched_lstsq(D: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Least squares ``min |D x - rhs|`` batched over leading axes (pseudo-inverse by
    SVD, so a rank-deficient system gives the minimum-norm solution, not an error)."""
    U, S, Vh = np.linalg.svd(D, full_matrices=False)
    tol = S[..., :1] * max(D.shape[-2:]) * np.finfo(float).eps
    with np.errstate(divide="ignore", invalid="ignore"):
        Sinv = np.where(tol < S, 1.0 / S, 0.0)
    Utb = np.einsum("...nk,...n->...k", U, rhs)
    return np.einsum("...kj,...k->...j", Vh, Sinv * Utb)


def fit_normal_conic(
    camera: Camera,
    pixels: np.ndarray,
    weights: np.ndarray | None = None,
    reference: np.ndarray | None = None,
    base_point: np.ndarray | None = None,
) -> NormalFit:
    """Normal from an algebraic fit of the image curve (seed 003's alternative).

    Unified camera (``xi > 0``), exactly seed 003 eqs. (4)-(6): in normalised
    coordinates ``m = (x, y) = K^-1 p`` (the lens distortion removed first,
    :meth:`Camera.pixels_to_normalised`) the image of the edge is the conic
    ``b0 x² + b1 y² + 2 b2 xy + 2 b3 x + 2 b4 y + 1 = 0`` with ``b_k = α_k / α_5``
    (``docs/math.md`` section 5, ``α_3 = nx nz``, ``α_4 = ny nz``, ``α_5 = nz²``); the
    five ``b_k`` are fitted by linear least squares and ``n = (b3, b4, 1) /
    |(b3, b4, 1)|``. Needs 5 points. Degenerate when the optical axis lies in (or
    near) the interpretation plane (``nz -> 0``), which is the usual situation of a
    camera at the base centre: this is why the seed prefers :func:`fit_normal`.

    Perspective camera (or ``xi = 0``, where the image is a straight line and a
    conic fit is degenerate): the line fit in normalised pixel coordinates
    ``((u - w/2)/w, (v - h/2)/w, 1)`` of the ideal (undistorted) image, then
    ``n = Kt^T l`` (seed 002). Needs 2 points.

    Arguments and result as :func:`fit_normal` (``residual`` is measured on the
    lifted points, so both fits are comparable).
    """
    X, w, valid = _prepare(camera, pixels, weights)
    p = np.asarray(pixels, dtype=float)
    count = valid.sum(axis=-1)
    sw = np.sqrt(w)[..., None]
    if isinstance(camera, PerspectiveCamera) or camera.xi == 0:
        if isinstance(camera, PerspectiveCamera):
            c = camera.pixels_to_line_coordinates(p)
            to_normal = camera.line_matrix
        else:
            c = camera.pixels_to_normalised(p)
            to_normal = np.eye(3)
        rows = np.concatenate([c, np.ones((*c.shape[:-1], 1))], axis=-1)
        rows = np.where(valid[..., None], rows, 0.0) * sw
        l = _smallest_vector(rows)
        n = l @ to_normal
        need = 2
    else:
        m = camera.pixels_to_normalised(p)
        m = np.where(valid[..., None], m, 0.0)
        x, y = m[..., 0], m[..., 1]
        D = np.stack([x * x, y * y, 2 * x * y, 2 * x, 2 * y], axis=-1) * sw
        rhs = -np.ones(x.shape) * sw[..., 0]
        beta = _batched_lstsq(D, rhs)
        n = np.stack([beta[..., 3], beta[..., 4], np.ones(beta.shape[:-1])], axis=-1)
        need = 5
    with np.errstate(invalid="ignore", divide="ignore"):
        n = n / np.linalg.norm(n, axis=-1, keepdims=True)
    n = _orient(n, X, valid, reference, base_point)
    n = np.where((count >= need)[..., None], n, np.nan)
    return NormalFit(n, _residual(n, X, w), count)


def direction_from_normals(n1: np.ndarray, n2: np.ndarray) -> np.ndarray:
    """Leg direction ``u = (n2 x n1) / |n2 x n1|`` from its two edge normals (..., 3),
    the convention of :func:`vision.directions_from_edges`."""
    return directions_from_edges(np.stack([np.asarray(n1, float), np.asarray(n2, float)],
                                          axis=-2))


def angle_between(a: np.ndarray, b: np.ndarray, oriented: bool = True) -> np.ndarray:
    """Angle [rad] between vectors (..., 3); ``oriented=False`` ignores their signs
    (angle between the lines / planes). Uses ``atan2(|a x b|, a . b)`` (accurate
    for small angles)."""
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    c = np.linalg.norm(np.cross(a, b), axis=-1)
    d = np.sum(a * b, axis=-1)
    if not oriented:
        d = np.abs(d)
    return np.arctan2(c, d)


def average_normals(
    normals: np.ndarray, visible: np.ndarray, min_fraction: float = 0.5,
    max_deviation: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Average the edge normals measured in K frames of the same (static) scene.

    What a user teaching a goal does with a burst of frames: every edge normal is the
    renormalised sum of its unit normals over the frames where the edge was seen, each
    first given the sign of the first of them (a plane's normal is defined up to
    sign; the detectors orient them consistently, this makes the sum safe anyway).
    Independent pixel noise then drops as ``1 / sqrt(K)``; a bias of the detector
    that is the same in every frame does not.

    A detector can lock onto the wrong edge in some frames (another leg's edge tens of
    pixels away); one such frame would pull the sum. With ``max_deviation``, a frame
    whose normal is farther than that from the per-edge median of the frames
    (component-wise median of the sign-aligned normals, renormalised) counts as not
    seeing the edge.

    Args:
        normals: (K, ..., 3) unit normals of K frames; NaN (or anything) where the edge
            was not seen.
        visible: (K, ...) bool, the edge was seen in that frame.
        min_fraction: An edge seen (and kept) in fewer than this fraction of the K
            frames is reported missing, in ``[0, 1]`` (default: at least half).
        max_deviation: Largest angle between a frame's normal and the median normal
            [rad] (None: keep every frame); e.g. the detector's inlier distance in
            pixels times :func:`radians_per_pixel`.

    Returns:
        ``normals`` (..., 3), the averaged unit normals (NaN where missing), and
        ``visible`` (...) bool.

    Raises:
        EstimationError: Shapes that do not match, no frame, ``min_fraction`` outside
            ``[0, 1]`` or a negative ``max_deviation``.
    """
    n = np.asarray(normals, dtype=float)
    vis = np.asarray(visible, dtype=bool)
    if n.ndim < 2 or n.shape[-1] != 3 or vis.shape != n.shape[:-1]:
        raise EstimationError(f"normals (K, ..., 3) and visible (K, ...) expected, got "
                              f"{n.shape} and {vis.shape}")
    k = n.shape[0]
    if k < 1:
        raise EstimationError("average_normals: no frame")
    if not 0.0 <= min_fraction <= 1.0:
        raise EstimationError(f"min_fraction must be in [0, 1], got {min_fraction}")
    if max_deviation is not None and not max_deviation >= 0.0:
        raise EstimationError(f"max_deviation must be >= 0 rad, got {max_deviation}")
    vis = vis & np.all(np.isfinite(n), axis=-1)
    n = np.where(vis[..., None], n, 0.0)
    # sign reference: the first frame in which each edge was seen
    first = np.argmax(vis, axis=0)
    ref = np.take_along_axis(n, first[None, ..., None], axis=0)[0]
    n = n * np.where(np.sum(n * ref, axis=-1) < 0, -1.0, 1.0)[..., None]
    if max_deviation is not None:
        with warnings.catch_warnings():  # edges never seen: all-NaN medians
            warnings.simplefilter("ignore", RuntimeWarning)
            med = np.nanmedian(np.where(vis[..., None], n, np.nan), axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            med = med / np.linalg.norm(med, axis=-1, keepdims=True)
            dev = angle_between(n, med)
        vis &= dev <= max_deviation
    total = np.sum(np.where(vis[..., None], n, 0.0), axis=0)
    count = np.sum(vis, axis=0)
    norm = np.linalg.norm(total, axis=-1)
    seen = (count >= min_fraction * k) & (count > 0) & (norm > 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = total / norm[..., None]
    return np.where(seen[..., None], mean, np.nan), seen


def radians_per_pixel(camera: Camera) -> float:
    """Angle of the viewing ray per pixel of image motion at the principal point [rad].

    ``(1 + xi) / f`` with ``f`` the mean focal length [px]: ``1 / f`` for a perspective
    camera, ``2 / f`` for a parabolic mirror (``xi = 1``); the lens distortion does not
    change it (its Jacobian is the identity at the principal point). Away from the
    principal point an ideal lens's pixel subtends a smaller angle, so a pixel distance
    turned into an angle with this factor is an upper bound there (not necessarily
    with a barrel distortion, which compresses the border).
    """
    return (1.0 + float(camera.xi)) / (0.5 * (float(camera.fx) + float(camera.fy)))
