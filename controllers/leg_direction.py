"""Leg-direction visual servoing (seeds 001 and 003): ``e_i = u_i x u_i*``.

``L_i = -[u_i*]_x M_i`` (``docs/math.md`` section 6), stacked over the visible legs
(18 x 6 with all six), ``tau = -lambda L^+ e``, ``q_dot = J_inv tau``. One call of
the compiled core (:func:`controllers.law_kernel.feature_law_kernel` of
:data:`~controllers.tasks.leg_direction.LEG_DIRECTIONS`, generated from the task's block
:func:`controllers.tasks.leg_direction.direction_block`) computes the step, for every
interaction choice; hidden legs are its zero-weight rows.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from controllers.base import ControllerContext, GoalBatch, Observation
from controllers.law_tools import Selection, goal_directions
from controllers.laws import VisionLaw
from controllers.tasks.leg_direction import LEG_DIRECTIONS
from controllers.tasks.leg_feature import LegFeature


class LegDirectionController(VisionLaw):
    """Leg-direction law: error ``u x u*``, interaction ``-[u*]_x M`` (seeds 001/003).

    The options of :class:`~controllers.laws.VisionLaw` (``gain``, ``adaptive_gain``,
    ``interaction``, ``threshold``, ``damping``, ``compiled``, ``leg_rate_feedforward``;
    documented there).
    """

    name = "leg-direction"
    features = frozenset({"lengths", "directions"})
    unit = "legs"
    observed_feature = LEG_DIRECTIONS
    #: The feature whose compiled core the law uses (a plugin's in
    #: :class:`~controllers.features.laws.FeatureLaw`).
    feature: ClassVar[LegFeature] = LEG_DIRECTIONS

    def _reset_features(self, context: ControllerContext) -> None:
        us, vis = goal_directions(self.name, context.goal)
        self._u_star = np.where(vis[:, None], us, 0.0)
        self._install_goal(self._u_star, us, vis)

    def _install_goal(self, desired: np.ndarray, us: np.ndarray, vis: np.ndarray) -> None:
        """Set the goal's visible legs ``vis`` (6,), the fill of hidden legs ``us`` (the
        desired directions, ``+z`` where unknown) and the core's goal inputs (``desired``
        zero where unknown)."""
        self._goal_visible = vis
        self._fill = us
        # (the legs' goal state of the DESIRED / MEAN interaction, where the core has it)
        self._install_kernel(self.feature, desired=desired, desired_directions=us)

    def desired_features(self) -> np.ndarray:
        """(6, 3) the desired leg directions (zeros where unknown)."""
        return np.asarray(self._u_star, dtype=float)

    def _batch_desired(self, goals: GoalBatch) -> tuple[np.ndarray | None, np.ndarray]:
        """The goals' directions as the compiled core's desired input, where all six are
        finite unit vectors: what :meth:`_reset_features` reads then."""
        m = len(goals)
        d = goals.directions
        if d is None or not self.compiled or self.interaction != "current":
            return None, np.zeros(m, dtype=bool)
        us = np.asarray(d, dtype=float)
        if us.shape != (m, 6, 3):
            return None, np.zeros(m, dtype=bool)  # the instances say what is wrong
        with np.errstate(invalid="ignore"):
            ok = np.isfinite(us).reshape(m, 18).all(axis=1)
            ok &= (np.abs(np.linalg.norm(us, axis=-1) - 1.0) <= 1e-6).all(axis=1)
        return us.reshape(m, 18), ok

    def _select(self, obs: Observation, q: np.ndarray) -> Selection:
        u_obs = np.asarray(obs.directions, dtype=float)
        vis = np.asarray(obs.direction_visible, dtype=bool) & self._goal_visible
        est = self.estimate
        est.predict_hidden(~vis, self.base_points, self.dt)
        est.directions[vis] = u_obs[vis]
        est.observed[:] = vis
        known = np.isfinite(est.directions[:, 0])
        # J_inv of a leg never seen: its desired direction (exact at the goal).
        est.in_use[:] = np.where(known[:, None], est.directions,
                                 np.where(self._goal_visible[:, None], self._u_star, np.nan))
        return Selection(np.where(vis[:, None], u_obs, self._fill), vis, vis,
                         est.in_use.copy(),
                         self._notes(vis, ~vis & known, ~known & self._goal_visible))
