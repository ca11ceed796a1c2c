"""What a control law carries from one period to the next (a task is a pure function of
the current measurements): the leg directions the vision laws know
(:class:`LegDirectionEstimate`) and the pose that warm-starts a forward kinematics
(:class:`PoseEstimate`). A batch estimate has a leading trial axis; ``row(k)`` gives one
trial's as views into it (a trial stepped alone or in its batch writes the same memory).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controllers.interaction import direction_interaction
from controllers.tasks.base import unit


@dataclass
class LegDirectionEstimate:
    """The leg directions a vision law knows between periods.

    Attributes:
        directions: (..., 6, 3) measured leg directions ``u_i`` (camera frame), the
            dead-reckoned value for legs hidden since, NaN for legs never seen.
        observed: (..., 6) bool, legs whose direction was measured this period.
        in_use: (..., 6, 3) the directions the inverse Jacobian uses this period
            (``directions``, or an approximation for never-seen legs; NaN unknown).
        twist: (..., 6) twist ``(v, w)`` commanded last period [m/s, rad/s] (zero
            after a refusal: nothing moved).
        lengths: (..., 6) leg lengths when that twist was commanded [m].
    """

    directions: np.ndarray
    observed: np.ndarray
    in_use: np.ndarray
    twist: np.ndarray
    lengths: np.ndarray

    @staticmethod
    def fresh(n: int | None = None) -> LegDirectionEstimate:
        """Nothing known: ``n`` trials (None: one trial, no leading axis)."""
        lead: tuple[int, ...] = () if n is None else (n,)
        return LegDirectionEstimate(
            directions=np.full((*lead, 6, 3), np.nan), observed=np.zeros((*lead, 6), bool),
            in_use=np.full((*lead, 6, 3), np.nan), twist=np.zeros((*lead, 6)),
            lengths=np.ones((*lead, 6)))

    def row(self, k: int) -> LegDirectionEstimate:
        """Trial ``k`` of a batch estimate, as views (writes go to the batch)."""
        return LegDirectionEstimate(self.directions[k], self.observed[k], self.in_use[k],
                                    self.twist[k], self.lengths[k])

    def measured_all(self, directions: np.ndarray, rows: np.ndarray | None = None) -> None:
        """Every direction measured this period (of the trials ``rows`` of a batch)."""
        at = Ellipsis if rows is None else rows
        self.directions[at] = directions
        self.observed[at] = True
        self.in_use[at] = directions

    def commanded(self, twist: np.ndarray, lengths: np.ndarray,
                  rows: np.ndarray | None = None) -> None:
        """A command was sent: the twist and lengths the dead reckoning integrates."""
        at = Ellipsis if rows is None else rows
        self.twist[at] = twist
        self.lengths[at] = lengths

    def halted(self) -> None:
        """No command was sent this period (a refusal): nothing to integrate."""
        self.twist[...] = 0.0

    def predict_hidden(self, hidden: np.ndarray, base_points: np.ndarray, dt: float) -> None:
        """Dead-reckon the directions of hidden legs over the last period (one trial).

        ``u += dt M_i(u, q_prev) tau_prev`` with the twist commanded at the previous
        period (nothing when it was zero). Call before writing the observed ones.

        Args:
            hidden: (6,) bool, legs not measured this period.
            base_points: (6, 3) estimated ``A_i`` [m].
            dt: Control period [s].
        """
        hidden = hidden & np.isfinite(self.directions[:, 0])
        if not hidden.any() or not np.any(self.twist):
            return
        u = self.directions[hidden]
        M = direction_interaction(base_points[hidden], u, self.lengths[hidden])
        self.directions[hidden] = unit(u + dt * (M @ self.twist))


@dataclass
class PoseEstimate:
    """A platform pose remembered between periods (warm start of a forward kinematics).

    Attributes:
        rotation: (..., 3, 3) platform orientation in the nominal base frame.
        translation: (..., 3) platform position in the nominal base frame [m].
    """

    rotation: np.ndarray
    translation: np.ndarray

    @staticmethod
    def of(rotations: np.ndarray, translations: np.ndarray) -> PoseEstimate:
        """An estimate holding copies of these poses."""
        return PoseEstimate(np.array(rotations, dtype=float),
                            np.array(translations, dtype=float))

    def row(self, k: int) -> PoseEstimate:
        """Trial ``k`` of a batch estimate, as views (writes go to the batch)."""
        return PoseEstimate(self.rotation[k], self.translation[k])

    def set(self, rotation: np.ndarray, translation: np.ndarray,
            rows: np.ndarray | None = None) -> None:
        """Remember new poses (of the trials ``rows`` of a batch)."""
        at = Ellipsis if rows is None else rows
        self.rotation[at] = rotation
        self.translation[at] = translation

    @property
    def pose(self) -> tuple[np.ndarray, np.ndarray]:
        """``(rotation, translation)`` (one trial)."""
        return self.rotation, self.translation


__all__ = ["LegDirectionEstimate", "PoseEstimate"]

