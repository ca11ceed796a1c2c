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
from vision.legs import (
    EdgePoints,
    LegObservation,
    directions_from_edges,
    edge_points,
    leg_edges,
    limb_points,
    observation_edge_points,
    observe_legs,
)

__all__ = [
    "Camera",
    "CameraError",
    "EdgePoints",
    "EstimationError",
    "LegObservation",
    "PerspectiveCamera",
    "UnifiedCamera",
    "VisionError",
    "camera_preset",
    "directions_from_edges",
    "edge_points",
    "front_camera",
    "leg_edges",
    "limb_points",
    "load_camera",
    "observation_edge_points",
    "observe_legs",
    "omni_camera",
]
