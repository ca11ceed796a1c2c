"""Where the velocity drives are now: the starting state ``v_0`` of the predictive
controllers' drive-aware prediction (``drive_model = "lag"``; the lag and the three
sources of ``v_0``: ``docs/math.md`` section 6, "Drive-aware prediction").

:class:`DriveLag` gives the leg velocities now from the option ``drive_state``:
``"measured"`` (``Observation.q_dot``, else as ``"encoders"``), ``"encoders"`` (the
last period's displacement and setpoint, carried to now by the lag) or ``"model"`` (the
lag run on the past setpoints from rest: an ablation), falling back to the latter when
the source has nothing finite to give.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from controllers.base import ControllerContext
from controllers.exceptions import OptionError
from controllers.leg_rate import lag_constants

#: Sources of the drives' state.
DRIVE_STATES = ("measured", "encoders", "model")


def drive_lag(context: ControllerContext, dt: float, name: str
              ) -> tuple[np.ndarray, np.ndarray]:
    """``(a, c)`` (6,) of the nominal velocity drives' lag over one period ``dt`` [s]
    (:func:`controllers.leg_rate.lag_constants`).

    Raises:
        OptionError: The nominal drives are in force mode (nothing lags a velocity
            setpoint: the controller commands velocities).
    """
    drives = context.geometry.drives
    if drives.mode != "velocity":
        raise OptionError(name, "drive_model", "'lag' models velocity-mode drives; the "
                          f"robot's [drives] mode is {drives.mode!r}")
    return lag_constants(drives, dt)


@dataclass
class DriveLag:
    """The lagging drives' state between steps (see the module docstring).

    Attributes:
        a: (6,) ``exp(-omega dt)``.
        c: (6,) ``(1 - a) / omega`` [s].
        dt: Control period [s].
        source: One of :data:`DRIVE_STATES`.
        velocities: (6,) the lag's run on the past setpoints: the leg velocities expected
            at the next step [m/s].
    """

    a: np.ndarray
    c: np.ndarray
    dt: float
    source: str
    velocities: np.ndarray = field(default_factory=lambda: np.zeros(6))
    _lengths: np.ndarray | None = None
    _setpoints: np.ndarray | None = None

    def now(self, lengths: np.ndarray, q_dot: np.ndarray | None) -> np.ndarray:
        """The leg velocities now [m/s] from the source (module docstring).

        Args:
            lengths: (6,) encoder lengths now [m].
            q_dot: (6,) measured leg velocities [m/s], or None.
        """
        if self.source == "measured" and q_dot is not None:
            v = np.asarray(q_dot, dtype=float)
            if np.all(np.isfinite(v)):
                return v
        if (self.source != "model" and self._lengths is not None
                and self._setpoints is not None):
            u = self._setpoints
            start = (np.asarray(lengths, dtype=float) - self._lengths
                     - (self.dt - self.c) * u) / self.c
            v = self.a * start + (1 - self.a) * u
            if np.all(np.isfinite(v)):
                return v  # type: ignore[no-any-return]
        return self.velocities

    def sent(self, now: np.ndarray, lengths: np.ndarray, setpoints: np.ndarray) -> None:
        """Record the step: the velocities ``now`` it started from, the encoder
        ``lengths`` [m] and the setpoints [m/s] the drives receive (non-finite: zero)."""
        u = np.where(np.isfinite(setpoints), setpoints, 0.0)
        self.velocities = self.a * now + (1 - self.a) * u
        q = np.asarray(lengths, dtype=float)
        self._lengths = q.copy() if np.all(np.isfinite(q)) else None
        self._setpoints = u
