"""The ``[payload]`` table of a scenario: a rigid body fixed to the true platform
(:mod:`hexapod.dynamics.payload`), in the dynamic world.

``mass_kg`` may be swept (a list); ``0`` is no payload (its ``com_mm`` and
``inertia_kg_m2`` then play no part), so that a sweep can start from the bare robot.
The controllers' model of the payload is the same body with its mass (and, alike, its
inertia) off by ``[calibration_error] payload_mass_percent``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from benchmarks.exceptions import ScenarioError
from hexapod.dynamics.payload import Payload
from hexapod.exceptions import InertiaError

#: Keys of ``[payload]`` that may be swept.
PAYLOAD_KEYS = ("mass_kg",)
#: Allowed ranges (merged into :data:`benchmarks.study.scenario_ranges.RANGES`).
PAYLOAD_RANGES: dict[str, tuple[float, float, bool, bool]] = {
    "payload.mass_kg": (0.0, 10_000.0, True, True),
    "calibration_error.payload_mass_percent": (-100.0, 1000.0, True, True),
}
#: The ``[inertia]`` key names of the six inertia values, for the messages.
_SIX = "[ixx, iyy, izz, ixy, ixz, iyz]"


@dataclass(frozen=True)
class PayloadConfig:
    """A payload fixed to the true platform (``[payload]``).

    Attributes:
        mass_kg: Its mass [kg] (0: none).
        com_mm: Its centre of mass in the platform frame [mm].
        inertia_kg_m2: ``[ixx, iyy, izz, ixy, ixz, iyz]`` about its centre of mass,
            platform axes [kg m^2] (the convention of ``[inertia] platform_inertia``;
            zeros: a point mass).
    """

    mass_kg: float = 0.0
    com_mm: tuple[float, ...] = (0.0, 0.0, 0.0)
    inertia_kg_m2: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)

    def body(self, source: str | None = None) -> Payload:
        """The payload in SI units (a massless one when ``mass_kg`` is 0).

        Raises:
            InertiaError: No rigid body has these values (``field`` names the key).
        """
        if self.mass_kg == 0.0:
            return Payload(0.0, np.zeros(3), np.zeros(6), source)
        return Payload(self.mass_kg, 1e-3 * np.asarray(self.com_mm, dtype=float),
                       np.asarray(self.inertia_kg_m2, dtype=float), source)


def check_payload(config: PayloadConfig, sweep: dict[str, list[Any]], path: str) -> None:
    """Refuse a ``[payload]`` that no rigid body has, at every swept mass.

    Raises:
        ScenarioError: Naming the file, the key (``payload.com_mm``,
            ``payload.inertia_kg_m2``) and the value.
    """
    if len(config.com_mm) != 3:
        raise ScenarioError(path, f"expected 3 numbers [x, y, z] in mm, got "
                            f"{list(config.com_mm)}", key="payload.com_mm")
    if len(config.inertia_kg_m2) != 6:
        raise ScenarioError(path, f"expected 6 numbers {_SIX} in kg m^2, got "
                            f"{list(config.inertia_kg_m2)}", key="payload.inertia_kg_m2")
    for mass in sweep.get("payload.mass_kg", [config.mass_kg]):
        try:
            PayloadConfig(mass, config.com_mm, config.inertia_kg_m2).body(path)
        except InertiaError as exc:
            key = {"payload.com": "payload.com_mm", "payload.inertia": "payload.inertia_kg_m2",
                   "payload.mass": "payload.mass_kg"}.get(exc.field, exc.field)
            raise ScenarioError(path, f"{exc.problem} (mass_kg = {mass:g})", key=key) from None
