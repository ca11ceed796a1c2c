"""Tracking metrics of a trajectory task (``docs/scenarios.md``, "Trajectory tasks";
``docs/dynamic-world.md``): RMS and largest error of the TRUE pose from the reference
while it moves, and the settling time after its end (until the pose stays within the
tolerances), fed by :meth:`benchmarks.sim.book.Book.check` every period; in the dynamic
world the RMS drive force at the control instants (``rms_leg_force_n``), and with a
``[payload]`` the position error of the periods in which a drive was at its force limit
(``saturated_periods``, ``tracking_saturated_rms_mm``, ``tracking_saturated_max_mm``)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from benchmarks.sim.inputs import SimScenario


class Tracker:
    """The tracking metrics of a group of trials (index = row of the group).

    Args:
        sc: The scenario (a trajectory task).
        duration: (n,) the trials' reference durations [s]
            (:attr:`benchmarks.sim.reference.Targets.duration`).
    """

    def __init__(self, sc: SimScenario, duration: np.ndarray) -> None:
        n = len(duration)
        self.dt = sc.dt
        self.last_step = sc.task.max_steps
        self.duration = duration
        self._moving_until = self.duration + 1e-12  # (a period at t <= this is moving)
        #: The first and last references' ends: a period before the first moves every
        #: row, one after the last none.
        self._first_moving = float(self._moving_until.min()) if n else -np.inf
        self._last_moving = float(self._moving_until.max()) if n else -np.inf
        self._rows = np.arange(n)
        self.count = np.zeros(n, dtype=int)
        self.sum_dp2 = np.zeros(n)
        self.sum_da2 = np.zeros(n)
        self.max_dp = np.zeros(n)
        self.max_da = np.zeros(n)
        #: The plant's drive forces (n, 6) [N] of some rows, None in the kinematic world.
        self.drive_forces: Callable[[np.ndarray | slice], np.ndarray] | None = None
        self.sum_f2 = np.zeros(n)
        self.count_f = np.zeros(n, dtype=int)
        #: The plant's time at a force limit (n,) [s] of some rows (a payload scenario).
        self.saturation: Callable[[np.ndarray | slice], np.ndarray] | None = None
        self.per_leg = getattr(sc, "payload", None) is not None
        self.sat_seen = np.zeros(n)
        self.sat_count = np.zeros(n, dtype=int)
        self.sat_dp2 = np.zeros(n)
        self.sat_max = np.zeros(n)

    def follow(self, plant: Any) -> None:
        """Sample the drive forces of ``plant`` at every period (a plant without
        ``drive_forces``, the kinematic world's, gives none)."""
        self.drive_forces = getattr(plant, "drive_forces", None)
        if self.per_leg:
            self.saturation = getattr(plant, "saturated_time", None)

    def add(self, step: int, idx: np.ndarray | slice, dp: np.ndarray, da: np.ndarray
            ) -> None:
        """One period of the rows ``idx`` (indices, or a slice: every row): position
        errors ``dp`` [m], orientation errors ``da`` [rad] from the reference."""
        pos = self._rows[idx]  # (a slice: a view)
        now = step * self.dt
        if now <= self._last_moving:  # (no row moves once every reference has ended)
            moving = None if now <= self._first_moving else now <= self._moving_until[idx]
            rows, dpm, dam = ((idx, dp, da) if moving is None or moving.all()
                              else (pos[moving], dp[moving], da[moving]))
            self.count[rows] += 1
            self.sum_dp2[rows] += dpm ** 2
            self.sum_da2[rows] += dam ** 2
            self.max_dp[rows] = np.maximum(self.max_dp[rows], dpm)
            self.max_da[rows] = np.maximum(self.max_da[rows], dam)
        if self.drive_forces is not None:
            f2 = np.asarray(self.drive_forces(idx), dtype=float) ** 2
            total = f2[:, 0] + f2[:, 1]  # np.sum's order along a row, without a reduction
            for k in range(2, f2.shape[1]):
                total += f2[:, k]
            self.sum_f2[idx] += total
            self.count_f[idx] += f2.shape[1]
        if self.saturation is not None:
            seen = self.saturation(idx)
            hit = seen > self.sat_seen[idx]
            self.sat_seen[idx] = seen
            rows = pos[hit]
            self.sat_count[rows] += 1
            self.sat_dp2[rows] += dp[hit] ** 2
            self.sat_max[rows] = np.maximum(self.sat_max[rows], dp[hit])

    def row(self, m: int, last: int) -> dict[str, Any]:
        """The metrics of row ``m`` for its result row; ``last`` is the last period at
        which its pose was out of the tolerances (-1: none; the book's convergence test,
        :meth:`benchmarks.sim.book.Book.check`)."""
        c = max(int(self.count[m]), 1)
        end = float(self.duration[m])
        if last >= self.last_step:
            settle: float | None = None  # out of tolerance at the last period
        else:
            settle = max(0.0, (last + 1) * self.dt - end) if last >= 0 else 0.0
        forces = ({"rms_leg_force_n": float(np.sqrt(self.sum_f2[m] / self.count_f[m]))}
                  if self.count_f[m] else {})
        saturated: dict[str, Any] = {}
        if self.saturation is not None:
            k = int(self.sat_count[m])
            saturated = {"saturated_periods": k,
                         "tracking_saturated_rms_mm": (float(np.sqrt(self.sat_dp2[m] / k) * 1e3)
                                                       if k else None),
                         "tracking_saturated_max_mm": float(self.sat_max[m] * 1e3) if k
                         else None}
        return {
            **forces, **saturated,
            "trajectory_duration_s": end,
            "tracking_rms_position_mm": float(np.sqrt(self.sum_dp2[m] / c) * 1e3),
            "tracking_max_position_mm": float(self.max_dp[m] * 1e3),
            "tracking_rms_orientation_deg": float(np.rad2deg(np.sqrt(self.sum_da2[m] / c))),
            "tracking_max_orientation_deg": float(np.rad2deg(self.max_da[m])),
            "settling_time_s": settle,
        }

