"""Cameras that give leg-edge features: a frame source (simulated rendering, a video
file or a device, :mod:`vision.sources`) with the edge detector, tracking the edges from
frame to frame (:meth:`vision.detect.PerspectiveTracker.track`). The real servo loop
(``hexapod-bench servo --camera sim|video:PATH|device:N``) reads its features from them.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from hexapod.geometry import HexapodGeometry
from vision.exceptions import SourceOpenError, SourceSpecError

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Features:
    """Edge features of one image.

    Attributes:
        normals: (6, 2, 3) unit edge normals in the (estimated) camera frame; NaN where
            missing.
        edge_visible: (6, 2) bool, which edges were found.
    """

    normals: np.ndarray
    edge_visible: np.ndarray

    @property
    def visible_count(self) -> int:
        """Number of edges found (0 to 12)."""
        return int(np.count_nonzero(self.edge_visible))



class FeatureSensor(Protocol):
    """A camera that gives the edge features at the current (predicted) pose."""

    lost_frames: int

    def measure(self, rotation: np.ndarray, translation: np.ndarray) -> Features | None:
        """The features of the next image (None for a lost frame)."""

    def close(self) -> None:
        """Release the camera."""


class _TrackingMixin:
    """Keeps the last normals (NaN where an edge was not found) to seed the next
    detection (:meth:`vision.detect.PerspectiveTracker.track`)."""

    previous: np.ndarray | None = None

    def _remember(self, f: Features) -> Features:
        self.previous = np.asarray(f.normals) if bool(np.any(f.edge_visible)) else None
        return f


class SimCamera(_TrackingMixin):
    """``--camera sim``: renders the legs at the given pose and detects their edges.

    The rendered robot and camera are the nominal ones: the pose passed to
    :meth:`measure` (forward kinematics of the measured lengths) is the truth of
    this simulated world.

    Args:
        camera: The camera.
        geometry: The robot.
        seed: Seed of the pixel noise.
        drop_every: Lose one frame in every ``drop_every`` (0: never), to exercise the
            lost-frame path.
    """

    def __init__(self, camera: Any, geometry: HexapodGeometry, seed: int = 0,
                 drop_every: int = 0) -> None:
        from vision.image_sensor import ImageSensor

        self.sensor = ImageSensor(camera, camera, geometry, rng=np.random.default_rng(seed))
        self.drop_every = int(drop_every)
        self.frames = 0
        self.lost_frames = 0

    def measure(self, rotation: np.ndarray, translation: np.ndarray) -> Features | None:
        """Render at ``(rotation, translation)`` (base frame, m) and detect the edges."""
        self.frames += 1
        if self.drop_every and self.frames % self.drop_every == 0:
            self.lost_frames += 1
            return None
        m = self.sensor.measure(rotation, translation, predicted_normals=self.previous)
        return self._remember(Features(np.asarray(m.normals, float),
                                       np.asarray(m.edge_visible, bool)))

    def close(self) -> None:
        """Nothing to release."""


class VideoCamera(_TrackingMixin):
    """``--camera video:PATH`` or ``device:N``: frames through OpenCV, edges detected.

    Args:
        source: Device index or video file path.
        camera: The camera model of the frames (intrinsics, pose).
        geometry: The nominal robot (predictions for the detector).

    Raises:
        SourceOpenError: The device or file cannot be opened.
    """

    def __init__(self, source: int | str, camera: Any, geometry: HexapodGeometry) -> None:
        from vision.detect import OmniDetector, PerspectiveTracker
        from vision.sources import VideoSource

        self.camera = camera
        self.geometry = geometry
        self.source = VideoSource(source, camera)
        self.detector: Any = (PerspectiveTracker(camera) if camera.family == "perspective"
                              else OmniDetector(camera))
        self.lost_frames = 0
        self.ended = False

    def measure(self, rotation: np.ndarray, translation: np.ndarray) -> Features | None:
        """Read the next frame and detect the edges near their prediction at the pose."""
        from vision.detect import LegPrediction

        dropped = self.source.dropped
        frame = self.source.read()
        self.lost_frames += self.source.dropped - dropped
        if frame is None:
            self.ended = not self.source.is_device
            self.lost_frames += 1
            return None
        pred = LegPrediction.from_pose(self.camera, self.geometry, rotation, translation)
        det = self.detector.track(frame.image, pred, self.previous)
        return self._remember(Features(np.asarray(det.normals, float),
                                       np.asarray(det.edge_visible, bool)))

    def close(self) -> None:
        """Release the capture."""
        self.source.close()


def open_camera(spec: str, camera: Any, geometry: HexapodGeometry,
                seed: int = 0) -> FeatureSensor:
    """The feature sensor of a ``--camera`` spec: ``sim``, ``video:PATH`` or ``device:N``.

    Raises:
        SourceSpecError: Unknown spec or bad device number.
        SourceOpenError: The device or file cannot be opened.
    """
    if spec == "sim":
        return SimCamera(camera, geometry, seed)
    kind, _, arg = spec.partition(":")
    if kind == "video" and arg:
        return VideoCamera(arg, camera, geometry)
    if kind == "device" and arg:
        try:
            index = int(arg)
        except ValueError:
            raise SourceSpecError(spec, "the device must be a number (device:0)") from None
        return VideoCamera(index, camera, geometry)
    raise SourceSpecError(spec, "expected sim, video:PATH or device:N")


def check_camera_spec(spec: str) -> None:
    """The refusals of :func:`open_camera` that need nothing opened: an unknown spec, a
    device that is not a number, a ``video:`` file that does not exist (a command checks
    them before it writes anything or connects a robot).

    Raises:
        SourceSpecError: Unknown spec or bad device number.
        SourceOpenError: The ``video:`` file does not exist.
    """
    if spec == "sim":
        return
    kind, _, arg = spec.partition(":")
    if kind == "video" and arg:
        if not Path(arg).is_file():
            raise SourceOpenError(arg, "no such file" if not Path(arg).exists()
                                  else "not a file")
        return
    if kind == "device" and arg:
        try:
            int(arg)
        except ValueError:
            raise SourceSpecError(spec, "the device must be a number (device:0)") from None
        return
    raise SourceSpecError(spec, "expected sim, video:PATH or device:N")


def sensor_camera(sensor: Any) -> Any:
    """The (estimated) camera model a sensor interprets its images with."""
    if isinstance(sensor, SimCamera):
        return sensor.sensor.estimated_camera
    return sensor.camera
