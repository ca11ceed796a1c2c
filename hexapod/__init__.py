"""Gough-Stewart platform: geometry, kinematics, closed-chain Pinocchio model, backends.

The robot knows nothing of cameras or controllers (the layers: ``docs/architecture.md``).

The closed-chain model and the forward kinematics (Pinocchio, CasADi: about 0.3 s to
import) load on first use of one of their names (``hexapod.build_model``,
``hexapod.forward_kinematics``, ...): importing ``hexapod.exceptions`` or
``hexapod.geometry`` does not pay for them.
"""

import importlib
from typing import TYPE_CHECKING, Any

from hexapod.exceptions import (
    BackendError,
    ConfigFileError,
    ForwardKinematicsError,
    GeometryError,
    HexapodError,
    ShapeError,
    StrokeLimitError,
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
from hexapod.workspace import extremal_configurations, home_pose, sample_poses

if TYPE_CHECKING:
    from hexapod.fk import (
        BatchForwardKinematicsResult,
        ForwardKinematicsResult,
        forward_kinematics,
        forward_kinematics_batch,
    )
    from hexapod.model import HexapodModel, build_model

#: The names loaded on first use, and their modules.
_LAZY = {
    "BatchForwardKinematicsResult": "hexapod.fk",
    "ForwardKinematicsResult": "hexapod.fk",
    "forward_kinematics": "hexapod.fk",
    "forward_kinematics_batch": "hexapod.fk",
    "HexapodModel": "hexapod.model",
    "build_model": "hexapod.model",
}

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


def __getattr__(name: str) -> Any:
    """The names of :data:`_LAZY`, imported on first use (PEP 562)."""
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'hexapod' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_LAZY})
