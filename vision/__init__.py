"""Vision: cameras (perspective, unified), cylindrical legs as image features, noise,
estimation of interpretation-plane normals (``MATH.md`` sections 4, 5 and 8)."""

from vision.cameras import (
    Camera,
    PerspectiveCamera,
    UnifiedCamera,
    camera_preset,
    front_camera,
    load_camera,
    omni_camera,
)
from vision.exceptions import CameraError, EstimationError, VisionError
from vision.legs import directions_from_edges, leg_edges

__all__ = [
    "Camera",
    "CameraError",
    "EstimationError",
    "PerspectiveCamera",
    "UnifiedCamera",
    "VisionError",
    "camera_preset",
    "directions_from_edges",
    "front_camera",
    "leg_edges",
    "load_camera",
    "omni_camera",
]
