"""Inertial parameters of a hexapod: the ``[inertia]`` table of the robot file.

Each leg is two rigid bodies: the *body* (the cylinder hinged at the base point
``A_i``) and the *rod* (hinged at the platform point ``B_i``, sliding in the body).
Both are axisymmetric about the leg axis, so each is given by its mass, the
distance of its centre of mass from its hinge along the leg, and two principal
moments about that centre: transverse and axial. The platform is a general rigid
body (mass, centre of mass and 3x3 inertia in the platform frame).

Defaults (:meth:`InertiaParameters.default`, used when a robot file has no
``[inertia]`` table and for every preset) are an **assumption**, not a measurement
of any real robot: they are the numbers :mod:`hexapod.model` has always used for
the Pinocchio model, i.e.

- platform: 2.0 kg, a homogeneous disc of the platform's radius (the largest
  horizontal distance of a platform joint from the platform origin) and 10 mm
  thick, centred on the platform origin;
- body: 0.5 kg, a homogeneous cylinder of the leg radius and of length
  ``0.9 q_min``, centre of mass half-way (``0.45 q_min`` from ``A_i``);
- rod: 0.2 kg, a homogeneous cylinder of 0.6 times the leg radius and of length
  ``0.9 q_min``, centre of mass ``0.45 q_min`` from ``B_i``;
- gravity ``(0, 0, -9.81)`` m/s^2 in the base frame (base horizontal, z up).

For the DeltaLab preset this gives ``body_com = rod_com = 0.15525`` m.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from functools import lru_cache
from typing import Any

import numpy as np

from hexapod.config import check_keys, get_matrix, get_number
from hexapod.exceptions import ConfigFileError, InertiaError

#: Standard gravity [m/s^2].
STANDARD_GRAVITY = 9.81

#: Relative slack of the positive-definiteness and triangle-inequality checks.
_TOL = 1e-12


def cylinder_inertia(mass: float, radius: float, length: float) -> tuple[float, float]:
    """Principal moments ``(transverse, axial)`` [kg m^2] of a homogeneous solid
    cylinder about its centre of mass.

    Args:
        mass: [kg].
        radius: [m].
        length: [m].
    """
    return mass * (3 * radius**2 + length**2) / 12, mass * radius**2 / 2


def inertia_matrix(six: np.ndarray) -> np.ndarray:
    """The symmetric 3x3 tensor of ``[ixx, iyy, izz, ixy, ixz, iyz]`` (the products are
    the tensor's off-diagonal entries, URDF's and Pinocchio's convention)."""
    ixx, iyy, izz, ixy, ixz, iyz = (float(x) for x in six)
    return np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])


@dataclass(frozen=True, eq=False)
class InertiaParameters:
    """Masses, centres of mass and inertias of the platform and the legs.

    The same values for the six legs. Validated on construction (:class:`InertiaError`
    names the key); :meth:`check_legs` checks the centres of mass against a stroke.

    Attributes:
        platform_mass: [kg], positive.
        platform_com: (3,) centre of mass in the platform frame [m].
        platform_inertia: (6,) ``[ixx, iyy, izz, ixy, ixz, iyz]`` about the centre of
            mass, platform axes [kg m^2].
        body_mass: Mass of the cylinder hinged at ``A_i`` [kg] (0: massless).
        body_com: Distance of its centre of mass from ``A_i`` along the leg [m].
        body_inertia: (2,) ``[transverse, axial]`` about its centre of mass [kg m^2].
        rod_mass: Mass of the rod hinged at ``B_i`` [kg] (0: massless).
        rod_com: Distance of its centre of mass from ``B_i`` back along the leg [m].
        rod_inertia: (2,) ``[transverse, axial]`` about its centre of mass [kg m^2].
        gravity: (3,) gravity acceleration in the base frame [m/s^2].
        source: File the values were read from (for error messages).
    """

    platform_mass: float
    platform_com: np.ndarray
    platform_inertia: np.ndarray
    body_mass: float
    body_com: float
    body_inertia: np.ndarray
    rod_mass: float
    rod_com: float
    rod_inertia: np.ndarray
    gravity: np.ndarray
    source: str | None = None

    #: The keys of the ``[inertia]`` table, in file order.
    KEYS = ("platform_mass", "platform_com", "platform_inertia", "body_mass", "body_com",
            "body_inertia", "rod_mass", "rod_com", "rod_inertia", "gravity")

    def __post_init__(self) -> None:
        src = self.source
        shapes = {"platform_com": (3,), "platform_inertia": (6,), "body_inertia": (2,),
                  "rod_inertia": (2,), "gravity": (3,)}
        for key in self.KEYS:
            value = getattr(self, key)
            shape = shapes.get(key, ())
            try:
                arr = np.array(value, dtype=float)
            except (TypeError, ValueError):
                raise InertiaError(f"inertia.{key}", f"expected numbers, got {value!r}",
                                   src) from None
            if arr.shape != shape:
                raise InertiaError(f"inertia.{key}", f"expected shape {shape}, got {arr.shape}",
                                   src)
            if not np.all(np.isfinite(arr)):
                raise InertiaError(f"inertia.{key}", f"not finite: {arr.tolist()}", src)
            if shape == ():
                object.__setattr__(self, key, float(arr))
            else:
                arr.flags.writeable = False
                object.__setattr__(self, key, arr)
        if self.platform_mass <= 0:
            raise InertiaError("inertia.platform_mass",
                               f"must be positive, got {self.platform_mass} kg", src)
        _check_tensor("inertia.platform_inertia", inertia_matrix(self.platform_inertia), src)
        for part in ("body", "rod"):
            mass = getattr(self, f"{part}_mass")
            moments = getattr(self, f"{part}_inertia")
            if mass < 0:
                raise InertiaError(f"inertia.{part}_mass", f"negative mass {mass} kg", src)
            if mass == 0:
                if np.any(moments != 0):
                    raise InertiaError(f"inertia.{part}_inertia",
                                       f"a massless {part} has no inertia: expected [0, 0], "
                                       f"got {moments.tolist()} kg m^2", src)
                continue
            transverse, axial = moments
            _check_tensor(f"inertia.{part}_inertia",
                          np.diag([transverse, transverse, axial]), src)

    @property
    def massless_legs(self) -> bool:
        """True when the bodies and rods have neither mass nor inertia."""
        return self.body_mass == 0 and self.rod_mass == 0

    @property
    def platform_tensor(self) -> np.ndarray:
        """(3, 3) platform inertia about its centre of mass, platform axes [kg m^2]."""
        return inertia_matrix(self.platform_inertia)

    def check_legs(self, q_min: float, source: str | None = None) -> None:
        """Refuse a centre of mass outside the leg: each must lie between the leg's two
        joints at every length, i.e. in ``[0, q_min]`` from its hinge.

        Args:
            q_min: Shortest leg length [m].
            source: File name for the message (default: the parameters' own).

        Raises:
            InertiaError: ``body_com`` or ``rod_com`` outside ``[0, q_min]``.
        """
        src = source or self.source
        for part, hinge in (("body", "A_i"), ("rod", "B_i")):
            com = getattr(self, f"{part}_com")
            if not 0.0 <= com <= q_min:
                # (millimetres where metres are meant: more than a metre, fine in mm)
                hint = (f" (millimetres? [inertia] is in SI units: {com:g} mm is "
                        f"{com * 1e-3:g} m)" if com > 1.0 and com * 1e-3 <= q_min else "")
                raise InertiaError(
                    f"inertia.{part}_com",
                    f"centre of mass {com} m from {hinge} is outside the leg: it must lie "
                    f"between 0 and the shortest leg length q_min = {q_min:g} m{hint}", src)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, InertiaParameters):
            return NotImplemented
        if self is other:
            return True
        return all(np.array_equal(getattr(self, k), getattr(other, k)) for k in self.KEYS)

    __hash__ = None  # type: ignore[assignment]

    def replace(self, **changes: Any) -> InertiaParameters:
        """A copy with some fields changed (validated again)."""
        kwargs = {f.name: getattr(self, f.name) for f in fields(self)}
        kwargs.update(changes)
        return InertiaParameters(**kwargs)

    @classmethod
    def default(cls, platform_radius: float, leg_radius: float, q_min: float
                ) -> InertiaParameters:
        """The assumed defaults (module docstring), sized on the robot; the same
        (immutable) object for the same sizes.

        Args:
            platform_radius: Radius of the platform disc [m].
            leg_radius: Radius of the legs [m].
            q_min: Shortest leg length [m].
        """
        return _default(float(platform_radius), float(leg_radius), float(q_min))

    def massless(self) -> InertiaParameters:
        """The same platform with massless legs (the textbook case)."""
        return self.replace(body_mass=0.0, body_inertia=np.zeros(2), rod_mass=0.0,
                            rod_inertia=np.zeros(2))

    @classmethod
    def from_dict(cls, table: dict[str, Any], path: str, defaults: InertiaParameters
                  ) -> InertiaParameters:
        """Read an ``[inertia]`` table (SI units); absent keys keep ``defaults``.

        Raises:
            ConfigFileError: Unknown key, or a value of the wrong type or shape.
            InertiaError: A physically impossible value.
        """
        if not isinstance(table, dict):
            raise ConfigFileError(path, f"expected a table, got {table!r}", key="inertia")
        check_keys(table, cls.KEYS, path, prefix="inertia.")
        shapes = {"platform_com": (3,), "platform_inertia": (6,), "body_inertia": (2,),
                  "rod_inertia": (2,), "gravity": (3,)}
        values: dict[str, Any] = {}
        for key in cls.KEYS:
            if key not in table:
                values[key] = getattr(defaults, key)
            elif key in shapes:
                values[key] = get_matrix(table, key, shapes[key], path, prefix="inertia.")
            else:
                values[key] = get_number(table, key, path, prefix="inertia.")
        return cls(**values, source=path)

    def to_dict(self) -> dict[str, Any]:
        """The ``[inertia]`` table (SI units, plain lists)."""
        out: dict[str, Any] = {}
        for key in self.KEYS:
            value = getattr(self, key)
            out[key] = value.tolist() if isinstance(value, np.ndarray) else float(value)
        return out


@lru_cache(maxsize=256)
def _default(platform_radius: float, leg_radius: float, q_min: float) -> InertiaParameters:
    """The defaults, built without the checks of ``__post_init__`` (valid by construction,
    tested; every robot of a study with its own leg radius makes one)."""
    thickness = 0.01
    m_p = 2.0
    lateral = m_p * (3 * platform_radius**2 + thickness**2) / 12
    length = 0.9 * q_min
    values: dict[str, Any] = {
        "platform_mass": m_p,
        "platform_com": np.zeros(3),
        "platform_inertia": np.array([lateral, lateral, m_p * platform_radius**2 / 2,
                                      0.0, 0.0, 0.0]),
        "body_mass": 0.5, "body_com": length / 2,
        "body_inertia": np.array(cylinder_inertia(0.5, leg_radius, length)),
        "rod_mass": 0.2, "rod_com": length / 2,
        "rod_inertia": np.array(cylinder_inertia(0.2, 0.6 * leg_radius, length)),
        "gravity": np.array([0.0, 0.0, -STANDARD_GRAVITY]),
        "source": None,
    }
    obj = InertiaParameters.__new__(InertiaParameters)
    for key, value in values.items():
        if isinstance(value, np.ndarray):
            value.flags.writeable = False
        object.__setattr__(obj, key, value)
    return obj


def _check_tensor(key: str, tensor: np.ndarray, source: str | None) -> None:
    """Refuse an inertia tensor that is not positive definite or whose principal moments
    violate the triangle inequality (each at most the sum of the other two)."""
    moments = np.linalg.eigvalsh(tensor)
    scale = max(float(np.abs(moments).max()), 1e-300)
    if moments[0] <= _TOL * scale:
        raise InertiaError(key, "not positive definite: principal moments "
                           f"{np.round(moments, 12).tolist()} kg m^2", source)
    a, b, c = moments
    if c > a + b + _TOL * scale:
        raise InertiaError(key, f"principal moments {np.round(moments, 12).tolist()} kg m^2 "
                           "violate the triangle inequality (the largest exceeds the sum of "
                           "the other two: no rigid body has them)", source)
