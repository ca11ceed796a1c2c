"""Dynamics of the hexapod: inertial and drive parameters, the closed-chain dynamic model.

- :mod:`hexapod.dynamics.inertia`: :class:`InertiaParameters` (the ``[inertia]`` table);
- :mod:`hexapod.dynamics.drives`: :class:`DriveParameters` (the ``[drives]`` table);
- :class:`DynamicModel`: forward and inverse dynamics of the mechanism in the
  platform's coordinates (``docs/dynamics.md``), imported lazily (it needs the
  Pinocchio model, which needs :mod:`hexapod.geometry`, which needs the parameters).
"""

from __future__ import annotations

from typing import Any

from hexapod.dynamics.drives import DriveParameters
from hexapod.dynamics.inertia import InertiaParameters

__all__ = ["DriveParameters", "DynamicModel", "InertiaParameters"]


def __getattr__(name: str) -> Any:
    if name == "DynamicModel":
        from hexapod.dynamics.model import DynamicModel

        return DynamicModel
    raise AttributeError(f"module 'hexapod.dynamics' has no attribute {name!r}")
