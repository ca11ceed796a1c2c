"""Leg-edge detection in images, for the unified (omnidirectional) and the perspective camera.

Both detectors output a :class:`EdgeDetection`: for each leg ``i`` and edge ``j``
the interpretation-plane normal ``n_ij`` (``docs/math.md`` sections 4 and 5, fitted from
the edge pixels lifted with the *given* camera model, i.e. the estimated one), the
number of points and the fit residual, and whether the edge was found. A missing
edge is reported as missing (``edge_visible`` False, NaN normal), never invented.

Order and orientation of the normals follow :func:`vision.legs.leg_edges`: edge 1
is the limb on the ``+h`` side of the plane through the projection centre and the
leg axis (``h = A x u``), and each normal is oriented to agree in sign with the
predicted normal of the same edge (``n1 = cos(theta) h - sin(theta) w``, ...). The
prediction (:class:`LegPrediction`) only has to be good enough to tell the two
edges of a leg apart and to associate image features with legs.

**Omnidirectional** (:class:`OmniDetector`, seed 003 section III-A): the image is
sampled along ``n_circles`` circles centred on the principal point with diameters
from ``d_min`` to ``d_max`` (nearest pixels, indices computed once), each 1D signal
is thresholded half-way between its darkest sample and its median (the background:
the legs cover a small part of every circle, a bright object may set its maximum),
and every leg crosses every circle as a dark band whose start and end are the two
edges. Each edge is then located with sub-sample accuracy as the strongest gradient
of its polarity near the transition (central differences of the bilinearly
interpolated signal, refined by a parabola), which does not depend on the grey
levels on either side (on a cluttered background the local level differs from the
circle's). An edge whose points lie farther than ``max_rms_px`` (RMS) from their
plane is reported missing; a straight dark object running along a leg can still
bias an edge within that tolerance (``docs/results.md``). Bands are associated to
legs by the angle where the predicted leg axis crosses the circle (the nearest
predicted leg wins, within half the distance to the next predicted leg); a band
whose width is far from the predicted width (two legs merged, clutter) is dropped.
No initialisation is needed: without a prediction the legs at the home pose are
used (the legs stay near their base joints' azimuth, which the calibration gives).

**Perspective** (:class:`PerspectiveTracker`, the moving-edges idea of ViSP):
``n_samples`` points are placed along each predicted edge segment; from each, a 1D
profile is read along the normal of the predicted line over ``+-search_px`` (exact
bilinear interpolation) and the strongest grey-level gradient of the right polarity
(dark leg inside, brighter background outside) is kept if stronger than
``min_contrast``, refined by a parabola. Samples that fall inside another leg's
predicted band (where a leg may hide the edge, or be hidden by it against a dark
background) are not used. A robust line (Theil-Sen on the offsets from the
predicted line, then a residual test) rejects the points of the remaining occluders
and clutter, and the normal is the robust least-squares fit of the inliers.

Initialisation and tracking (:meth:`PerspectiveTracker.track`, the policy of the
simulator's image sensor and of the servo loop's cameras): edges found in the
previous frame are searched around their last position; for the others, the model
prediction (the pose of the measured leg lengths, seen by the estimated camera) is
first aligned with the image by one translation (:meth:`PerspectiveTracker.align`:
the consensus of the twelve edges' gradient responses), which absorbs the image
offset of the calibration error (tens of pixels) without locking an edge onto
another leg's limb; a final narrow pass ends every frame. There is no
prediction-free (Hough/LSD) detection: the encoders always give the prediction.

Both detectors run compiled cores (:mod:`vision.kernels`) that compute the same as
the numpy code here, which stays as the reference and the fallback.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from hexapod.geometry import HexapodGeometry
from hexapod.kinematics import legs_in_frame
from hexapod.workspace import home_pose
from vision.cameras import Camera, PerspectiveCamera
from vision.exceptions import VisionError
from vision.legs import directions_from_edges, leg_edges

logger = logging.getLogger(__name__)


class DetectionError(VisionError, ValueError):
    """A detector cannot run on its input (wrong image size or type, bad settings).

    Attributes:
        field: The offending input or setting.
        problem: What is wrong with it.
    """

    def __init__(self, field: str, problem: str) -> None:
        self.field = field
        self.problem = problem
        super().__init__(f"{field}: {problem}")


# ============================================================================
# Prediction and result
# ============================================================================
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


# ============================================================================
# Shared helpers
# ============================================================================
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


# ============================================================================
# Omnidirectional camera: circle scanning (seed 003, section III-A)
# ============================================================================
class OmniDetector:
    """Automatic leg-edge detector for a unified camera looking along the legs.

    Args:
        camera: The (estimated) unified camera: its principal point centres the
            circles and its model lifts the edge pixels.
        d_min: Smallest circle diameter [px] (seed 003: 184).
        d_max: Largest circle diameter [px] (seed 003: 370).
        n_circles: Number of circles (seed 003: 17).
        n_angles: Samples per circle.
        min_points: Minimal number of inlier points for an edge.
        outlier_px: Points farther than this from the fitted edge are rejected [px].
        max_rms_px: An edge whose inliers' RMS distance exceeds this is missing [px].
        width_tolerance: A band is kept if its angular width is within a factor
            ``width_tolerance`` of the predicted one.
        min_contrast: Minimal grey-level range along a circle for it to be used.
    """

    def __init__(
        self,
        camera: Camera,
        d_min: float = 184.0,
        d_max: float = 370.0,
        n_circles: int = 17,
        n_angles: int = 1024,
        min_points: int = 5,
        outlier_px: float = 1.5,
        max_rms_px: float = 0.5,
        width_tolerance: float = 1.8,
        min_contrast: float = 40.0,
    ) -> None:
        if not 0 < d_min < d_max:
            raise DetectionError("d_min/d_max", f"expected 0 < d_min < d_max, got {d_min}, "
                                                f"{d_max}")
        if n_circles < 2 or n_angles < 16:
            raise DetectionError("n_circles/n_angles", f"too few: {n_circles}, {n_angles}")
        self.camera = camera
        self.d_min, self.d_max = float(d_min), float(d_max)
        self.n_circles, self.n_angles = int(n_circles), int(n_angles)
        self.min_points = int(min_points)
        self.outlier_px = float(outlier_px)
        self.max_rms_px = float(max_rms_px)
        self.width_tolerance = float(width_tolerance)
        self.min_contrast = float(min_contrast)
        cx, cy = camera.cx, camera.cy
        W, H = camera.width, camera.height
        self.radii = np.linspace(0.5 * d_min, 0.5 * d_max, n_circles)
        self.angles = np.arange(n_angles) * (2.0 * np.pi / n_angles)
        mx = cx + self.radii[:, None] * np.cos(self.angles)[None, :]
        my = cy + self.radii[:, None] * np.sin(self.angles)[None, :]
        inside = (mx >= 0) & (mx <= W - 2) & (my >= 0) & (my <= H - 2)
        if not np.all(inside):
            raise DetectionError(
                "d_max", f"circles of diameter up to {d_max} px around ({cx:.1f}, {cy:.1f}) "
                         f"leave the {W}x{H} image")
        # Nearest-pixel flat indices (coarse signal) and bilinear data (refinement).
        self._idx = (np.rint(my).astype(np.intp) * W + np.rint(mx).astype(np.intp))
        x0, y0 = np.floor(mx), np.floor(my)
        self._base = (y0.astype(np.intp) * W + x0.astype(np.intp))
        self._fx, self._fy = mx - x0, my - y0
        self._W = W
        # Unit rays of the samples: exact rays at the sample points, and the elevation
        # (z) and pixels-per-radian of each circle.
        pix = np.stack([mx, my], -1)
        self._rays = camera.lift(pix)
        self._z = np.nanmean(self._rays[..., 2], axis=1)
        r_in = camera.lift(np.stack([cx + self.radii - 0.5, np.full_like(self.radii, cy)], -1))
        r_out = camera.lift(np.stack([cx + self.radii + 0.5, np.full_like(self.radii, cy)], -1))
        d_ang = np.arccos(np.clip(np.sum(r_in * r_out, -1), -1.0, 1.0))
        self._px_per_rad = 1.0 / d_ang  # (n_circles,)
        # Exact lift of a point at (circle k, fractional sample position) is the
        # rotation of the circle's ray only for fx = fy and no skew.
        self._isotropic = bool(camera.K[0, 1] == 0 and camera.fx == camera.fy)
        self._default: LegPrediction | None = None
        self._geometry: HexapodGeometry | None = None
        self._ref_key: LegPrediction | None = None
        self._ref: tuple[np.ndarray, ...] = ()
        self._kernel: Any = None  # vision.kernels.OmniKernel, built on first use

    def default_prediction(self, geometry: HexapodGeometry) -> LegPrediction:
        """The legs at the home pose (the automatic mode's association reference)."""
        if self._default is None or self._geometry is not geometry:
            self._default = LegPrediction.from_pose(self.camera, geometry)
            self._geometry = geometry
        return self._default

    # ----------------------------------------------------------------- reference
    def _crossings(self, P0: np.ndarray, d: np.ndarray, length: np.ndarray) -> np.ndarray:
        """Azimuth [rad] where the segments ``P0 + s d`` (s in [0, length]) cross the
        cone of each circle: (..., n_circles), NaN if they do not."""
        Z = self._z
        P0 = P0[..., None, :]
        d = d[..., None, :]
        a = d[..., 2] ** 2 - Z**2 * np.sum(d * d, -1)
        b = 2.0 * (P0[..., 2] * d[..., 2] - Z**2 * np.sum(P0 * d, -1))
        c = P0[..., 2] ** 2 - Z**2 * np.sum(P0 * P0, -1)
        disc = b * b - 4 * a * c
        with np.errstate(invalid="ignore", divide="ignore"):
            sq = np.sqrt(np.where(disc >= 0, disc, np.nan))
            best = np.full(a.shape, np.nan)
            for sgn in (-1.0, 1.0):
                s = (-b + sgn * sq) / (2 * a)
                z = P0[..., 2] + s * d[..., 2]
                ok = (s >= 0) & (s <= length[..., None]) & (z * Z >= 0)
                best = np.where(ok & np.isnan(best), s, best)
            P = P0 + best[..., None] * d
        if self.camera.K[0, 1] == 0:
            # The unified projection scales (X, Y) by a positive factor, then K by
            # (fx, fy): the image azimuth about the principal point is that of
            # (fx X, fy Y) (NaN where no crossing).
            return np.arctan2(self.camera.fy * P[..., 1], self.camera.fx * P[..., 0])
        pix, _ = self.camera.project(P)
        return np.arctan2(pix[..., 1] - self.camera.cy, pix[..., 0] - self.camera.cx)

    def _reference(self, prediction: LegPrediction) -> tuple[np.ndarray, ...]:
        """Per (leg, circle): predicted axis azimuth, association gate, predicted band
        width [rad] and whether edge 1 comes first (smaller azimuth). Cached."""
        if self._ref_key is prediction:
            return self._ref
        A, u, q, r = (prediction.base_points, prediction.directions, prediction.lengths,
                      prediction.radius)
        starts = np.stack([A, A + r * prediction.normals[:, 0], A + r * prediction.normals[:, 1]])
        dirs = np.broadcast_to(u, starts.shape)
        ref = self._crossings(starts, dirs, np.broadcast_to(q, starts.shape[:-1]))
        axis = ref[0]  # (6, C)
        d = np.abs(_wrap(axis[:, None, :] - axis[None, :, :]))  # (6, 6, C)
        d = np.where(np.eye(6, dtype=bool)[..., None] | np.isnan(d), np.inf, d)
        gate = np.minimum(0.5 * d.min(axis=1), np.deg2rad(20.0))
        de = _wrap(ref[1] - ref[2])
        width = np.abs(de)
        e1_first = de < 0
        self._ref = (np.nan_to_num(axis, nan=1e3), np.where(np.isnan(axis), 0.0, gate),
                     np.nan_to_num(width, nan=0.0), e1_first)
        self._ref_key = prediction
        return self._ref

    # ----------------------------------------------------------------- detect
    def scan(self, image: np.ndarray) -> np.ndarray:
        """The coarse (nearest-pixel) polar samples (n_circles, n_angles) uint8."""
        image = _check_image(image, self.camera)
        return np.ravel(image)[self._idx]

    def _bilinear(self, flat: np.ndarray, c: np.ndarray, j: np.ndarray) -> np.ndarray:
        b = self._base[c, j]
        fx, fy = self._fx[c, j], self._fy[c, j]
        W = self._W
        v00, v01 = flat[b].astype(float), flat[b + 1].astype(float)
        v10, v11 = flat[b + W].astype(float), flat[b + W + 1].astype(float)
        return (1 - fy) * ((1 - fx) * v00 + fx * v01) + fy * ((1 - fx) * v10 + fx * v11)

    def track(
        self, image: np.ndarray, prediction: LegPrediction,
        previous: np.ndarray | None = None, align_px: float = 0.0, refine_px: float = 0.0,
    ) -> EdgeDetection:
        """Detect the edges of one frame of a sequence (same call as
        :meth:`PerspectiveTracker.track`): the scan is global; the normals found in
        the previous frame (finite rows of ``previous``) replace the model's in the
        association reference. ``align_px`` and ``refine_px`` are not used."""
        if previous is not None:
            prediction = prediction.with_normals(np.asarray(previous, float))
        return self.detect(image, prediction)

    def detect(
        self, image: np.ndarray, prediction: LegPrediction | None = None,
        geometry: HexapodGeometry | None = None, use_compiled: bool = True,
    ) -> EdgeDetection:
        """Detect the twelve leg edges.

        Args:
            image: (height, width) uint8 grey image (BGR is converted).
            prediction: Predicted legs (association and edge order); default: the
                home pose of ``geometry``. Derived data are cached while the same
                prediction object is passed.
            geometry: The robot, needed when ``prediction`` is None.
            use_compiled: Use the compiled scan and fit (:mod:`vision.kernels`) when
                they are available; False runs the numpy reference (same results).

        Returns:
            An :class:`EdgeDetection` (``expected_points = n_circles``).
        """
        from vision import kernels

        if prediction is None:
            if geometry is None:
                raise DetectionError("prediction", "give a prediction or the geometry")
            prediction = self.default_prediction(geometry)
        image = _check_image(image, self.camera)
        refs = self._reference(prediction)
        compiled = use_compiled and kernels.available()
        C = self.n_circles
        if compiled:
            if self._kernel is None:
                self._kernel = kernels.OmniKernel(
                    self._idx, self._base, self._fx, self._fy, self._W, self.radii,
                    self._z, self._px_per_rad, (self.camera.cx, self.camera.cy))
            if self._isotropic:
                normals, vis, cnt, rms, pts = self._kernel.detect(
                    image, refs, prediction.normals, self.min_contrast,
                    self.width_tolerance, self.outlier_px, self.min_points,
                    self.max_rms_px, iterations=1)
                return EdgeDetection(normals, vis, cnt, rms, pts, C)
            pts_a = self._kernel.scan(image, refs, self.min_contrast, self.width_tolerance)
        else:
            pts_a = self._scan(image, refs)
        valid = np.isfinite(pts_a)
        a = np.where(valid, pts_a, 0.0)
        r = self.radii
        px = self.camera.cx + r * np.cos(a)
        py = self.camera.cy + r * np.sin(a)
        if self._isotropic:
            z = self._z
            rho = np.sqrt(np.maximum(1.0 - z * z, 0.0))
            rays = np.stack([rho * np.cos(a), rho * np.sin(a), np.broadcast_to(z, a.shape)], -1)
        else:
            rays = self.camera.lift(np.stack([px, py], -1))
        normals, vis, cnt, rms, inl = _robust_fit(
            rays, valid, self._px_per_rad, prediction.normals, self.outlier_px,
            self.min_points, self.max_rms_px, iterations=1, use_compiled=compiled)
        pts = np.where(inl[..., None], np.stack([px, py], -1), np.nan)
        return EdgeDetection(normals, vis, cnt, rms, pts, C)

    def _scan(self, image: np.ndarray, refs: tuple[np.ndarray, ...]) -> np.ndarray:
        """The numpy circle scan: azimuths (6, 2, C) of the edge points [rad] (NaN
        where none), the reference of the compiled ``omni_scan``."""
        flat = np.ravel(image)
        sig = flat[self._idx]
        C, N = sig.shape
        lo = sig.min(axis=1)
        # The background level of a circle is its (lower) median: the legs cover a
        # small part of every circle, while its maximum may be a bright object.
        bg = np.partition(sig, (N - 1) // 2, axis=1)[:, (N - 1) // 2]
        thr_i = ((lo.astype(np.uint16) + bg + 1) // 2).astype(np.uint8)
        thr_i[(bg.astype(float) - lo) < self.min_contrast] = 0  # flat circle: no band
        dark = (sig < thr_i[:, None]).view(np.int8)
        # Transitions: +1 = first dark sample of a band, -1 = first bright after it.
        step = np.empty_like(dark)
        np.subtract(dark[:, 1:], dark[:, :-1], out=step[:, 1:])
        np.subtract(dark[:, :1], dark[:, -1:], out=step[:, :1])
        c_t, j_t = np.nonzero(step)
        is_start = step[c_t, j_t] > 0
        c_s, j_s = c_t[is_start], j_t[is_start]
        c_e, j_e = c_t[~is_start], j_t[~is_start]
        axis_ref, gate_ref, width_ref, e1_first_ref = refs
        pts_a = np.full((6, 2, C), np.nan)  # azimuth of each edge point [rad]
        if c_s.size:
            # Pair each band start with the next end on the same circle (wrapping).
            key_e = c_e * N + j_e
            idx = np.searchsorted(key_e, c_s * N + j_s)
            first = np.searchsorted(key_e, c_s * N)
            wrap = (idx >= key_e.size) | (c_e[np.minimum(idx, key_e.size - 1)] != c_s)
            je = j_e[np.where(wrap, first, idx)]
            a_c = (j_s + 0.5 * ((je - j_s) % N)) * (2 * np.pi / N)  # coarse centre
            width = ((je - j_s) % N) * (2 * np.pi / N)
            diff = np.abs(_wrap(a_c[:, None] - axis_ref[:, c_s].T))  # (nb, 6)
            leg = np.argmin(diff, axis=1)
            dbest = diff[np.arange(leg.size), leg]
            w_ref = width_ref[leg, c_s]
            tol = self.width_tolerance
            ok = (dbest < gate_ref[leg, c_s]) & (width < tol * w_ref + 2 * np.pi / N) & (
                width > w_ref / tol - 2 * np.pi / N)
            if np.any(ok):
                c_k, leg_k, d_k, js, jek = c_s[ok], leg[ok], dbest[ok], j_s[ok], je[ok]
                # One band per (circle, leg): the nearest to the prediction.
                key = c_k * 6 + leg_k
                order = np.lexsort((d_k, key))
                ks = key[order]
                keep = order[np.concatenate([[True], ks[1:] != ks[:-1]])]
                c_k, leg_k, js, jek = c_k[keep], leg_k[keep], js[keep], jek[keep]
                # Sub-sample edges: the strongest gradient of the edge's polarity
                # (falling at a band start, rising at its end) among the central
                # differences at samples j-2 .. j+1 of the bilinear signal, refined
                # by a parabola through it and its neighbours.
                cc = np.concatenate([c_k, c_k])
                jj = np.concatenate([js, jek])
                sign = np.concatenate([np.full(js.size, -1.0), np.full(jek.size, 1.0)])
                b = np.stack([self._bilinear(flat, cc, (jj + o) % N) for o in range(-3, 3)],
                             axis=-1)
                g = 0.5 * (b[:, 2:] - b[:, :-2]) * sign[:, None]  # at samples j-2 .. j+1
                rows = np.arange(jj.size)
                kk = np.clip(np.argmax(g, axis=1), 1, 2)
                gm, g0, gp = g[rows, kk - 1], g[rows, kk], g[rows, kk + 1]
                den = gm - 2 * g0 + gp
                with np.errstate(invalid="ignore", divide="ignore"):
                    frac = np.where(den < 0, 0.5 * (gm - gp) / den, 0.0)
                frac = np.clip(frac, -0.5, 0.5)
                ang = (jj - 2 + kk + frac) * (2 * np.pi / N)
                n_k = c_k.size
                a_start, a_end = ang[:n_k], ang[n_k:]
                first1 = e1_first_ref[leg_k, c_k]
                pts_a[leg_k, 0, c_k] = np.where(first1, a_start, a_end)
                pts_a[leg_k, 1, c_k] = np.where(first1, a_end, a_start)
        return pts_a


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2 * np.pi) - np.pi


# ============================================================================
# Perspective camera: moving-edges tracker
# ============================================================================
class PerspectiveTracker:
    """Tracker of the two edges of each leg in a perspective image.

    Args:
        camera: The (estimated) perspective camera (lifts the edge pixels).
        n_samples: Sample points per edge.
        search_px: Half-length of the 1D search along the normal [px].
        refine_px: Half-length of the second, narrow pass around the first fit [px]
            (0: no second pass).
        min_contrast: Minimal gradient of a valid edge point [grey levels per px].
        end_margin: Fraction of the segment left out at each end (joints, caps).
        occlusion_margin_px: Samples closer than this to another leg's predicted band
            are not used [px].
        min_points: Minimal number of inliers for an edge.
        outlier_px: Inlier distance to the robust line [px].
        max_rms_px: An edge whose inliers' RMS distance exceeds this is missing [px].
    """

    def __init__(
        self,
        camera: Camera,
        n_samples: int = 24,
        search_px: float = 12.0,
        refine_px: float = 0.0,
        min_contrast: float = 12.0,
        end_margin: float = 0.06,
        occlusion_margin_px: float = 3.0,
        min_points: int = 6,
        outlier_px: float = 1.0,
        max_rms_px: float = 0.8,
    ) -> None:
        if not isinstance(camera, PerspectiveCamera) and camera.xi != 0:
            raise DetectionError("camera", "the tracker needs a perspective camera")
        if n_samples < 4:
            raise DetectionError("n_samples", f"must be >= 4, got {n_samples}")
        if search_px < 1:
            raise DetectionError("search_px", f"must be >= 1, got {search_px}")
        self.camera = camera
        self.n_samples = int(n_samples)
        self.search_px = float(search_px)
        self.refine_px = float(refine_px)
        self.min_contrast = float(min_contrast)
        self.end_margin = float(end_margin)
        self.occlusion_margin_px = float(occlusion_margin_px)
        self.min_points = int(min_points)
        self.outlier_px = float(outlier_px)
        self.max_rms_px = float(max_rms_px)
        self._Kinv = np.linalg.inv(camera.K)
        self._f = 0.5 * (camera.fx + camera.fy)
        self._kernel: Any = None  # vision.kernels.TrackKernel, built on first use

    # ----------------------------------------------------------------- geometry
    def predicted_segments(self, prediction: LegPrediction) -> np.ndarray:
        """(6, 2, 2, 2) pixel end points of the predicted edges: the projections of the
        limb end points ``A + r n + s q u`` (s = 0, 1), moved onto the predicted line."""
        A, u, q, r, n = (prediction.base_points, prediction.directions, prediction.lengths,
                         prediction.radius, prediction.normals)
        s = np.array([0.0, 1.0])
        P = (A[:, None, None, :] + r * n[:, :, None, :]
             + (s[None, None, :, None] * q[:, None, None, None]) * u[:, None, None, :])
        pix, _ = self.camera.project(P)
        lines = _pixel_lines(self.camera, n)  # (6, 2, 3), (a, b) unit
        d = np.sum(lines[:, :, None, :2] * pix, -1) + lines[:, :, None, 2]
        return pix - d[..., None] * lines[:, :, None, :2]

    def detect(
        self, image: np.ndarray, prediction: LegPrediction,
        search_px: float | None = None, refine_px: float | None = None,
        use_compiled: bool = True,
    ) -> EdgeDetection:
        """Find the twelve edges near their prediction.

        Args:
            image: (height, width) uint8 grey image (BGR is converted).
            prediction: Predicted legs in the estimated camera frame.
            search_px: Overrides the search half-length of this call [px].
            refine_px: Overrides the second-pass half-length of this call [px].
            use_compiled: Use the compiled robust fit (:mod:`vision.kernels`) when it
                is available; False runs the numpy reference (same results).

        Returns:
            An :class:`EdgeDetection` (``expected_points = n_samples``).
        """
        image = _check_image(image, self.camera)
        search = self.search_px if search_px is None else float(search_px)
        refine = self.refine_px if refine_px is None else float(refine_px)
        seg = self.predicted_segments(prediction)
        lines = _pixel_lines(self.camera, prediction.normals)
        det = self._pass(image, seg, lines, prediction, search, use_compiled)
        if refine > 0:
            ok = det.edge_visible
            l2 = np.where(ok[..., None], _pixel_lines(self.camera, det.normals), lines)
            d = np.sum(l2[:, :, None, :2] * seg, -1) + l2[:, :, None, 2]
            seg2 = seg - d[..., None] * l2[:, :, None, :2]
            pred2 = prediction.with_normals(det.normals)
            det = self._pass(image, seg2, l2, pred2, np.where(ok, refine, search),
                             use_compiled)
        return det

    def _pass(
        self, image: np.ndarray, seg: np.ndarray, lines: np.ndarray,
        prediction: LegPrediction, search: float | np.ndarray, use_compiled: bool = True,
    ) -> EdgeDetection:
        """One search pass: profiles along the normals of the predicted edges, the
        strongest gradient of the right polarity on each, occlusion gate, Theil-Sen
        line, robust plane fit. The compiled core (:class:`vision.kernels.TrackKernel`)
        computes the same as :meth:`_profile_offsets`, :meth:`_contested`,
        :func:`_theil_sen_inliers` and :func:`_robust_fit` below."""
        from vision import kernels

        M = self.n_samples
        t, P, out = self._samples(seg, lines)
        search_arr = np.broadcast_to(np.asarray(search, float), (6, 2))
        R = math.ceil(float(np.max(search_arr)))
        if use_compiled and kernels.available():
            if self._kernel is None:
                self._kernel = kernels.TrackKernel(self.camera.width, self.camera.height, M)
            normals, vis, cnt, rms, pts = self._kernel.track(
                image, P, out, search_arr, R, t, seg, lines, prediction.normals,
                self.occlusion_margin_px, self.min_contrast, self.outlier_px, self._Kinv,
                self._f, (self.camera.cx, self.camera.cy), self.min_points, self.max_rms_px,
                iterations=2)
            return EdgeDetection(normals, vis, cnt, rms, pts, M)
        offset, valid = self._profile_offsets(image, P, out, search_arr, R)
        valid &= ~self._contested(P, seg, lines)
        valid &= _theil_sen_inliers(offset, valid, t, 2.0 * self.outlier_px)
        pts = P + offset[..., None] * out[:, :, None, :]
        pts = np.where(valid[..., None], pts, np.nan)
        rays = self._lift(np.where(valid[..., None], pts, 0.0))
        normals, vis, cnt, rms, inl = _robust_fit(
            rays, valid, self._px_per_rad(pts), prediction.normals, self.outlier_px,
            self.min_points, self.max_rms_px, use_compiled=False)
        return EdgeDetection(normals, vis, cnt, rms, np.where(inl[..., None], pts, np.nan), M)

    def _samples(self, seg: np.ndarray, lines: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Positions ``t`` (M,) along the segments, sample points ``P`` (6, 2, M, 2) [px]
        and the outward unit normals ``out`` (6, 2, 2) (away from the leg's other edge)."""
        M = self.n_samples
        m = self.end_margin
        t = m + (1 - 2 * m) * (np.arange(M) + 0.5) / M  # (M,)
        p0, p1 = seg[:, :, 0, :], seg[:, :, 1, :]
        P = p0[:, :, None, :] + t[None, None, :, None] * (p1 - p0)[:, :, None, :]  # (6,2,M,2)
        nrm = lines[..., :2]  # unit (a, b): the line normal in pixels
        other = lines[:, ::-1]
        side = np.sum(other[:, :, None, :2] * P, -1) + other[:, :, None, 2]  # (6,2,M)
        sgn = np.sign(np.sum(side, -1) * np.sum(nrm * other[..., :2], -1))  # (6, 2)
        out = nrm * np.where(sgn == 0, 1.0, sgn)[..., None]
        return t, P, out

    def track(
        self, image: np.ndarray, prediction: LegPrediction,
        previous: np.ndarray | None = None, align_px: float = 40.0, refine_px: float = 4.0,
    ) -> EdgeDetection:
        """Detect the edges of one frame of a sequence (the policy of every caller).

        Edges found in the previous frame (finite rows of ``previous``) are searched
        around their last position (``search_px``); if any edge was not found, the
        model prediction is first aligned with the image (:meth:`align`, translations
        up to ``align_px``) and gives the others. A second pass of ``refine_px``
        around the first fit ends every frame, so that the final samples depend on
        the detected lines, not on the history of predictions (the goal image and the
        images near it are measured alike).

        Args:
            image: (height, width) uint8 grey image (BGR is converted).
            prediction: The model's prediction (e.g. at the pose of the measured leg
                lengths) in the estimated camera frame.
            previous: (6, 2, 3) normals of the previous frame, NaN where not found
                (None: first frame).
            align_px: Largest translation of the alignment [px] (0: no alignment).
            refine_px: Half-length of the final pass [px] (0: none).

        Returns:
            An :class:`EdgeDetection`.
        """
        tracked = np.zeros((6, 2), bool)
        if previous is not None:
            prev = np.asarray(previous, float)
            if prev.shape != (6, 2, 3):
                raise DetectionError("previous", f"expected shape (6, 2, 3), got {prev.shape}")
            tracked = np.all(np.isfinite(prev), axis=-1)
        base = prediction
        if not tracked.all() and align_px > 0:
            _, base = self.align(image, prediction, align_px)
        if tracked.any():
            base = base.with_normals(np.where(tracked[..., None], prev, np.nan))
        return self.detect(image, base, self.search_px, refine_px)

    def align(
        self, image: np.ndarray, prediction: LegPrediction, max_shift_px: float = 40.0,
        use_compiled: bool = True,
    ) -> tuple[np.ndarray, LegPrediction]:
        """The image translation that best aligns the predicted edges with the image.

        A calibration error (camera pose, intrinsics) moves the whole image of the
        robot by about the same amount, often more than the tracker's search window:
        a per-edge search then picks whatever strong edge of the right polarity is
        nearest, possibly another leg's limb. Instead, every edge's gradient response
        towards the bright outside (positive part, summed over its samples outside
        the other legs' predicted bands) is read as a function of the offset along
        its normal, and the one translation ``(dx, dy)`` maximising the total
        response of the twelve edges (integer pixels within ``max_shift_px``) is
        kept: an edge of another leg in one window cannot outvote the others.

        Args:
            image: (height, width) uint8 grey image.
            prediction: Predicted legs in the estimated camera frame.
            max_shift_px: Largest translation tried in each axis [px].
            use_compiled: Use the compiled core (:func:`vision.kernels.align_shift`)
                when it is available; False runs the numpy reference (same shift).

        Returns:
            ``shift`` (2,) [px] and the prediction with its edges moved by it.
        """
        from vision import kernels

        image = _check_image(image, self.camera)
        if not max_shift_px >= 1:
            raise DetectionError("max_shift_px", f"must be >= 1, got {max_shift_px}")
        seg = self.predicted_segments(prediction)
        lines = _pixel_lines(self.camera, prediction.normals)
        _, P, out = self._samples(seg, lines)
        R = math.ceil(float(max_shift_px)) + 1
        if use_compiled and kernels.available():
            shift = kernels.align_shift(image, P, out, seg, lines, self.occlusion_margin_px,
                                        R, float(max_shift_px))
        else:
            shift = self._align_numpy(image, P, out, seg, lines, R, float(max_shift_px))
        moved = lines.copy()
        moved[..., 2] -= moved[..., 0] * shift[0] + moved[..., 1] * shift[1]
        with np.errstate(invalid="ignore", divide="ignore"):  # any camera with xi = 0
            n = moved @ self.camera.K
            n /= np.linalg.norm(n, axis=-1, keepdims=True)
        return shift, prediction.with_normals(n)

    def _align_numpy(self, image: np.ndarray, P: np.ndarray, out: np.ndarray, seg: np.ndarray,
                     lines: np.ndarray, R: int, max_shift_px: float) -> np.ndarray:
        """The numpy reference of the alignment's shift (see :meth:`align`)."""
        _, grad = _gradient_profiles(image, P, out, R)
        grad = np.maximum(grad, 0.0)
        use = np.all(np.isfinite(P), -1) & ~self._contested(P, seg, lines)
        G = np.sum(np.where(use[..., None], grad, 0.0), axis=2)  # (6, 2, 2R - 1)
        G = np.where(np.all(np.isfinite(out), -1)[..., None], G, 0.0)
        d = np.arange(-(R - 1), R, dtype=float)
        d = d[np.abs(d) <= max_shift_px]
        DX, DY = np.meshgrid(d, d, indexing="ij")
        o = DX.ravel()[:, None, None] * out[..., 0] + DY.ravel()[:, None, None] * out[..., 1]
        o = np.nan_to_num(o, nan=0.0) + (R - 1)  # index into G (S, 6, 2)
        k0 = np.clip(np.floor(o).astype(np.intp), 0, G.shape[-1] - 2)
        w = np.clip(o - k0, 0.0, 1.0)
        ii, jj = np.meshgrid(np.arange(6), np.arange(2), indexing="ij")
        score = np.sum((1 - w) * G[ii, jj, k0] + w * G[ii, jj, k0 + 1], axis=(1, 2))
        best = int(np.argmax(score))
        return np.array([DX.ravel()[best], DY.ravel()[best]])

    def _profile_offsets(
        self, image: np.ndarray, P: np.ndarray, out: np.ndarray, search: np.ndarray, R: int,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Edge offset along ``out`` of every sample [px] and whether it is valid.

        The profile through sample ``P`` is read at the integer offsets ``-R .. R``
        along ``out`` (exact bilinear interpolation, 0 outside the image); its central
        difference at the offsets ``o`` with ``|o| <= search`` whose point lies in the
        image is the gradient towards the outside (bright). The strongest one (the
        first on ties) is refined by a parabola through it and its neighbours (no
        refinement when a neighbour is not a candidate); it is valid if at least
        ``min_contrast`` and not at ``o = +-(R - 1)``.
        """
        Q, grad = _gradient_profiles(image, P, out, R)
        finite = np.all(np.isfinite(Q), axis=(-2, -1))
        g_off = np.arange(-(R - 1), R, dtype=float)
        candidate = np.abs(g_off)[None, None, None, :] <= search[..., None, None]
        Qg = Q[..., 1:-1, :]
        in_img = ((Qg[..., 0] >= 0) & (Qg[..., 0] <= self.camera.width - 1)
                  & (Qg[..., 1] >= 0) & (Qg[..., 1] <= self.camera.height - 1))
        g = np.where(candidate & in_img, grad, _NO_GRADIENT)
        L = g.shape[-1]
        k = np.argmax(g, axis=-1)
        km = np.clip(k, 1, max(L - 2, 1))
        gk = np.take_along_axis(g, k[..., None], -1)[..., 0]
        if L >= 3:
            gm, g0, gp = (np.take_along_axis(g, (km + d)[..., None], -1)[..., 0]
                          for d in (-1, 0, 1))
        else:
            gm = g0 = gp = np.zeros(k.shape)
        den = gm - 2 * g0 + gp
        with np.errstate(invalid="ignore", divide="ignore"):
            frac = np.where((den < 0) & (den > -1e5), 0.5 * (gm - gp) / den, 0.0)
        frac = np.clip(frac, -0.5, 0.5)
        offset = g_off[km] + frac if L >= 1 else np.zeros(k.shape)
        valid = finite & (gk >= self.min_contrast) & (k == km) & (L >= 3)
        return offset, valid

    def _lift(self, pix: np.ndarray) -> np.ndarray:
        h = np.concatenate([pix, np.ones((*pix.shape[:-1], 1))], -1) @ self._Kinv.T
        return h / np.linalg.norm(h, axis=-1, keepdims=True)

    def _px_per_rad(self, pts: np.ndarray) -> np.ndarray:
        # Distance to a line in pixels ~ angle * f / cos^2 of the ray angle (at most):
        # |n.X| is the sine of the angle between the ray and the plane; one pixel
        # across the line at radius rho from the centre is about f / (f^2 + rho^2)
        # ^(1/2) * cos... use the local scale f * (1 + (rho/f)^2) ^ 0.5.
        d = np.nan_to_num(pts - np.array([self.camera.cx, self.camera.cy]))
        rho2 = np.sum(d * d, -1) / self._f**2
        return self._f * np.sqrt(1.0 + rho2)

    def _contested(self, P: np.ndarray, seg: np.ndarray, lines: np.ndarray) -> np.ndarray:
        """(6, 2, M): samples inside (or within the margin of) another leg's band."""
        mg = self.occlusion_margin_px
        # Signed distances of every sample to both edge lines of every leg k.
        d = (np.einsum("ijmx,kex->ijmke", P, lines[..., :2]) + lines[None, None, None, :, :, 2])
        # Inside leg k: on opposite sides of its two lines (the band between them).
        d1, d2 = d[..., 0], d[..., 1]
        s1 = np.sign(np.sum(lines[:, 0, :2] * lines[:, 1, :2], -1))  # (6,) same/opposite normals
        between = (d1 * d2 * s1 <= 0) | (np.abs(d1) < mg) | (np.abs(d2) < mg)
        # Within the leg's extent along its axis (with the margin).
        c0 = 0.5 * (seg[:, 0, 0] + seg[:, 1, 0])  # (6, 2) base end centre
        c1 = 0.5 * (seg[:, 0, 1] + seg[:, 1, 1])
        ax = c1 - c0
        L = np.linalg.norm(ax, axis=-1)
        with np.errstate(invalid="ignore", divide="ignore"):
            axu = ax / L[:, None]
        tt = np.einsum("ijmkx,kx->ijmk", P[:, :, :, None, :] - c0, axu)
        along = (tt >= -mg) & (tt <= L + mg)
        hit = between & along & np.isfinite(tt)
        hit &= ~np.eye(6, dtype=bool)[:, None, None, :]
        return np.any(hit, axis=-1)


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
    """Profiles through the samples ``P`` (..., M, 2) along ``out`` (..., 2): the points
    ``Q`` (..., M, 2R + 1, 2) at the integer offsets ``-R .. R`` [px] and the central
    differences (..., M, 2R - 1) of the bilinear signal at the offsets ``-(R-1) .. R-1``
    (positive towards the bright side of an edge whose outside is along ``out``)."""
    offs = np.arange(-R, R + 1, dtype=float)
    Q = P[..., :, None, :] + offs[:, None] * out[..., None, None, :]
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


# ============================================================================
# Display
# ============================================================================
def draw_detection(
    image: np.ndarray, camera: Camera, detection: EdgeDetection,
    colors: tuple[tuple[int, int, int], tuple[int, int, int]] = ((0, 0, 255), (255, 128, 0)),
) -> np.ndarray:
    """A BGR copy of the image with the detected edges (fitted curves over the span of
    their inlier points) and the inlier points drawn over it.

    Edge 1 in the first colour, edge 2 in the second (BGR).
    """
    out = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR) if image.ndim == 2 else image.copy()
    for i in range(6):
        for j in range(2):
            if not detection.edge_visible[i, j]:
                continue
            n = detection.normals[i, j]
            p = detection.points[i, j]
            p = p[np.all(np.isfinite(p), -1)]
            X = camera.lift(p)
            X = X - np.outer(X @ n, n)
            X /= np.linalg.norm(X, axis=-1, keepdims=True)
            # Extreme points along the great circle, then slerp between them.
            ref = X[0]
            tang = np.cross(n, ref)
            ang = np.arctan2(X @ tang, X @ ref)
            a = np.linspace(ang.min(), ang.max(), 40)
            arc = np.cos(a)[:, None] * ref + np.sin(a)[:, None] * tang
            pix, _ = camera.project(arc)
            pix = pix[np.all(np.isfinite(pix), -1)]
            cv2.polylines(out, [np.round(pix * 16).astype(np.int32)], False, colors[j], 1,
                          cv2.LINE_AA, 4)
            for q in p:
                cv2.circle(out, (round(q[0] * 16), round(q[1] * 16)), 2 * 16,
                           colors[j], 1, cv2.LINE_AA, 4)
    return out


__all__ = [
    "DetectionError",
    "EdgeDetection",
    "LegPrediction",
    "OmniDetector",
    "PerspectiveTracker",
    "draw_detection",
    "fit_normals",
]
