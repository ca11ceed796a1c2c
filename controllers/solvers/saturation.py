"""What a computed-torque law commands when a leg's force is over the NOMINAL drives'
``force_limit`` (option ``saturation``; ``docs/dynamic-world.md``):

- ``"clip"`` (default, what the force-mode drives do anyway): each leg clipped to
  ``[-limit, limit]`` on its own;
- ``"scale"``: the whole vector scaled by ``min_i limit_i / |f_i|``, its direction kept;
- ``"qp"``: the direction of the task acceleration kept: ``f_0 + s (f - f_0)``, ``f_0``
  the nominal forces at zero platform acceleration, ``s`` the largest in ``[0, 1]`` within
  the limits (:func:`acceleration_fraction`); clipped when ``f_0`` alone is over a limit.

Rows under every limit are returned unchanged (the same numbers, bit for bit).
"""

from __future__ import annotations

import operator
from typing import TYPE_CHECKING

import numpy as np

from controllers.exceptions import OptionError

if TYPE_CHECKING:
    from hexapod.dynamics import DynamicModel

#: The strategies (module docstring).
STRATEGIES = ("clip", "scale", "qp")


def checked_strategy(controller: str, strategy: object) -> str:
    """``strategy`` if it is one of :data:`STRATEGIES`.

    Raises:
        OptionError: Naming the option and the strategies.
    """
    if strategy not in STRATEGIES:
        raise OptionError(controller, "saturation", f"expected one of "
                          f"{', '.join(map(repr, STRATEGIES))}, got {strategy!r}")
    return str(strategy)


def over_limit(forces: np.ndarray, limit: np.ndarray | list[float]) -> bool:
    """Whether a leg's force (6,) [N] is over its limit (6,) [N] (a NaN is not; the
    limits may be given as a list, the per-step callers' cached one)."""
    lim = limit.tolist() if isinstance(limit, np.ndarray) else limit
    return any(map(operator.gt, map(abs, forces.tolist()), lim))


def acceleration_fraction(forces: np.ndarray, bias: np.ndarray, limit: np.ndarray
                          ) -> float | None:
    """The largest ``s`` in ``[0, 1]`` with ``|bias + s (forces - bias)| <= limit`` [N] on
    every leg (the solution of ``min (1 - s)^2`` there), or None when ``bias`` (the
    forces at zero platform acceleration) is over a limit."""
    f0 = np.asarray(bias, dtype=float)
    g = np.asarray(forces, dtype=float) - f0
    if np.any(np.abs(f0) > limit) or not np.all(np.isfinite(g)):
        return None
    s = 1.0
    for gi, f0i, li in zip(g.tolist(), f0.tolist(), limit.tolist(), strict=True):
        if gi > 0.0:
            s = min(s, (li - f0i) / gi)
        elif gi < 0.0:
            s = min(s, (-li - f0i) / gi)
    return max(s, 0.0)


def saturated(strategy: str, forces: np.ndarray, limit: np.ndarray,
              bias: np.ndarray | None = None) -> np.ndarray:
    """The forces [N] the controller commands under ``strategy`` (module docstring).

    Args:
        strategy: One of :data:`STRATEGIES`.
        forces: (6,) the forces of the control law [N].
        limit: (6,) the nominal drives' limits [N].
        bias: (6,) the forces at zero platform acceleration [N] (``"qp"`` only; needed
            when a leg is over its limit).
    """
    if not over_limit(forces, limit):
        return forces
    if strategy == "scale":  # the most loaded leg at its limit
        f = np.asarray(forces, dtype=float)
        a = np.abs(f)
        over = a > limit
        return f * float(np.min(limit[over] / a[over]))  # type: ignore[no-any-return]
    if strategy == "qp":
        if bias is None:
            raise ValueError("saturation 'qp': the forces at zero acceleration are needed")
        s = acceleration_fraction(forces, bias, limit)
        if s is not None:
            forces = bias + s * (forces - bias)  # clipped below: rounding at the limit
    return np.clip(forces, -limit, limit)  # type: ignore[no-any-return]


def zero_acceleration_forces(model: DynamicModel, pose: np.ndarray, q_dot: np.ndarray,
                             coulomb_velocity: np.ndarray | None = None, hold: float = 0.0
                             ) -> np.ndarray:
    """The nominal forces [N] at zero platform acceleration (``f_0`` of ``"qp"``):
    :meth:`~controllers.solvers.computed_torque.ComputedTorqueSolver.forces` with a zero
    acceleration at the twist ``K^-1 q_dot``.

    Args:
        model: The NOMINAL dynamic model.
        pose: (12,) ``R`` (column-major) and ``t`` [m], as the compiled steps give it.
        q_dot: (6,) measured leg velocities [m/s].
        coulomb_velocity: As :meth:`ComputedTorqueSolver.forces` (None: ``q_dot + hold a``).
        hold: The control period [s].
    """
    from controllers.solvers.computed_torque import ComputedTorqueSolver

    R, t = pose[0:9].reshape(3, 3).T, pose[9:12]
    K = model.terms_batch(R[None], t[None], np.zeros((1, 6)))[2][0]
    twist = np.linalg.solve(K, q_dot)
    f, _ = ComputedTorqueSolver.forces(model, R, t, twist, np.zeros(6), q_dot,
                                       coulomb_velocity, hold)
    return f


__all__ = ["STRATEGIES", "acceleration_fraction", "checked_strategy", "over_limit",
           "saturated", "zero_acceleration_forces"]
