"""The options of the GCS backend (``gcs:URL?key=value&...``) and its system velocity."""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from hexapod.backends.gcs_pose import ROTATION_ORDERS, PoseConvention
from hexapod.exceptions import BackendError
from hexapod.geometry import HexapodGeometry
from hexapod.kinematics import inverse_kinematics

__all__ = ["GcsOptions", "platform_velocity"]


@dataclass(frozen=True)
class GcsOptions:
    """How :class:`GcsHexapod` talks to its controller (``gcs:URL?key=value&...``).

    Attributes:
        vmo: When to ask ``VMO?`` before a ``MOV``: ``"edge"`` (a target leg within
            ``vmo_margin`` of a stroke end), ``"always"`` or ``"never"``.
        vmo_margin: The edge band [m] (``vmo_margin_mm``).
        pivot: Pivot point to set at connect, platform frame [m] (``pivot_mm=R,S,T``);
            None: use the controller's (``SPI?``).
        rotation_order: The controller's U, V, W convention (``rotation``).
        zero_height: Height of the platform frame at the controller's zero position [m]
            (``zero_mm``); None: the nominal home height.
        velocity: ``VLS`` to set [m/s] (``velocity`` in mm/s); None: from the leg speed
            limit (:func:`platform_velocity`).
        timeout: Longest wait for an answer [s].
        baudrate: Baud rate of a serial link (``baud``).
    """

    vmo: str = "edge"
    vmo_margin: float = 2e-3
    pivot: tuple[float, float, float] | None = None
    rotation_order: str = "moving-xyz"
    zero_height: float | None = None
    velocity: float | None = None
    timeout: float = 0.5
    baudrate: int = 115200

    def __post_init__(self) -> None:
        if self.vmo not in ("edge", "always", "never"):
            raise BackendError(f"vmo must be edge, always or never, got {self.vmo!r}")
        if self.rotation_order not in ROTATION_ORDERS:
            raise BackendError(f"rotation must be one of {ROTATION_ORDERS}, got "
                               f"{self.rotation_order!r}")
        if not (self.timeout > 0 and self.vmo_margin >= 0):
            raise BackendError("timeout must be positive and vmo_margin_mm >= 0")
        if self.velocity is not None and not self.velocity > 0:
            raise BackendError(f"velocity must be positive, got {self.velocity} m/s")

    @classmethod
    def parse(cls, spec: str) -> tuple[str, GcsOptions]:
        """Split ``URL?key=value&...`` into the URL and the options.

        Raises:
            BackendError: An unknown key or a bad value (the message lists the keys).
        """
        url, _, query = spec.partition("?")
        changes: dict[str, Any] = {}
        for item in filter(None, query.split("&")):
            key, sep, value = item.partition("=")
            if not sep or key not in _OPTION_KEYS:
                raise BackendError(f"gcs option {item!r}: expected KEY=VALUE with KEY one of "
                                   f"{', '.join(sorted(_OPTION_KEYS))}")
            field, convert = _OPTION_KEYS[key]
            try:
                changes[field] = convert(value)
            except ValueError as exc:
                raise BackendError(f"gcs option {item!r}: {exc}") from None
        return url, replace(cls(), **changes)


def _mm_triple(text: str) -> tuple[float, float, float]:
    values = [float(x) * 1e-3 for x in text.split(",")]
    if len(values) != 3:
        raise ValueError("expected R,S,T in mm")
    return values[0], values[1], values[2]


_OPTION_KEYS: dict[str, tuple[str, Callable[[str], Any]]] = {
    "vmo": ("vmo", str),
    "vmo_margin_mm": ("vmo_margin", lambda s: float(s) * 1e-3),
    "pivot_mm": ("pivot", _mm_triple),
    "rotation": ("rotation_order", str),
    "zero_mm": ("zero_height", lambda s: float(s) * 1e-3),
    "velocity": ("velocity", lambda s: float(s) * 1e-3),
    "timeout": ("timeout", float),
    "baud": ("baudrate", int),
}


def platform_velocity(geometry: HexapodGeometry, convention: PoseConvention,
                      coords: np.ndarray, margin: float = 1.5) -> float:
    """The system velocity (``VLS``) that lets the legs move at their speed limit.

    The largest platform speed the legs can produce with every leg at its speed limit
    (the 64 sign combinations of the vertices of the box of leg velocities), measured as
    the controller measures it: the pivot point's speed in mm/s or the rotation rate in
    deg/s, whichever is larger, at ``coords``; times ``margin`` because the Jacobian
    changes over the workspace.

    Returns:
        ``VLS`` [m/s] (numerically mm/s / 1000; the same number is deg/s / 1000).
    """
    c0 = np.asarray(coords, dtype=float)
    M = np.empty((6, 6))
    h = 1e-7
    for j in range(6):
        e = np.zeros(6)
        e[j] = h
        qp = inverse_kinematics(geometry, *convention.pose(c0 + e))
        qm = inverse_kinematics(geometry, *convention.pose(c0 - e))
        M[:, j] = (qp - qm) / (2 * h)
    Minv = np.linalg.inv(M)
    best = 0.0
    for signs in itertools.product((-1.0, 1.0), repeat=6):
        dc = Minv @ (np.array(signs) * geometry.max_speed)
        best = max(best, float(np.linalg.norm(dc[:3])),
                   float(np.linalg.norm(np.rad2deg(dc[3:]))) * 1e-3)
    return margin * best


def option_keys() -> tuple[str, ...]:
    """The keys of a ``gcs`` spec's options (``URL?KEY=VALUE&...``)."""
    return tuple(_OPTION_KEYS)
