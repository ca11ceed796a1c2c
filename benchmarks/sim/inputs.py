"""What the simulator reads of a study: its typed inputs. The simulator imports nothing
of ``benchmarks/study/``: it reads the sections of :mod:`benchmarks.scenario_sections` as
they are and declares the rest of a scenario point here, as protocols that the study's
:class:`benchmarks.study.scenario.Scenario` provides (checked by mypy where the study
calls the simulator).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, Protocol

from benchmarks.scenario_sections import (
    CalibrationErrorConfig,
    ClockConfig,
    DrivesConfig,
    ImageConfig,
    NoiseConfig,
    TaskConfig,
)


class SimController(Protocol):
    """A controller of the study: registry name, options and label in the rows."""

    @property
    def name(self) -> str: ...
    @property
    def label(self) -> str: ...
    @property
    def options(self) -> dict[str, Any]: ...


class SimPayload(Protocol):
    """A payload fixed to the true platform (``[payload]``)."""

    def body(self, source: str | None = None) -> Any:
        """The :class:`hexapod.dynamics.payload.Payload` (SI units)."""
        ...


class SimScenario(Protocol):
    """One point of a study, as the simulator reads it."""

    @property
    def name(self) -> str: ...
    @property
    def source(self) -> str: ...
    @property
    def seed(self) -> int: ...
    @property
    def controllers(self) -> Sequence[SimController]: ...
    @property
    def dt(self) -> float: ...
    @property
    def world(self) -> str: ...
    @property
    def physics_dt(self) -> float: ...
    @property
    def sensor(self) -> str: ...
    @property
    def teach_frames(self) -> int: ...
    @property
    def robot_preset(self) -> str | None: ...
    @property
    def robot_geometry(self) -> str | None: ...
    @property
    def camera_preset(self) -> str | None: ...
    @property
    def camera_file(self) -> str | None: ...
    @property
    def geometry_data(self) -> Any: ...
    @property
    def camera_data(self) -> Any: ...
    @property
    def image(self) -> ImageConfig: ...
    @property
    def noise(self) -> NoiseConfig: ...
    @property
    def calibration_error(self) -> CalibrationErrorConfig: ...
    @property
    def task(self) -> TaskConfig: ...
    @property
    def clock(self) -> ClockConfig: ...
    @property
    def drives(self) -> DrivesConfig: ...
    @property
    def payload(self) -> SimPayload | None: ...
    @property
    def sweep(self) -> Mapping[str, Any]: ...
