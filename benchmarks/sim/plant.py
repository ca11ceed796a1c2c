"""The plant seam: the robot between two control periods, for the one closed loop
(:func:`benchmarks.sim.loop.closed_loop`). A plant owns nothing of the controller: it
moves the state of the rows that still run (leg lengths ``q``, platform pose ``R``,
``t``: the caller's arrays, changed in place) over one control period with their
commands. :class:`KinematicPlant` (``[robot] world = "kinematic"``, the default) is the
massless ideal robot, :class:`~benchmarks.sim.dynamic_plant.DynamicPlant` the true
robot's dynamics and drives, :class:`BackendPlant` robots behind backends (a study's
``--backend``, the servo session's robot).

What a world applies (:func:`world_actuation`, :mod:`hexapod.actuation`): the kinematic
world integrates leg velocities and refuses a controller that commands leg forces (an
:class:`~hexapod.exceptions.ActuationError` naming it, the trial's failure); the dynamic
world's drives follow what the controller commands (velocity mode, or force mode for
leg forces; the rest of the robot file is kept).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from hexapod.actuation import Actuation
from hexapod.backends.base import Backend, clamp_velocities
from hexapod.fk import pack_rows, set_guesses, solve_rows
from hexapod.plausible import reading_problem

#: The failure of a trial whose true pose cannot be found from its leg lengths.
FK_FAILURE = "forward kinematics of the true robot failed (singularity?)"


class Plant:
    """The robot between control periods (see the module docstring); the kinematic
    world's encoders and figures, which the other plants override.

    Attributes:
        q: (N, 6) leg lengths [m] of every row (the plant changes them).
        R: (N, 3, 3) platform rotations: the poses the camera sees.
        t: (N, 3) platform positions [m].
    """

    q: np.ndarray
    R: np.ndarray
    t: np.ndarray

    def advance(self, run: np.ndarray, velocities: np.ndarray, dt: float
                ) -> dict[int, str]:
        """Move rows ``run`` (n,) with their commands ``velocities`` (n, 6) [m/s] over
        one control period ``dt`` [s]; returns the rows whose world failed, with the
        reason (their state is left at the last good one)."""
        raise NotImplementedError

    def use_actuation(self, actuation: Actuation, label: str) -> None:
        """Apply what the controller ``label`` commands (the kinematic world integrates
        leg velocities: nothing to switch)."""

    def measured_lengths(self, rows: np.ndarray, offsets: np.ndarray) -> np.ndarray:
        """The encoder readings of ``rows``: true lengths plus ``offsets`` (n, 6) [m]."""
        return self.q[rows] + offsets  # type: ignore[no-any-return]

    def measured_rates(self, rows: np.ndarray) -> np.ndarray | None:
        """The measured leg velocities of ``rows`` (n, 6) [m/s], or None (none measured:
        ``Observation.q_dot`` None)."""
        return None

    def row_figures(self, row: int) -> dict[str, Any]:
        """Extra figures of one trial for its result row (none in the kinematic world)."""
        return {}

    def series(self, row: int) -> dict[str, np.ndarray]:
        """Extra values of one trial this period, for its recorded series (none in the
        kinematic world)."""
        return {}


class KinematicPlant(Plant):
    """The massless ideal robot: leg lengths integrate the clamped command exactly.

    Args:
        q, R, t: (N, 6) true leg lengths [m], (N, 3, 3) rotations and (N, 3) positions
            [m] (changed in place).
        base_points, platform_points: (6, 3) or (N, 6, 3) true robots' points [m].
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


class BackendPlant(Plant):
    """Robots behind backends, one per row: each backend applies its row's command over
    the period (and paces it), the lengths are what it measures, the poses follow.

    Args:
        backends: One connected backend per row.
        q: (N, 6) leg lengths [m] (changed in place: measured minus ``offsets``).
        R, t: (N, 3, 3), (N, 3) [m] platform poses (changed in place by ``solve_poses``).
        offsets: (N, 6) encoder offsets [m]: measured = ``q`` + offsets.
        solve_poses: Sets the poses of rows ``run`` from their lengths ``q``; returns the
            (n,) mask of rows whose pose could not be found
            (:meth:`KinematicPlant.solve_poses` in a study).
        stroke: The nominal robot's stroke (q_min, q_max) [m]: a reading that cannot be
            its legs (:func:`reading_problem`) fails its row with the reason, its state
            left at the last good reading.
    """

    def __init__(self, backends: Sequence[Backend], q: np.ndarray, R: np.ndarray,
                 t: np.ndarray, offsets: np.ndarray,
                 solve_poses: Callable[[np.ndarray], np.ndarray],
                 stroke: tuple[float, float]) -> None:
        self.backends = list(backends)
        self.q, self.R, self.t = q, R, t
        self.offsets = offsets
        self.solve_poses = solve_poses
        self.stroke = stroke
        self.actuation = Actuation.VELOCITY
        self.label = "controller"
        n = len(self.backends)
        #: Each row's round-trip times [s].
        self.rtts: list[list[float]] = [[] for _ in range(n)]
        #: Each row's late periods.
        self.missed = np.zeros(n, dtype=int)
        #: Each row's last :class:`~hexapod.backends.base.BackendStep` (None before).
        self.last: list[Any] = [None] * n

    def use_actuation(self, actuation: Actuation, label: str) -> None:
        """See :meth:`Plant.use_actuation` (each backend checks it)."""
        self.actuation = actuation
        self.label = label

    def advance(self, run: np.ndarray, velocities: np.ndarray, dt: float
                ) -> dict[int, str]:
        """See :meth:`Plant.advance` (``velocities``: the commands of their kind; a
        reading that cannot be the robot's legs fails its row, :func:`reading_problem`)."""
        failures: dict[int, str] = {}
        for j, k in enumerate(run.tolist()):
            bs = self.backends[k].apply(velocities[j], self.actuation, dt, self.label)
            self.rtts[k].append(float(bs.round_trip_s))
            self.missed[k] += int(bs.missed_period)
            self.last[k] = bs
            problem = reading_problem(bs.lengths, self.stroke)
            if problem is None:
                self.q[k] = bs.lengths - self.offsets[k]
            else:
                failures[k] = problem
        if failures:
            run = run[[k not in failures for k in run.tolist()]]
        bad = self.solve_poses(run)  # the backends moved the legs: the poses follow
        return {**failures, **dict.fromkeys(run[bad].tolist(), FK_FAILURE)}

    def row_figures(self, row: int) -> dict[str, Any]:
        """The link's figures of one row: round-trip median and p99 [ms], late periods."""
        if not self.rtts[row]:
            return {}
        arr = np.array(self.rtts[row]) * 1e3
        return {"rtt_median_ms": float(np.median(arr)),
                "rtt_p99_ms": float(np.percentile(arr, 99)),
                "missed_periods": int(self.missed[row])}


def world_actuation(sc: Any) -> tuple[tuple[Actuation, ...], str]:
    """What the scenario's world (``sc.world``) applies, and how messages name it."""
    if getattr(sc, "world", "kinematic") == "dynamic":
        from benchmarks.sim.world import load_geometry

        if load_geometry(sc).drives.mode == "force":  # no velocity loop to command
            return ((Actuation.FORCE,), "the dynamic world with force-mode drives (robot "
                    "file [drives] mode = \"force\")")
        return (Actuation.VELOCITY, Actuation.FORCE), "the dynamic world"
    return (Actuation.VELOCITY,), "the kinematic world"


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
