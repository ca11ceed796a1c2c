"""Vision: cameras (perspective, unified), cylindrical legs as image features, noise,
estimation of interpretation-plane normals (``docs/math.md`` sections 4, 5 and 8)."""

from vision.cameras import (
    Camera,
    PerspectiveCamera,
    UnifiedCamera,
    camera_preset,
    front_camera,
    load_camera,
    omni_camera,
)
from vision.estimate import (
    NormalFit,
    angle_between,
    average_normals,
    direction_from_normals,
    fit_normal,
    fit_normal_conic,
    radians_per_pixel,
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
from vision.noise import (
    add_outliers,
    drop_edges,
    pixel_noise,
    random_rotations,
    random_unit_vectors,
    rotation_noise,
)

__all__ = [
    "Camera",
    "CameraError",
    "EdgePoints",
    "EstimationError",
    "LegObservation",
    "NormalFit",
    "PerspectiveCamera",
    "UnifiedCamera",
    "VisionError",
    "add_outliers",
    "angle_between",
    "average_normals",
    "camera_preset",
    "direction_from_normals",
    "directions_from_edges",
    "drop_edges",
    "edge_points",
    "fit_normal",
    "fit_normal_conic",
    "front_camera",
    "leg_edges",
    "limb_points",
    "load_camera",
    "observation_edge_points",
    "observe_legs",
    "omni_camera",
    "pixel_noise",
    "radians_per_pixel",
    "random_rotations",
    "random_unit_vectors",
    "rotation_noise",
]
