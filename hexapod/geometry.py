"""Geometry of a 6-6 Gough-Stewart platform.

Conventions (``docs/math.md`` section 1): the base frame ``b`` and the platform
frame ``e``; ``base_points[i]`` is the centre ``A_i`` of the base joint of leg
``i`` in ``b`` and ``platform_points[i]`` the centre ``eB_i`` of its platform
joint in ``e``. Lengths are in metres inside the code and millimetres in files.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w

from hexapod.config import check_file_kind, check_keys, get_matrix, get_number, load_toml
from hexapod.dynamics.drives import DriveParameters
from hexapod.dynamics.inertia import InertiaParameters
from hexapod.exceptions import ConfigFileError, DriveError, GeometryError, InertiaError

#: Minimum distance between two joints of the same plate [m].
MIN_JOINT_SEPARATION = 1e-4


#: The pairs ``i < j`` of six points (an upper triangle mask).
_PAIRS = np.triu(np.ones((6, 6), dtype=bool), 1)


def _validate_points(name: str, value: Any, source: str | None) -> np.ndarray:
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise GeometryError(name, "expected a 6x3 array of numbers", source) from None
    if arr.shape != (6, 3):
        raise GeometryError(name, f"expected shape (6, 3), got {arr.shape}", source)
    if not np.isfinite(arr).all():
        i, j = np.argwhere(~np.isfinite(arr))[0]
        raise GeometryError(name, f"leg {i}: its point's {'xyz'[j]} coordinate is "
                            f"{arr[i, j]} (not finite; row {i} of the 6 points)", source)
    diff = arr[:, None, :] - arr[None, :, :]
    d2 = np.einsum("ijk,ijk->ij", diff, diff)  # squared distances of every pair
    close = (d2 < MIN_JOINT_SEPARATION**2) & _PAIRS
    if close.any():
        i, j = np.argwhere(close)[0]  # (the first pair i < j in row order)
        d = math.sqrt(float(d2[i, j]))
        span = float(np.max(np.linalg.norm(arr, axis=1)))  # [m]
        metres = (f"; every point within {span * 1e3:.3g} mm of the origin: metres where "
                  "millimetres are meant (a robot file's base_points_mm, platform_points_mm)?"
                  if span < 0.01 else "")
        raise GeometryError(
            name, f"points {i} and {j} coincide (distance {d * 1e3:.4f} mm){metres}", source
        )
    centred = arr - arr.mean(axis=0)
    s = np.linalg.svd(centred, compute_uv=False)
    if s[1] < 1e-6 * max(s[0], 1e-12):
        raise GeometryError(name, "all six points are collinear", source)
    return arr


@dataclass(frozen=True)
class HexapodGeometry:
    """Geometry of a Gough-Stewart platform.

    Attributes:
        base_points: Base joint centres ``A_i`` in the base frame, (6, 3) [m].
        platform_points: Platform joint centres ``eB_i`` in the platform frame, (6, 3) [m].
        stroke: Leg length limits ``(q_min, q_max)`` [m].
        leg_radius: Radius of the cylindrical legs [m].
        max_speed: Leg speed limit [m/s].
        name: A label.
        inertia: Masses and inertias (the ``[inertia]`` table); None gives the assumed
            defaults sized on this robot (:meth:`InertiaParameters.default`).
        drives: Drives and encoders (the ``[drives]`` table); None gives the assumed
            defaults (:meth:`DriveParameters.default`).
    """

    base_points: np.ndarray
    platform_points: np.ndarray
    stroke: tuple[float, float]
    leg_radius: float = 0.015
    max_speed: float = 0.05
    name: str = "hexapod"
    source: str | None = field(default=None, compare=False, repr=False)
    inertia: InertiaParameters = None  # type: ignore[assignment]  # None: the default
    drives: DriveParameters = None  # type: ignore[assignment]  # None: the default

    def __post_init__(self) -> None:
        src = self.source
        base = _validate_points("base_points", self.base_points, src)
        plat = _validate_points("platform_points", self.platform_points, src)
        try:
            q_min, q_max = (float(x) for x in self.stroke)
        except (TypeError, ValueError):
            raise GeometryError(
                "stroke", f"expected (q_min, q_max), got {self.stroke!r}", src
            ) from None
        if not (np.isfinite(q_min) and np.isfinite(q_max)):
            raise GeometryError("stroke", f"not finite: ({q_min}, {q_max})", src)
        if q_min <= 0:
            raise GeometryError("stroke", f"q_min must be positive, got {q_min} m", src)
        if q_min >= q_max:
            raise GeometryError(
                "stroke", f"q_min ({q_min} m) must be smaller than q_max ({q_max} m)", src
            )
        r = float(self.leg_radius)
        if not np.isfinite(r) or r <= 0:
            raise GeometryError("leg_radius", f"must be positive and finite, got {r}", src)
        v = float(self.max_speed)
        if not np.isfinite(v) or v <= 0:
            raise GeometryError("max_speed", f"must be positive and finite, got {v}", src)
        _check_units(base, plat, q_max, r, v, src)
        base.flags.writeable = False
        plat.flags.writeable = False
        object.__setattr__(self, "base_points", base)
        object.__setattr__(self, "platform_points", plat)
        object.__setattr__(self, "stroke", (q_min, q_max))
        object.__setattr__(self, "leg_radius", r)
        object.__setattr__(self, "max_speed", v)
        defaulted = self.inertia is None
        inertia = self.default_inertia() if defaulted else self.inertia
        if not isinstance(inertia, InertiaParameters):
            raise GeometryError("inertia", f"expected InertiaParameters, got {inertia!r}", src)
        if not defaulted:
            inertia.check_legs(q_min, src)
        object.__setattr__(self, "inertia", inertia)
        object.__setattr__(self, "_inertia_defaulted", defaulted)
        drives = self.drives if self.drives is not None else DriveParameters.default()
        if not isinstance(drives, DriveParameters):
            raise GeometryError("drives", f"expected DriveParameters, got {drives!r}", src)
        object.__setattr__(self, "drives", drives)
        _check_si_tables(self, src)

    def default_inertia(self) -> InertiaParameters:
        """The assumed inertial parameters sized on this robot (platform radius, leg
        radius, shortest leg length): :meth:`InertiaParameters.default`."""
        radius = float(np.max(np.linalg.norm(np.asarray(self.platform_points)[:, :2], axis=1)))
        return InertiaParameters.default(radius, float(self.leg_radius), float(self.stroke[0]))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, HexapodGeometry):
            return NotImplemented
        return (
            np.array_equal(self.base_points, other.base_points)
            and np.array_equal(self.platform_points, other.platform_points)
            and self.stroke == other.stroke
            and self.leg_radius == other.leg_radius
            and self.max_speed == other.max_speed
            and self.inertia == other.inertia
            and self.drives == other.drives
        )

    __hash__ = None  # type: ignore[assignment]

    @cached_property
    def home_height(self) -> float:
        """Height [m] of the home pose (platform parallel to the base, centred) where the
        mean leg length is the middle of the stroke."""
        from hexapod.workspace import home_height

        return home_height(self)

    @property
    def q_min(self) -> float:
        """Lower stroke limit [m]."""
        return self.stroke[0]

    @property
    def q_max(self) -> float:
        """Upper stroke limit [m]."""
        return self.stroke[1]

    @property
    def q_mid(self) -> float:
        """Middle of the stroke [m]."""
        return 0.5 * (self.stroke[0] + self.stroke[1])

    def replace(self, **changes: Any) -> HexapodGeometry:
        """Return a copy with some fields changed (validated again).

        Default inertial parameters follow the changed robot (they are sized on it);
        parameters given explicitly are kept."""
        kwargs: dict[str, Any] = {
            "base_points": self.base_points,
            "platform_points": self.platform_points,
            "stroke": self.stroke,
            "leg_radius": self.leg_radius,
            "max_speed": self.max_speed,
            "name": self.name,
            "inertia": None if getattr(self, "_inertia_defaulted", False) else self.inertia,
            "drives": self.drives,
        }
        kwargs.update(changes)
        return HexapodGeometry(**kwargs)

    # ----------------------------------------------------------------- TOML
    #: The keys of a robot file.
    FILE_KEYS = ("name", "base_points_mm", "platform_points_mm", "stroke_mm", "leg_radius_mm",
             "max_speed_mm_s", "inertia", "drives")

    @classmethod
    def from_dict(cls, table: dict[str, Any], path: str = "<dict>") -> HexapodGeometry:
        """Build a geometry from a table in the file format (millimetres).

        Args:
            table: Keys ``base_points_mm`` (6x3), ``platform_points_mm`` (6x3),
                ``stroke_mm`` ([min, max]), ``leg_radius_mm`` and optionally
                ``name`` and ``max_speed_mm_s``; tables ``inertia`` and ``drives`` in SI
                units (``docs/dynamics.md``), keys absent from them keep their defaults.
            path: Source name for error messages.
        """
        check_file_kind(table, path, "robot file")
        check_keys(
            table,
            cls.FILE_KEYS,
            path,
            required=("base_points_mm", "platform_points_mm", "stroke_mm", "leg_radius_mm"),
        )
        base = get_matrix(table, "base_points_mm", (6, 3), path) * 1e-3
        plat = get_matrix(table, "platform_points_mm", (6, 3), path) * 1e-3
        stroke = get_matrix(table, "stroke_mm", (2,), path) * 1e-3
        radius = get_number(table, "leg_radius_mm", path) * 1e-3
        speed = get_number(table, "max_speed_mm_s", path) * 1e-3 if "max_speed_mm_s" in table \
            else 0.05
        name = table.get("name", Path(path).stem)
        if not isinstance(name, str):
            raise ConfigFileError(path, f"expected a string, got {name!r}", key="name")
        _check_file_values(table, path)
        try:
            geometry = cls(base, plat, (float(stroke[0]), float(stroke[1])), radius, speed,
                           name, source=path)
        except GeometryError as exc:  # name the key as written in the file
            raise GeometryError(_FILE_KEYS.get(exc.field, exc.field), exc.problem,
                                path) from None
        tables: dict[str, Any] = {}
        try:
            if "inertia" in table:
                tables["inertia"] = InertiaParameters.from_dict(table["inertia"], path,
                                                                geometry.default_inertia())
            if "drives" in table:
                tables["drives"] = DriveParameters.from_dict(table["drives"], path)
            if not tables:
                return geometry
            return cls(base, plat, geometry.stroke, radius, speed, name, source=path, **tables)
        except InertiaError:
            if geometry.q_max < METRES_STROKE:  # the stroke is at fault, not [inertia]
                raise GeometryError("stroke_mm", _METRES_HINT.format(geometry.q_max * 1e3),
                                    path) from None
            raise

    @classmethod
    def from_toml(cls, path: str | Path) -> HexapodGeometry:
        """Load a geometry from a TOML file (lengths in millimetres).

        Raises:
            ConfigFileError: Missing file, bad TOML, missing or misspelt key.
            GeometryError: A field has an invalid value.
        """
        return cls.from_dict(load_toml(path), str(path))

    def to_dict(self, dynamics: bool = False) -> dict[str, Any]:
        """The file representation (millimetres; the tables in SI units).

        Args:
            dynamics: Always include the ``inertia`` and ``drives`` tables; by default
                each is included only when it differs from its default.
        """
        out = {
            "name": self.name,
            "base_points_mm": (self.base_points * 1e3).round(9).tolist(),
            "platform_points_mm": (self.platform_points * 1e3).round(9).tolist(),
            "stroke_mm": [self.stroke[0] * 1e3, self.stroke[1] * 1e3],
            "leg_radius_mm": self.leg_radius * 1e3,
            "max_speed_mm_s": self.max_speed * 1e3,
        }
        if dynamics or self.inertia != self.default_inertia():
            out["inertia"] = self.inertia.to_dict()
        if dynamics or self.drives != DriveParameters.default():
            out["drives"] = self.drives.to_dict()
        return out

    def to_toml(self, path: str | Path) -> None:
        """Save the geometry to a TOML file (lengths in millimetres), with its
        ``[inertia]`` and ``[drives]`` tables written out in full."""
        Path(path).write_text(tomli_w.dumps(self.to_dict(dynamics=True)))


#: Bounds no Gough-Stewart robot reaches, in SI units: a value beyond one is a unit
#: slip (millimetres for metres) in the Python constructor, whose lengths are metres.
MAX_LEG_LENGTH, MAX_SPEED = 50.0, 20.0


def _check_units(base: np.ndarray, plat: np.ndarray, q_max: float, r: float, v: float,
                 src: str | None) -> None:
    """Refuse a stroke, leg radius or speed limit no robot of this size has (module
    constants above; a leg thicker than the larger plate). A robot file's speed limit is
    left to the file's own check (``check`` and ``servo`` warn above 2 m/s, naming
    ``max_speed_mm_s``)."""
    size = float(max(np.linalg.norm(base[:, :2], axis=1).max(),
                     np.linalg.norm(plat[:, :2], axis=1).max()))
    hint = "millimetres for metres? the geometry is in SI units"
    if q_max > MAX_LEG_LENGTH:
        raise GeometryError("stroke", f"q_max {q_max:g} m: no hexapod has legs this long "
                            f"({hint})", src)
    if r >= size:
        raise GeometryError("leg_radius", f"{r:g} m is at least the plates' radius "
                            f"{size:g} m ({hint})", src)
    if v > MAX_SPEED and src is None:  # (a robot file's speed: its own unit-slip warning)
        raise GeometryError("max_speed", f"{v:g} m/s: no hexapod's legs move this fast "
                            f"({hint})", src)


def _check_si_tables(g: HexapodGeometry, src: str | None) -> None:
    """Refuse the SI tables' values no robot of this size has and a slip of units gives:
    the platform's centre of mass more than ten times the robot's size from its centre
    (millimetres in ``[inertia] platform_com``), an encoder coarser than a hundredth of the
    stroke (micrometres in ``[drives] encoder_resolution``, which is in metres)."""
    size = float(max(np.linalg.norm(g.base_points, axis=1).max(),
                     np.linalg.norm(g.platform_points, axis=1).max()))
    com = np.asarray(g.inertia.platform_com, dtype=float)
    if float(np.linalg.norm(com)) > 10.0 * size:
        raise InertiaError("inertia.platform_com", f"{com.tolist()} m is "
                           f"{float(np.linalg.norm(com)):g} m from the platform's centre, more "
                           f"than ten times the robot's size ({size * 1e3:.0f} mm): "
                           "millimetres where metres are meant? ([inertia] is in SI units)",
                           src)
    span = g.stroke[1] - g.stroke[0]
    for leg, x in enumerate(np.asarray(g.drives.encoder_resolution, dtype=float)):
        if x > 0.01 * span:
            raise DriveError("drives.encoder_resolution", f"leg {leg}: {x:g} m, coarser than "
                             f"a hundredth of the stroke ({span * 10:.3g} mm): the key is in "
                             "metres (a 1 um encoder is 1e-6)", src)


#: The file key of each field (errors name the key as written in the file).
_FILE_KEYS = {"base_points": "base_points_mm", "platform_points": "platform_points_mm",
              "stroke": "stroke_mm", "leg_radius": "leg_radius_mm",
              "max_speed": "max_speed_mm_s"}


#: A longest leg length under this [m] is a stroke given in metres (no hexapod's legs are
#: that short): the ``[inertia]`` checks against it would blame the inertia.
METRES_STROKE = 0.01
_METRES_HINT = ("the longest leg length is {:g} mm: given in metres? stroke_mm is in "
                "millimetres ([shortest, longest] leg length)")


def _check_file_values(table: dict[str, Any], path: str) -> None:
    """The values of a geometry file in its own terms (millimetres, the key as written).

    Raises:
        GeometryError: ``stroke_mm`` not ``[shortest, longest]`` with a positive shortest
            length, or a non-positive ``leg_radius_mm`` / ``max_speed_mm_s``.
    """
    lo, hi = (float(x) for x in table["stroke_mm"])
    if lo <= 0:
        raise GeometryError("stroke_mm", f"the shortest leg length must be positive, got "
                            f"{lo:g} mm (stroke_mm = [shortest, longest] in mm)", path)
    if lo >= hi:
        raise GeometryError(
            "stroke_mm", f"expected [shortest, longest] in mm with shortest < longest, got "
            f"[{lo:g}, {hi:g}] mm" + (" (swap the two values?)" if lo > hi else ""), path)
    for key, unit in (("leg_radius_mm", "mm"), ("max_speed_mm_s", "mm/s")):
        if key in table and float(table[key]) <= 0:
            raise GeometryError(key, f"must be positive, got {float(table[key]):g} {unit}",
                                path)


def circular_points(radius: float, angles: np.ndarray, z: float = 0.0) -> np.ndarray:
    """Points on a horizontal circle: (len(angles), 3) [m]."""
    a = np.asarray(angles, dtype=float)
    return np.stack([radius * np.cos(a), radius * np.sin(a), np.full_like(a, z)], axis=-1)


def deltalab(leg_radius: float = 0.015) -> HexapodGeometry:
    """The DeltaLab "Table de Stewart" of the seeds (``docs/math.md`` section 9).

    Base radius 270 mm, alpha 4.25 deg; platform radius 195 mm, beta 5.885 deg;
    strokes 345-485 mm; leg radius 15 mm by default.
    """
    alpha = np.deg2rad(4.25)
    beta = np.deg2rad(5.885)
    a_angles, b_angles = [], []
    for k in range(3):
        a_angles += [2 * k * np.pi / 3 + alpha, 2 * k * np.pi / 3 - alpha]
        b_angles += [2 * k * np.pi / 3 + np.pi / 3 - beta, 2 * k * np.pi / 3 - np.pi / 3 + beta]
    return HexapodGeometry(
        base_points=circular_points(0.270, np.array(a_angles)),
        platform_points=circular_points(0.195, np.array(b_angles)),
        stroke=(0.345, 0.485),
        leg_radius=leg_radius,
        max_speed=0.05,
        name="deltalab",
    )


def preset(name: str) -> HexapodGeometry:
    """Return a geometry preset by name (``"deltalab"``)."""
    presets = {"deltalab": deltalab}
    if name not in presets:
        from hexapod.config import suggest

        hint = suggest(name, presets)
        raise GeometryError(
            "preset",
            f"unknown preset '{name}'; available: {', '.join(presets)}"
            + (f" (did you mean '{hint}'?)" if hint else ""),
        )
    return presets[name]()
