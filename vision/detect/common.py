"""What the detectors share: the prediction (:class:`LegPrediction`), the result
(:class:`EdgeDetection`), the input check and the robust plane fit of the edge rays."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from hexapod.geometry import HexapodGeometry
from hexapod.kinematics import legs_in_frame
from hexapod.workspace import home_pose
from vision.cameras import Camera
from vision.exceptions import DetectionError
from vision.legs import directions_from_edges, leg_edges


@dataclass(frozen=True)
class LegPrediction:
    """Where the legs are expected, in the (estimated) camera frame.

    Attributes:
        base_points: (6, 3) ``A_i`` [m].
        directions: (6, 3) unit ``u_i``.
        lengths: (6,) ``q_i`` [m].
        normals: (6, 2, 3) predicted edge normals (convention of :func:`leg_edges`).
        radius: Leg radius [m].
    """

    base_points: np.ndarray
    directions: np.ndarray
    lengths: np.ndarray
    normals: np.ndarray
    radius: float

    @classmethod
    def from_pose(
        cls,
        camera: Camera,
        geometry: HexapodGeometry,
        rotation: np.ndarray | None = None,
        translation: np.ndarray | None = None,
    ) -> LegPrediction:
        """The legs of a model at a platform pose (default: the home pose)."""
        if rotation is None or translation is None:
            rotation, translation = home_pose(geometry)
        legs = legs_in_frame(geometry, np.asarray(rotation, float),
                             np.asarray(translation, float), camera.camera_from_base)
        normals, _ = leg_edges(legs.base_points, legs.directions, geometry.leg_radius)
        return cls(np.asarray(legs.base_points, float), np.asarray(legs.directions, float),
                   np.asarray(legs.lengths, float), normals, float(geometry.leg_radius))

    def with_normals(self, normals: np.ndarray) -> LegPrediction:
        """The same legs with other predicted normals (e.g. the last measurement).

        Where both normals of a leg are finite, its direction is recomputed from them
        (``u = n2 x n1``, sign kept towards the previous direction); elsewhere the
        previous normals and direction are kept.
        """
        n = np.asarray(normals, float)
        if n.shape != (6, 2, 3):
            raise DetectionError("normals", f"expected shape (6, 2, 3), got {n.shape}")
        ok = np.all(np.isfinite(n), axis=(-2, -1))
        with np.errstate(invalid="ignore", divide="ignore"):
            u = directions_from_edges(np.where(ok[:, None, None], n, self.normals))
        u = np.where(np.sum(u * self.directions, axis=-1, keepdims=True) < 0, -u, u)
        u = np.where(ok[:, None] & np.all(np.isfinite(u), axis=-1, keepdims=True), u,
                     self.directions)
        edge_ok = np.all(np.isfinite(n), axis=-1)
        nn = np.where(edge_ok[..., None], n, self.normals)
        return LegPrediction(self.base_points, u, self.lengths, nn, self.radius)


@dataclass(frozen=True)
class EdgeDetection:
    """Detected leg edges in one image.

    Attributes:
        normals: (6, 2, 3) unit interpretation-plane normals in the camera frame of
            the camera model used for the fit; NaN where missing.
        edge_visible: (6, 2) the edge was found.
        n_points: (6, 2) number of inlier edge points of the fit.
        residual: (6, 2) RMS distance of the inliers to the fitted edge [px].
        points: (6, 2, N, 2) inlier edge pixels (NaN padding), for display.
        expected_points: Number of points each edge could give (circles or samples).
    """

    normals: np.ndarray
    edge_visible: np.ndarray
    n_points: np.ndarray
    residual: np.ndarray
    points: np.ndarray
    expected_points: int

    @property
    def quality(self) -> np.ndarray:
        """(6, 2) fraction of the possible edge points that are inliers (0 if missing)."""
        return np.where(self.edge_visible, self.n_points / float(self.expected_points), 0.0)



def _check_image(image: np.ndarray, camera: Camera) -> np.ndarray:
    if not isinstance(image, np.ndarray):
        raise DetectionError("image", f"expected a numpy array, got {type(image).__name__}")
    if image.ndim == 3 and image.shape[2] in (3, 4):
        image = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY if image.shape[2] == 3
                             else cv2.COLOR_BGRA2GRAY)
    if image.ndim != 2:
        raise DetectionError("image", f"expected a grey (H, W) image, got shape {image.shape}")
    if image.shape != (camera.height, camera.width):
        raise DetectionError(
            "image", f"size {image.shape[1]}x{image.shape[0]} does not match the camera "
                     f"{camera.width}x{camera.height}")
    if image.dtype != np.uint8:
        raise DetectionError("image", f"expected uint8, got {image.dtype}")
    return image


def fit_normals(
    rays: np.ndarray, weights: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Batched weighted plane fit through the origin (``docs/math.md`` section 5).

    The normal minimising ``sum w (n . X)^2`` is the eigenvector of the smallest
    eigenvalue of ``sum w X X^T`` (the smallest right singular vector of the
    stacked, weighted rays: the estimator of :func:`vision.estimate.fit_normal`,
    batched).

    Args:
        rays: (..., N, 3) unit rays (NaN allowed where the weight is 0).
        weights: (..., N) non-negative weights.

    Returns:
        ``normals`` (..., 3) (arbitrary sign) and ``abs_residuals`` (..., N) = ``|n.X|``
        for every finite ray, weighted or not (a point rejected earlier keeps its true
        residual, so that a robust loop does not re-admit it); 0 for non-finite rays.
    """
    X = np.where(weights[..., None] > 0, rays, 0.0)
    Xw = X * weights[..., None]
    M = np.einsum("...ni,...nj->...ij", Xw, X)
    _, vecs = np.linalg.eigh(M)
    n = vecs[..., :, 0]
    res = np.abs(np.einsum("...ni,...i->...n", np.nan_to_num(rays), n))
    return n, res


def _orient(normals: np.ndarray, predicted: np.ndarray) -> np.ndarray:
    s = np.sum(normals * predicted, axis=-1, keepdims=True)
    return np.where(s < 0, -normals, normals)


def _robust_fit(
    rays: np.ndarray,
    valid: np.ndarray,
    px_per_rad: np.ndarray | float,
    predicted: np.ndarray,
    outlier_px: float,
    min_points: int,
    max_rms_px: float,
    iterations: int = 2,
    use_compiled: bool = True,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Fit, reject points farther than ``outlier_px`` from the fit, refit.

    Per edge: the weights start at ``valid``; up to ``iterations + 1`` times the
    weighted points are fitted (an edge with fewer than 2 of them gets no normal
    and stops), every valid point gets its residual [px] and the new weights are
    the valid points within ``outlier_px``; an edge stops when its weights no
    longer change. The RMS is that of the final inliers' residuals to the last fit.
    The compiled core (:func:`vision.kernels.fit_planes`) computes the same.

    Args:
        rays: (..., N, 3) unit rays (finite where valid).
        valid: (..., N) bool.
        px_per_rad: Pixels per radian of residual, scalar or (..., N).
        predicted: (..., 3) predicted normals (orientation; an edge without a finite
            prediction is missing).
        outlier_px: Inlier distance [px].
        min_points: Minimal number of inliers of a visible edge.
        max_rms_px: Largest RMS residual of a visible edge [px].
        iterations: Refits after the first fit.
        use_compiled: Use the compiled core when it is available.

    Returns:
        ``normals`` (..., 3) oriented like ``predicted`` (NaN if missing),
        ``visible`` (...), ``n_points`` (...), ``rms_px`` (...), ``inliers``
        (..., N).
    """
    from vision import kernels

    if use_compiled and kernels.available():
        return kernels.fit_planes(rays, valid, px_per_rad, predicted, outlier_px,
                                  min_points, max_rms_px, iterations)
    w = np.asarray(valid, bool).copy()
    ppr = np.broadcast_to(np.asarray(px_per_rad, float), w.shape)
    n = np.full((*rays.shape[:-2], 3), np.nan)
    res_px = np.zeros(w.shape)
    fitted = np.zeros(w.shape[:-1], bool)
    active = np.ones(w.shape[:-1], bool)
    for _ in range(iterations + 1):
        active &= w.sum(-1) >= 2
        if not np.any(active):
            break
        n_fit, res = fit_normals(rays, w.astype(float))
        rp = res * ppr
        n = np.where(active[..., None], n_fit, n)
        res_px = np.where(active[..., None], rp, res_px)
        fitted |= active
        new_w = np.where(active[..., None], valid & (rp <= outlier_px), w)
        active &= np.any(new_w != w, axis=-1)
        w = new_w
    cnt = w.sum(-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        rms = np.sqrt(np.sum(np.where(w, res_px**2, 0.0), -1) / np.maximum(cnt, 1))
    visible = (fitted & (cnt >= min_points) & (rms <= max_rms_px)
               & np.all(np.isfinite(predicted), -1))
    n = _orient(n, predicted)
    n = np.where(visible[..., None], n, np.nan)
    return n, visible, cnt, np.where(visible, rms, np.nan), w & visible[..., None]

