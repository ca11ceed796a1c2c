"""Gough-Stewart platform: geometry, kinematics, closed-chain Pinocchio model, backends.

The robot knows nothing of cameras or controllers (see ``docs/architecture.md``).
"""

from hexapod.exceptions import (
    BackendError,
    ConfigFileError,
    ForwardKinematicsError,
    GeometryError,
    HexapodError,
    ShapeError,
    StrokeLimitError,
)
from hexapod.fk import (
    BatchForwardKinematicsResult,
    ForwardKinematicsResult,
    forward_kinematics,
    forward_kinematics_batch,
)
from hexapod.geometry import HexapodGeometry, deltalab, preset
from hexapod.kinematics import (
    LegState,
    Transform,
    inverse_jacobian,
    inverse_kinematics,
    leg_directions,
    leg_vectors,
    legs_in_frame,
    platform_points_in_base,
)
from hexapod.model import HexapodModel, build_model
from hexapod.workspace import extremal_configurations, home_pose, sample_poses

__version__ = "0.1.0"

__all__ = [
    "BackendError",
    "BatchForwardKinematicsResult",
    "ConfigFileError",
    "ForwardKinematicsError",
    "ForwardKinematicsResult",
    "GeometryError",
    "HexapodError",
    "HexapodGeometry",
    "HexapodModel",
    "LegState",
    "ShapeError",
    "StrokeLimitError",
    "Transform",
    "build_model",
    "deltalab",
    "extremal_configurations",
    "forward_kinematics",
    "forward_kinematics_batch",
    "home_pose",
    "inverse_jacobian",
    "inverse_kinematics",
    "leg_directions",
    "leg_vectors",
    "legs_in_frame",
    "platform_points_in_base",
    "preset",
    "sample_poses",
]
