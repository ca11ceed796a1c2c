"""The dynamic world: the TRUE robot's mechanism, drives and encoders between control periods
(``[robot] world = "dynamic"``, ``docs/dynamic-world.md``).

Every trial's true robot is integrated over a control period in ``dt / physics_dt``
steps by :class:`hexapod.dynamics.robots.DynamicRobots`, from rest with its drives
holding the platform against gravity; the drives' setpoints are the controller's leg
velocities clamped as the kinematic world clamps them, or leg forces in force mode. A
trial's world fails when a leg ends a period beyond its stroke by more than
:data:`END_STOP` (an end stop) or the state is not finite. The controller sees the
encoders (true lengths plus the joint offsets, quantised to the encoder resolution); the
rows get the drive figures (:meth:`DynamicPlant.row_figures`), the series the forces.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from benchmarks.sim.plant import Plant
from benchmarks.sim.world import TrialSetup
from hexapod.actuation import Actuation
from hexapod.backends.base import clamp_velocities
from hexapod.dynamics.drive_model import quantise
from hexapod.dynamics.robots import DynamicRobots
from hexapod.dynamics.robots_compiled import row_index
from hexapod.exceptions import ActuationError

#: A leg beyond its stroke by more than this has hit its end stop [m].
END_STOP = 1e-4
#: The saturation columns of the rows of a scenario with a ``[payload]``.
SATURATION_COLUMNS = ("saturation_legs_s", "saturation_legs_fraction", "saturation_fraction")


class DynamicPlant(Plant):
    """The dynamic world of a group of trials (see the module docstring).

    Args:
        sc: The scenario (``dt``, ``physics_dt``).
        group: The trials; each row's true robot is ``group[k].world.geometry``.
        q, R, t: The true state, as :class:`~benchmarks.sim.plant.KinematicPlant`'s.
        base_points, platform_points: The true robots' points, (6, 3) or (N, 6, 3) [m].
    """

    def __init__(self, sc: Any, group: list[TrialSetup], q: np.ndarray, R: np.ndarray,
                 t: np.ndarray, base_points: np.ndarray, platform_points: np.ndarray) -> None:
        self.q, self.R, self.t = q, R, t  # R, t changed in place by the robots
        self.steps = max(1, round(sc.dt / sc.physics_dt))
        self.h = sc.dt / self.steps
        self.dt = sc.dt
        geometries = [s.world.geometry for s in group]
        self.stroke, self.max_speed = geometries[0].stroke, geometries[0].max_speed
        self.robots = DynamicRobots(geometries, R, t, base_points, platform_points)
        #: Whether the rows get :data:`SATURATION_COLUMNS` (a scenario with a payload).
        self.per_leg = getattr(sc, "payload", None) is not None
        #: (N,) periods each trial has run.
        self.periods = np.zeros(len(group), dtype=int)
        #: (N, 6) one encoder count per control period [m/s]: the leg rates' resolution.
        self.rate_resolution = self.robots.resolution / self.dt

    def use_actuation(self, actuation: Actuation, label: str) -> None:
        """Drive the legs in the mode of ``actuation``: force (torque) mode for leg
        forces, the robot file's mode for leg velocities."""
        if actuation is Actuation.FORCE:
            self.robots.drives.mode = "force"
        elif self.robots.drives.mode == "force":
            raise ActuationError(label, "velocity", ("force",), "the dynamic world's "
                                 "force-mode drives (robot file [drives] mode = \"force\")",
                                 problem=None, quantity=Actuation.VELOCITY.quantity,
                                 accepted_quantities=[Actuation.FORCE.quantity])

    def measured_rates(self, rows: np.ndarray) -> np.ndarray:
        """The encoders' leg velocities (n, 6) [m/s]: the true leg rates quantised to one
        encoder count per control period (what a velocity estimate from the counts
        resolves)."""
        index = row_index(rows)
        return quantise(self.robots.leg_rates(index), self.rate_resolution[index])

    def advance(self, run: np.ndarray, velocities: np.ndarray, dt: float
                ) -> dict[int, str]:
        """See :meth:`benchmarks.sim.plant.Plant.advance` (``velocities`` are leg velocity
        setpoints [m/s] in velocity mode, leg forces [N] in force mode)."""
        robots = self.robots
        index = row_index(run)  # (consecutive rows: slices, views)
        if robots.drives.mode == "velocity":
            setpoints, _ = clamp_velocities(self.q[index], velocities, dt, self.stroke,
                                            self.max_speed)
        else:
            setpoints = np.where(np.isfinite(velocities), velocities, 0.0)
        diverged = robots.advance(run, setpoints, self.h, self.steps)
        self.periods[index] += 1
        q = robots.period_lengths[index]
        lo, hi = self.stroke
        inside = (q > lo - END_STOP) & (q < hi + END_STOP)
        if inside.all() and not diverged.any():  # the common case
            self.q[index] = q
            return {}
        out = ~np.all(inside, axis=1) & ~diverged
        failed = {int(k): "the dynamic world diverged (a non-finite state)"
                  for k in run[diverged]}
        for j in np.flatnonzero(out):
            leg = int(np.argmax(np.maximum(lo - q[j], q[j] - hi)))
            failed[int(run[j])] = (f"leg {leg} hit its end stop: {q[j, leg] * 1e3:.3f} mm, "
                                   f"stroke [{lo * 1e3:.3f}, {hi * 1e3:.3f}] mm")
        good = ~diverged
        self.q[run[good]] = q[good]
        return failed

    def measured_lengths(self, rows: np.ndarray, offsets: np.ndarray) -> np.ndarray:
        """See :meth:`benchmarks.sim.plant.Plant.measured_lengths`: the encoders' counts."""
        index = row_index(rows)
        return quantise(self.q[index] + offsets, self.robots.resolution[index])

    def row_figures(self, row: int) -> dict[str, Any]:
        """The drive figures of one trial's result row: largest drive force [N], time at
        a force limit [s], RMS and largest drive tracking error [mm/s]."""
        r = self.robots
        count = r.track_count[row]
        return {
            "max_leg_force_n": float(r.force_max[row]),
            "saturation_time_s": float(r.saturated_time[row]),
            "drive_tracking_rms_mm_s": (float(np.sqrt(r.track_sq[row] / count) * 1e3)
                                        if count else None),
            "drive_tracking_max_mm_s": float(r.track_max[row] * 1e3) if count else None,
            **(self._saturation(row) if self.per_leg else {}),
        }

    def _saturation(self, row: int) -> dict[str, Any]:
        """:data:`SATURATION_COLUMNS` of one trial: each leg's time at its force limit [s]
        and its fraction of the time run, and the fraction any leg spent there."""
        legs = self.robots.saturated_legs[row]
        run = self.periods[row] * self.dt
        share = (lambda x: float(x / run) if run > 0 else None)  # noqa: E731
        return {"saturation_legs_s": [float(x) for x in legs],
                "saturation_legs_fraction": [share(x) for x in legs],
                "saturation_fraction": share(self.robots.saturated_time[row])}

    def saturated_time(self, rows: np.ndarray | slice) -> np.ndarray:
        """The time (n,) [s] any drive of ``rows`` (indices or a slice) has spent at its
        force limit so far."""
        return self.robots.saturated_time[rows].copy()

    def drive_forces(self, rows: np.ndarray | slice) -> np.ndarray:
        """The drives' forces (n, 6) [N] of ``rows`` (indices or a slice: a view) at the
        end of the last period."""
        return self.robots.forces[rows]

    def series(self, row: int) -> dict[str, np.ndarray]:
        """The drives' forces (6,) [N] at the end of the last period."""
        return {"leg_forces": self.robots.forces[row].copy()}
