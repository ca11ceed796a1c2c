"""The measured-leg-rate feed-forward of the velocity laws (option
``leg_rate_feedforward``; the drive model and its inversion: ``docs/math.md`` section 6,
"Measured-leg-rate feed-forward"): the setpoint ``u = q_dot* + kappa (q_dot* - v)``,
``kappa = c / (dt - c)``, that moves each lagging velocity drive by ``dt q_dot*`` over
the period from its measured velocity ``v`` (an unmeasured or non-finite ``v`` leaves the
law's command). A wrapper that adds ``r`` after the law (the tracking feed-forward,
:mod:`controllers.tracking`) tells it first (``velocity_offset``): the law then uses
``v - r``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from controllers.base import Command, ControllerContext, Observation
from controllers.exceptions import ContextError, OptionError


def lag_constants(drives: Any, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """``a = exp(-omega dt)``, ``c = (1 - a) / omega`` [s] (6,) of the drives' velocity lag."""
    omega = 2 * np.pi * np.broadcast_to(np.asarray(drives.velocity_bandwidth, float), (6,))
    return np.exp(-omega * dt), -np.expm1(-omega * dt) / omega


def feedforward_gain(context: ControllerContext, dt: float, name: str) -> np.ndarray:
    """``kappa = c / (dt - c)`` (6,) of the nominal velocity drives over a period ``dt``
    [s] (module docstring).

    Raises:
        ContextError: The nominal drives are in force mode (no velocity loop lags the
            command), or their model has no geometry.
    """
    geometry = getattr(context, "geometry", None)
    drives = getattr(geometry, "drives", None)
    if drives is None:
        raise ContextError(name, "geometry.drives", "leg_rate_feedforward needs the nominal "
                           "drives' bandwidth (a geometry with [drives])")
    if drives.mode != "velocity":
        raise ContextError(name, "geometry.drives.mode", "leg_rate_feedforward models "
                           f"velocity-mode drives; the robot's [drives] mode is {drives.mode!r}")
    _, c = lag_constants(drives, dt)
    return c / (dt - c)  # type: ignore[no-any-return]


def feed_forward(q_dot: np.ndarray, measured: np.ndarray | None, offset: np.ndarray,
                 kappa: np.ndarray) -> np.ndarray:
    """``u = q_dot + kappa (q_dot - (v - offset))`` row by row, (6,) or (n, 6) [m/s]; a
    row whose measured velocity ``v`` is absent or not finite keeps ``q_dot``.

    Args:
        q_dot: The law's leg velocities [m/s].
        measured: The measured leg velocities ``v`` [m/s] (None: not measured).
        offset: What a wrapper adds after the law [m/s].
        kappa: :func:`feedforward_gain` [-].
    """
    q = np.asarray(q_dot, dtype=float)
    if measured is None:
        return q
    v = np.asarray(measured, dtype=float)
    u = q + kappa * (q - (v - offset))
    known = np.all(np.isfinite(v), axis=-1, keepdims=True)
    return np.where(known, u, q)  # type: ignore[no-any-return]


class LegRateFeedForward:
    """The option's state and steps, for the one-step velocity laws
    (:class:`controllers.laws.VisionLaw` derives from it): off, the law's command goes out
    as it is; on, :func:`feed_forward` of it: per trial (:meth:`fed_forward`, the rows a
    batch leaves to Python) or in the batch's C (:mod:`controllers.law_rows`)."""

    #: The controller's name (set by the controller class).
    name: str = "controller"
    #: Whether the option is on.
    leg_rate_feedforward: bool = False
    #: ``kappa`` (6,) after a reset (None: off).
    rate_kappa: np.ndarray | None = None
    #: What a wrapper adds after the law this period [m/s] (a row of the batch's).
    rate_offset: np.ndarray
    #: ``kappa`` of every trial of a batch (rows), None when off.
    batch_kappa: np.ndarray | None = None
    #: The wrapper offsets of every trial of a batch [m/s] (the instances' rows).
    batch_offset: np.ndarray

    def init_leg_rate(self, value: Any) -> None:
        """Check and keep the option (``velocity_offset`` is defined only when on: the
        tracking wrapper tells the controllers that have one, :mod:`controllers.tracking`).

        Raises:
            OptionError: Not a boolean.
        """
        if not isinstance(value, bool | np.bool_):
            raise OptionError(self.name, "leg_rate_feedforward",
                              f"expected true or false, got {value!r}")
        self.leg_rate_feedforward = bool(value)
        self.rate_offset = np.zeros(6)
        if self.leg_rate_feedforward:
            self.velocity_offset = self._velocity_offset

    def reset_leg_rate(self, context: ControllerContext, dt: float) -> None:
        """The trial's ``kappa`` (when on).

        Raises:
            ContextError: As :func:`feedforward_gain`.
        """
        if self.leg_rate_feedforward:
            self.rate_kappa = feedforward_gain(context, dt, self.name)
            self.rate_offset = np.zeros(6)

    def _velocity_offset(self, q_dot: np.ndarray) -> None:
        """The leg velocities [m/s] a wrapper adds to the coming step's command (the
        tracking feed-forward): the feed-forward then compares the measured leg rates
        with the law's command plus them. Cleared after the step."""
        self.rate_offset[:] = np.asarray(q_dot, dtype=float).reshape(6)

    def fed_forward(self, cmd: Command, observation: Observation) -> Command:
        """The law's command of one trial, fed forward when on (a refusal as it is); the
        wrapper's offset cleared."""
        if self.rate_kappa is None:
            return cmd
        offset, self.rate_offset[:] = self.rate_offset.copy(), 0.0
        if cmd.reason is None:
            cmd.velocities = feed_forward(cmd.velocities, observation.q_dot, offset,
                                          self.rate_kappa)
        return cmd

    def batch_reset_leg_rate(self, trials: Sequence[Any]) -> None:
        """Gather the trials' ``kappa`` and make their offsets rows of one array."""
        self.batch_kappa = None
        if self.leg_rate_feedforward:
            self.batch_kappa = np.array([t.rate_kappa for t in trials])
            self.batch_offset = np.zeros((len(trials), 6))
            for k, inst in enumerate(trials):
                inst.rate_offset = self.batch_offset[k]
