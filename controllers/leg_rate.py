"""The measured-leg-rate feed-forward of the velocity laws (option
``leg_rate_feedforward``, ``docs/math.md`` section 6): what the drive-aware predictive
controller's gain comes from (``drive_model = "lag"``, ``drive_state = "measured"``),
for a one-step law.

A velocity drive follows its setpoint ``u`` with the lag of its velocity loop, first
order at its bandwidth ``omega = 2 pi f_b`` in the controllers' model (the nominal
robot file's ``[drives] velocity_bandwidth``). Over one period ``dt``, from the leg
velocity ``v`` measured now, the leg moves by ``dq = (dt - c) u + c v`` with
``a = exp(-omega dt)`` and ``c = (1 - a) / omega``. The law wants ``dq = dt q_dot*`` (its
command ``q_dot* = J_inv tau``); the setpoint that gives it is

``u = q_dot* + kappa (q_dot* - v)``,  ``kappa = c / (dt - c)``,

the law's velocity plus the shortfall of the legs' measured velocity, fed forward. As
``omega -> infinity``, ``kappa -> 0`` and the law's command comes back. A leg velocity
that is not measured (no ``q_dot``, a NaN in the row) leaves the command as the law's.
A wrapper that adds a velocity after the law (the tracking feed-forward ``r``,
:mod:`controllers.tracking`) tells it first (``velocity_offset``): the law then uses
``v - r``, so that the sum ``u + r`` is the setpoint above for ``q_dot* + r``.
"""

from __future__ import annotations

import numpy as np

from controllers.base import ControllerContext
from controllers.exceptions import ContextError


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
    omega = 2 * np.pi * np.broadcast_to(np.asarray(drives.velocity_bandwidth, float), (6,))
    c = -np.expm1(-omega * dt) / omega
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
