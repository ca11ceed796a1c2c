"""Image sensor for the closed-loop simulator: render, detect, estimate at every step.

The true camera and the true robot render the image; the detection and the fit of
the normals use the *estimated* camera (intrinsics and pose): the measured normals
are what a real system would compute from the same pixels, so calibration errors
of the camera reach the features exactly as they would on the robot.

Detection (:meth:`vision.detect.PerspectiveTracker.track`, the policy shared with
the servo loop's cameras): the model at the pose being measured, seen by the
estimated camera, is what the forward kinematics of the encoder readings gives with
the calibrated model. Edges found in the previous frame (``predicted_normals``,
NaN where not found) are searched ``+-search_px`` around their last position; when
some edge was not found, the model prediction is first aligned with the image (one
translation up to ``align_px``, which absorbs the image offset of the calibration
error); a final pass of ``refine_px`` ends every frame. The omnidirectional
detector scans the whole image and uses the prediction only to associate bands
with legs.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np

from hexapod.geometry import HexapodGeometry
from vision.cameras import Camera, PerspectiveCamera
from vision.detect import (
    EdgeDetection,
    LegPrediction,
    OmniDetector,
    PerspectiveTracker,
)
from vision.exposure import middle_pose, render_exposed
from vision.render import Renderer, RenderStyle

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class ImageMeasurement:
    """Features measured in one rendered image.

    Attributes:
        normals: (6, 2, 3) edge normals in the estimated camera frame (NaN if missing).
        lines: (6, 2, 3) unit lines in normalised pixel coordinates
            (:meth:`PerspectiveCamera.normal_to_line` of the estimated camera), NaN if
            missing; None for a unified camera.
        edge_visible: (6, 2) the edge was detected.
        quality: (6, 2) fraction of the possible edge points that are inliers (0 if
            missing).
        n_points: (6, 2) inlier points of each edge.
        residual_px: (6, 2) RMS distance of the inliers to the fitted edge [px].
        render_time_s: Time spent rendering [s].
        detect_time_s: Time spent detecting and fitting [s].
        detection: The full detection (edge points, for display).
    """

    normals: np.ndarray
    lines: np.ndarray | None
    edge_visible: np.ndarray
    quality: np.ndarray
    n_points: np.ndarray
    residual_px: np.ndarray
    render_time_s: float
    detect_time_s: float
    detection: EdgeDetection


class ImageSensor:
    """Renders the legs, detects their edges and fits the normals.

    Args:
        true_camera: Camera that takes the picture (true intrinsics and pose).
        estimated_camera: Camera model used to interpret it (same kind and size).
        geometry: The true robot (rendering).
        rng: Generator (or seed) of the pixel noise.
        background: ``"plain"`` or ``"cluttered"``.
        blur_px: Gaussian blur of the optics [px].
        noise_std: Pixel noise [grey levels].
        estimated_geometry: The robot model used for predictions (default: ``geometry``).
        style: Full rendering style (overrides ``background``, ``blur_px`` and
            ``noise_std`` when given).
        search_px: Search half-length of the perspective tracker around the
            previous detection or the aligned prediction [px].
        align_px: Largest image translation between the model prediction and the
            image tried by the alignment [px]. It must cover the image error of the
            calibrated model.
        refine_px: Half-length of the final pass [px].
    """

    def __init__(
        self,
        true_camera: Camera,
        estimated_camera: Camera,
        geometry: HexapodGeometry,
        rng: np.random.Generator | int | None = None,
        background: str = "plain",
        blur_px: float = 0.8,
        noise_std: float = 2.0,
        estimated_geometry: HexapodGeometry | None = None,
        style: RenderStyle | None = None,
        search_px: float = 12.0,
        align_px: float = 40.0,
        refine_px: float = 4.0,
    ) -> None:
        if true_camera.family != estimated_camera.family:
            raise ValueError(f"true and estimated cameras differ in kind: {true_camera.kind} "
                             f"vs {estimated_camera.kind}")
        if (true_camera.width, true_camera.height) != (estimated_camera.width,
                                                       estimated_camera.height):
            raise ValueError("true and estimated cameras differ in image size")
        self.true_camera = true_camera
        self.estimated_camera = estimated_camera
        self.geometry = geometry
        self.estimated_geometry = geometry if estimated_geometry is None else estimated_geometry
        if style is None:
            style = RenderStyle(background=background, blur_px=blur_px, noise_std=noise_std)
        self.renderer = Renderer(true_camera, geometry, style, rng)
        self.detector: OmniDetector | PerspectiveTracker
        if isinstance(estimated_camera, PerspectiveCamera):
            self.detector = PerspectiveTracker(estimated_camera, search_px=search_px)
        else:
            self.detector = OmniDetector(estimated_camera)
        self.search_px = float(search_px)
        self.align_px = float(align_px)
        self.refine_px = float(refine_px)
        self.last_image: np.ndarray | None = None

    def predict(
        self, rotation: np.ndarray, translation: np.ndarray,
        predicted_normals: np.ndarray | None = None,
    ) -> LegPrediction:
        """The prediction given to the detector (see the module docstring)."""
        pred = LegPrediction.from_pose(self.estimated_camera, self.estimated_geometry,
                                       rotation, translation)
        if predicted_normals is not None:
            pred = pred.with_normals(predicted_normals)
        return pred

    def measure(
        self, rotation: np.ndarray, translation: np.ndarray,
        predicted_normals: np.ndarray | None = None,
    ) -> ImageMeasurement:
        """Render the robot at a pose and measure the leg edges in the image.

        Args:
            rotation: (3, 3) true platform orientation in the base frame, or (S, 3, 3)
                the orientations along the exposure (motion blur,
                :func:`vision.exposure.render_exposed`).
            translation: (3,) true platform position in the base frame [m], or (S, 3).
            predicted_normals: (6, 2, 3) normals found in the previous frame, in the
                estimated camera frame, NaN where not found (None: first frame).

        Returns:
            An :class:`ImageMeasurement`.
        """
        t0 = time.perf_counter()
        image = render_exposed(self.renderer, rotation, translation)
        t1 = time.perf_counter()
        pred = self.predict(*middle_pose(rotation, translation))
        det = self.detector.track(image, pred, predicted_normals, self.align_px,
                                  self.refine_px)
        lines = None
        if isinstance(self.estimated_camera, PerspectiveCamera):
            with np.errstate(invalid="ignore"):
                lines = self.estimated_camera.normal_to_line(det.normals)
        t2 = time.perf_counter()
        self.last_image = image
        return ImageMeasurement(
            normals=det.normals, lines=lines, edge_visible=det.edge_visible,
            quality=det.quality, n_points=det.n_points, residual_px=det.residual,
            render_time_s=t1 - t0, detect_time_s=t2 - t1, detection=det,
        )
