"""The Cartesian coordinates of a PI hexapod (X, Y, Z, U, V, W) and the platform pose.

A GCS hexapod controller is commanded in six coordinates about its *pivot point*:

- X, Y, Z: the translation of the pivot point from where it is at the zero position,
  along the axes of the spatially fixed (base) frame [m here, mm on the wire];
- U, V, W: rotations about the X, Y and Z axes through the pivot point [rad here, deg on
  the wire]. PI's hexapod manuals state that the rotational axes (and the pivot point)
  move with the platform and that a rotation is "calculated from the individual
  rotations in the order U -> V -> W". Read as intrinsic rotations about moving axes,
  that is ``R = Rx(U) Ry(V) Rz(W)`` (``"moving-xyz"``, the default). The other reading,
  rotations about the fixed axes in the same order (``R = Rz(W) Ry(V) Rx(U)``), is
  ``"fixed-xyz"``. The choice is configurable because it was not verified against a
  controller (``docs/backends.md``).
- the pivot point ``(R, S, T)`` (``SPI``) is a point fixed to the platform, given in
  the platform frame [m here, mm on the wire].

The zero position (all six coordinates 0) is the platform frame at ``zero`` (a pose
in the base frame: by default the home pose of the geometry, parallel to the base,
centred, every leg near mid-stroke). Then the platform frame ``e`` is at::

    R_e = R_0 R(U, V, W)
    t_e = t_0 + (X, Y, Z) + R_0 p - R_0 R(U, V, W) p          (p: the pivot point)

so the pivot point moves by (X, Y, Z) only and the rotation turns about it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hexapod.exceptions import ShapeError
from hexapod.geometry import HexapodGeometry

#: The rotation conventions :class:`PoseConvention` knows.
ROTATION_ORDERS = ("moving-xyz", "fixed-xyz")


def _rx(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _ry(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _rz(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rotation_from_uvw(u: float, v: float, w: float, order: str = "moving-xyz") -> np.ndarray:
    """The rotation of U, V, W [rad] in a convention of :data:`ROTATION_ORDERS`."""
    if order == "moving-xyz":
        return _rx(u) @ _ry(v) @ _rz(w)
    if order == "fixed-xyz":
        return _rz(w) @ _ry(v) @ _rx(u)
    raise ValueError(f"unknown rotation order {order!r}; use one of {ROTATION_ORDERS}")


def uvw_from_rotation(R: np.ndarray, order: str = "moving-xyz") -> np.ndarray:
    """U, V, W [rad] of a rotation (the inverse of :func:`rotation_from_uvw`; V in
    [-90, 90] deg)."""
    R = np.asarray(R, dtype=float)
    if order == "moving-xyz":
        v = np.arcsin(np.clip(R[0, 2], -1.0, 1.0))
        return np.array([np.arctan2(-R[1, 2], R[2, 2]), v, np.arctan2(-R[0, 1], R[0, 0])])
    if order == "fixed-xyz":
        v = -np.arcsin(np.clip(R[2, 0], -1.0, 1.0))
        return np.array([np.arctan2(R[2, 1], R[2, 2]), v, np.arctan2(R[1, 0], R[0, 0])])
    raise ValueError(f"unknown rotation order {order!r}; use one of {ROTATION_ORDERS}")


@dataclass(frozen=True)
class PoseConvention:
    """How a controller's six coordinates map to the platform pose.

    Attributes:
        zero_rotation: (3, 3) platform orientation at the zero position (base frame).
        zero_translation: (3,) platform frame origin at the zero position [m].
        pivot: (3,) the pivot point in the platform frame [m] (``SPI`` R, S, T).
        rotation_order: ``"moving-xyz"`` or ``"fixed-xyz"`` (module docstring).
    """

    zero_rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    zero_translation: np.ndarray = field(default_factory=lambda: np.zeros(3))
    pivot: np.ndarray = field(default_factory=lambda: np.zeros(3))
    rotation_order: str = "moving-xyz"

    def __post_init__(self) -> None:
        for name, shape in (("zero_rotation", (3, 3)), ("zero_translation", (3,)),
                            ("pivot", (3,))):
            value = np.array(getattr(self, name), dtype=float)
            if value.shape != shape or not np.all(np.isfinite(value)):
                raise ShapeError(name, f"finite values of shape {shape}", value)
            object.__setattr__(self, name, value)
        if self.rotation_order not in ROTATION_ORDERS:
            raise ValueError(f"unknown rotation order {self.rotation_order!r}; use one of "
                             f"{ROTATION_ORDERS}")

    @classmethod
    def for_geometry(cls, geometry: HexapodGeometry, pivot: np.ndarray | None = None,
                     rotation_order: str = "moving-xyz", zero_height: float | None = None
                     ) -> PoseConvention:
        """The convention of a robot whose zero position is its home pose.

        Args:
            geometry: The robot (its ``home_height`` is the zero position's height).
            pivot: The pivot point in the platform frame [m] (origin if None).
            rotation_order: ``"moving-xyz"`` or ``"fixed-xyz"``.
            zero_height: Height of the platform frame at the zero position [m]
                (``geometry.home_height`` if None).
        """
        h = geometry.home_height if zero_height is None else float(zero_height)
        return cls(np.eye(3), np.array([0.0, 0.0, h]),
                   np.zeros(3) if pivot is None else np.asarray(pivot, float), rotation_order)

    def with_pivot(self, pivot: np.ndarray) -> PoseConvention:
        """The same convention about another pivot point [m] (platform frame)."""
        return PoseConvention(self.zero_rotation, self.zero_translation, np.asarray(pivot),
                              self.rotation_order)

    def pose(self, coords: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The platform pose (rotation, translation [m]) of coordinates
        ``(x, y, z [m], u, v, w [rad])``."""
        c = np.asarray(coords, dtype=float)
        if c.shape != (6,):
            raise ShapeError("coords", "(x, y, z, u, v, w)", c.shape)
        R0, t0, p = self.zero_rotation, self.zero_translation, self.pivot
        Ruvw = rotation_from_uvw(c[3], c[4], c[5], self.rotation_order)
        R = R0 @ Ruvw
        return R, t0 + c[:3] + R0 @ p - R @ p

    def coords(self, rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
        """The coordinates ``(x, y, z [m], u, v, w [rad])`` of a platform pose."""
        R = np.asarray(rotation, dtype=float)
        t = np.asarray(translation, dtype=float)
        R0, t0, p = self.zero_rotation, self.zero_translation, self.pivot
        uvw = uvw_from_rotation(R0.T @ R, self.rotation_order)
        xyz = t - t0 - R0 @ p + R @ p
        return np.concatenate([xyz, uvw])


def to_wire(coords: np.ndarray) -> dict[str, float]:
    """SI coordinates -> ``{"X": mm, ..., "U": deg, ...}`` (what ``MOV`` carries)."""
    c = np.asarray(coords, dtype=float)
    return {"X": c[0] * 1e3, "Y": c[1] * 1e3, "Z": c[2] * 1e3,
            "U": float(np.rad2deg(c[3])), "V": float(np.rad2deg(c[4])),
            "W": float(np.rad2deg(c[5]))}


def from_wire(values: dict[str, float]) -> np.ndarray:
    """``{"X": mm, ..., "W": deg}`` (all six) -> SI coordinates ``(x, y, z [m], u, v, w [rad])``."""
    return np.array([values["X"] * 1e-3, values["Y"] * 1e-3, values["Z"] * 1e-3,
                     np.deg2rad(values["U"]), np.deg2rad(values["V"]),
                     np.deg2rad(values["W"])])
