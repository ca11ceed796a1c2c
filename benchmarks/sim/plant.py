"""The plant seam: the TRUE robot between two control periods, for both engines.

A plant owns nothing of the controller: it receives the commanded leg velocities of the
rows that still run and moves the true state (leg lengths ``q``, platform pose ``R``,
``t``) over one control period. Both the batched engine (:mod:`benchmarks.sim.engine`)
and the per-trial path (:mod:`benchmarks.sim.stepper`) call the same plant, so they
give the same rows in every world.

- :class:`KinematicPlant` (``[robot] world = "kinematic"``, the default): today's world,
  massless and ideal. The command is clamped to the stroke and speed limits and
  integrated exactly over the period; the new pose is the forward kinematics of the true
  robot, warm-started at the previous pose.
- :class:`~benchmarks.sim.dynamic_plant.DynamicPlant` (``world = "dynamic"``): the true
  robot's dynamics and drives integrated at ``physics_dt`` (its own module).

The plants change the caller's arrays ``q``, ``R`` and ``t`` in place (rows ``run``).
"""

from __future__ import annotations

import logging
from typing import Any, Protocol

import numpy as np

from hexapod.backends.base import clamp_velocities
from hexapod.fk import pack_rows, set_guesses, solve_rows

log = logging.getLogger(__name__)

#: The failure of a trial whose true pose cannot be found from its leg lengths.
FK_FAILURE = "forward kinematics of the true robot failed (singularity?)"


class Plant(Protocol):
    """The true robot between control periods (see the module docstring)."""

    def advance(self, run: np.ndarray, velocities: np.ndarray, dt: float
                ) -> dict[int, str]:
        """Move rows ``run`` over one control period.

        Args:
            run: (n,) row indices of the trials that run this period.
            velocities: (n, 6) commanded leg velocities [m/s] (drive setpoints).
            dt: Control period [s].

        Returns:
            The rows (indices into the caller's arrays) whose world failed this period,
            with the reason (their state is left at the last good one).
        """
        ...

    def measured_lengths(self, rows: np.ndarray, offsets: np.ndarray) -> np.ndarray:
        """The encoder readings of ``rows``: true lengths plus ``offsets`` (n, 6) [m]."""
        ...

    def measured_rates(self, rows: np.ndarray) -> np.ndarray | None:
        """The measured leg velocities of ``rows`` (n, 6) [m/s], or None (kinematic)."""
        ...

    def row_figures(self, row: int) -> dict[str, Any]:
        """Extra figures of one trial for its result row (none in the kinematic world)."""
        ...

    def series(self, row: int) -> dict[str, np.ndarray]:
        """Extra values of one trial this period, for its recorded series (none in the
        kinematic world)."""
        ...


class KinematicPlant:
    """The massless ideal robot: leg lengths integrate the clamped command exactly.

    Args:
        q: (N, 6) true leg lengths [m] (changed in place).
        R: (N, 3, 3) true platform rotations (changed in place).
        t: (N, 3) true platform positions [m] (changed in place).
        base_points: (6, 3) or (N, 6, 3) true base points [m].
        platform_points: (6, 3) or (N, 6, 3) true platform points [m].
        stroke: Leg length limits ``(q_min, q_max)`` [m].
        max_speed: Leg speed limit [m/s].
    """

    def __init__(self, q: np.ndarray, R: np.ndarray, t: np.ndarray, base_points: np.ndarray,
                 platform_points: np.ndarray, stroke: tuple[float, float], max_speed: float
                 ) -> None:
        self.q, self.R, self.t = q, R, t
        self.stroke = stroke
        self.max_speed = max_speed
        # the robots' points packed once; the guesses and lengths are rewritten each period
        self._rows = pack_rows(R, t, q, base_points, platform_points)

    def advance(self, run: np.ndarray, velocities: np.ndarray, dt: float
                ) -> dict[int, str]:
        """See :meth:`Plant.advance`."""
        q = self.q
        vc, _ = clamp_velocities(q[run], velocities, dt, self.stroke, self.max_speed)
        q[run] = np.clip(q[run] + vc * dt, *self.stroke)
        bad = self.solve_poses(run)
        return dict.fromkeys(run[bad].tolist(), FK_FAILURE)

    def solve_poses(self, run: np.ndarray) -> np.ndarray:
        """Set the poses of ``run`` to the forward kinematics of their lengths, warm-started
        at their poses; returns the (n,) mask of rows where it failed (pose kept)."""
        x = self._rows[run]
        set_guesses(x, self.R[run], self.t[run], self.q[run])
        sol = solve_rows(x)
        bad = ~sol.converged
        okk = run[~bad]
        self.R[okk] = sol.rotations[~bad]
        self.t[okk] = sol.translations[~bad]
        return bad  # type: ignore[no-any-return]

    def measured_lengths(self, rows: np.ndarray, offsets: np.ndarray) -> np.ndarray:
        """See :meth:`Plant.measured_lengths` (ideal encoders)."""
        return self.q[rows] + offsets  # type: ignore[no-any-return]

    def row_figures(self, row: int) -> dict[str, Any]:
        """See :meth:`Plant.row_figures`: nothing."""
        return {}

    def measured_rates(self, rows: np.ndarray) -> np.ndarray | None:
        """The kinematic world measures no leg velocities (``Observation.q_dot`` None)."""
        return None

    def series(self, row: int) -> dict[str, np.ndarray]:
        """See :meth:`Plant.series`: nothing."""
        return {}


def make_plant(sc: Any, group: list[Any], q: np.ndarray, R: np.ndarray, t: np.ndarray,
               base_points: np.ndarray, platform_points: np.ndarray) -> Plant:
    """The plant of a group of trials in the scenario's world.

    Args:
        sc: The scenario (``sc.world``: ``"kinematic"`` or ``"dynamic"``).
        group: The trials (:class:`~benchmarks.sim.world.TrialSetup`), their true worlds.
        q, R, t: The caller's state arrays (changed in place by the plant).
        base_points, platform_points: The true robots' points, (6, 3) or (N, 6, 3) [m].
    """
    g = group[0].world.geometry
    if getattr(sc, "world", "kinematic") == "dynamic":
        from benchmarks.sim.dynamic_plant import DynamicPlant

        return DynamicPlant(sc, group, q, R, t, base_points, platform_points)
    return KinematicPlant(q, R, t, base_points, platform_points, g.stroke, g.max_speed)
