"""Drive and encoder parameters of the six legs: the ``[drives]`` table of the robot file.

Parameters only: how a drive behaves in simulation (its PI velocity loop, saturation
and friction) is the simulation's business. Each numeric key is either one number
(the same for every leg) or a list of six (leg by leg); ``mode`` is one for all.

Defaults (:meth:`DriveParameters.default`) are an **assumption** describing a small
ball-screw linear actuator with a DC motor and a commercial drive, of the size of the
DeltaLab legs (140 mm stroke, 50 mm/s), not a datasheet:

- ``force_limit`` 200 N (continuous force of a small screw actuator);
- ``rotor_inertia`` 2.5 kg: a rotor of 2.5e-7 kg m^2 seen through a 2 mm lead screw,
  ``J (2 pi / lead)^2``;
- ``viscous`` 50 N s/m and ``coulomb`` 5 N (screw and seal friction);
- ``encoder_resolution`` 1 um (an incremental encoder on the motor);
- ``mode`` ``"velocity"`` with a ``velocity_bandwidth`` of 50 Hz (the drive's inner PI
  velocity loop; the kinematic control laws' leg velocities are its setpoints).
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from functools import lru_cache
from typing import Any

import numpy as np

from hexapod.config import check_keys, suggest
from hexapod.exceptions import ConfigFileError, DriveError

#: Drive modes: an inner velocity loop (setpoints are leg velocities) or torque mode
#: (setpoints are leg forces).
MODES = ("velocity", "force")

#: Per-leg numeric keys: (unit, whether zero is allowed).
_NUMERIC = {
    "force_limit": ("N", False),
    "rotor_inertia": ("kg", True),
    "viscous": ("N s/m", True),
    "coulomb": ("N", True),
    "encoder_resolution": ("m", True),
    "velocity_bandwidth": ("Hz", False),
}


@dataclass(frozen=True, eq=False)
class DriveParameters:
    """The six legs' drives and encoders.

    Attributes:
        force_limit: (6,) largest force a drive delivers [N], positive.
        rotor_inertia: (6,) rotor inertia reflected to the leg's translation [kg].
        viscous: (6,) viscous friction coefficient [N s/m].
        coulomb: (6,) Coulomb friction force [N], below ``force_limit``.
        encoder_resolution: (6,) length quantum of the leg encoder [m] (0: exact).
        mode: ``"velocity"`` (inner PI velocity loop) or ``"force"`` (torque mode).
        velocity_bandwidth: (6,) bandwidth of the PI velocity loop [Hz], positive.
        source: File the values were read from (for error messages).
    """

    force_limit: np.ndarray
    rotor_inertia: np.ndarray
    viscous: np.ndarray
    coulomb: np.ndarray
    encoder_resolution: np.ndarray
    mode: str
    velocity_bandwidth: np.ndarray
    source: str | None = None

    #: The keys of the ``[drives]`` table, in file order.
    KEYS = ("force_limit", "rotor_inertia", "viscous", "coulomb", "encoder_resolution",
            "mode", "velocity_bandwidth")

    def __post_init__(self) -> None:
        src = self.source
        for key, (unit, zero_ok) in _NUMERIC.items():
            value = getattr(self, key)
            try:
                arr = np.array(np.broadcast_to(np.asarray(value, dtype=float), (6,)))
            except (TypeError, ValueError):
                raise DriveError(f"drives.{key}", "expected one number or six (one per leg), "
                                 f"got {value!r}", src) from None
            for leg, x in enumerate(arr):
                if not np.isfinite(x):
                    raise DriveError(f"drives.{key}", f"leg {leg}: not finite ({x})", src)
                if x < 0 or (x == 0 and not zero_ok):
                    need = "non-negative" if zero_ok else "positive"
                    raise DriveError(f"drives.{key}", f"leg {leg}: must be {need}, got {x} {unit}",
                                     src)
            arr.flags.writeable = False
            object.__setattr__(self, key, arr)
        for leg in range(6):
            if self.coulomb[leg] >= self.force_limit[leg]:
                raise DriveError("drives.coulomb", f"leg {leg}: Coulomb friction "
                                 f"{self.coulomb[leg]} N is not below the force limit "
                                 f"{self.force_limit[leg]} N (the leg could never move)", src)
        if self.mode not in MODES:
            hint = suggest(str(self.mode), MODES)
            raise DriveError("drives.mode", f"unknown mode {self.mode!r}; expected one of "
                             f"{', '.join(MODES)}" + (f" (did you mean '{hint}'?)" if hint
                                                      else ""), src)

    @classmethod
    def default(cls) -> DriveParameters:
        """The assumed defaults (module docstring); the same (immutable) object."""
        return _default()

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, DriveParameters):
            return NotImplemented
        if self is other:
            return True
        return self.mode == other.mode and all(
            np.array_equal(getattr(self, k), getattr(other, k)) for k in _NUMERIC)

    __hash__ = None  # type: ignore[assignment]

    def replace(self, **changes: Any) -> DriveParameters:
        """A copy with some fields changed (validated again)."""
        kwargs = {f.name: getattr(self, f.name) for f in fields(self)}
        kwargs.update(changes)
        return DriveParameters(**kwargs)

    @classmethod
    def from_dict(cls, table: dict[str, Any], path: str,
                  defaults: DriveParameters | None = None) -> DriveParameters:
        """Read a ``[drives]`` table (SI units); absent keys keep ``defaults``.

        Raises:
            ConfigFileError: Unknown key, or a value of the wrong type or length.
            DriveError: An impossible value (the message names the leg).
        """
        if not isinstance(table, dict):
            raise ConfigFileError(path, f"expected a table, got {table!r}", key="drives")
        check_keys(table, cls.KEYS, path, prefix="drives.")
        base = defaults or cls.default()
        values: dict[str, Any] = {k: getattr(base, k) for k in cls.KEYS}
        for key in _NUMERIC:
            if key not in table:
                continue
            value = table[key]
            ok_scalar = isinstance(value, int | float) and not isinstance(value, bool)
            ok_list = (isinstance(value, list) and len(value) == 6 and all(
                isinstance(x, int | float) and not isinstance(x, bool) for x in value))
            if not (ok_scalar or ok_list):
                raise ConfigFileError(path, "expected one number (every leg) or a list of six "
                                      f"numbers (leg by leg), got {value!r}",
                                      key=f"drives.{key}")
            values[key] = np.broadcast_to(np.asarray(value, dtype=float), (6,))
        if "mode" in table:
            if not isinstance(table["mode"], str):
                raise ConfigFileError(path, f"expected a string, got {table['mode']!r}",
                                      key="drives.mode")
            values["mode"] = table["mode"]
        return cls(**values, source=path)

    def to_dict(self) -> dict[str, Any]:
        """The ``[drives]`` table: one number where the six legs agree, else a list."""
        out: dict[str, Any] = {}
        for key in self.KEYS:
            value = getattr(self, key)
            if key == "mode":
                out[key] = value
            elif np.all(value == value[0]):
                out[key] = float(value[0])
            else:
                out[key] = value.tolist()
        return out


@lru_cache(maxsize=1)
def _default() -> DriveParameters:
    return DriveParameters(force_limit=np.full(6, 200.0), rotor_inertia=np.full(6, 2.5),
                           viscous=np.full(6, 50.0), coulomb=np.full(6, 5.0),
                           encoder_resolution=np.full(6, 1e-6), mode="velocity",
                           velocity_bandwidth=np.full(6, 50.0))
