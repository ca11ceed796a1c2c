"""Leg-direction visual servoing (seeds 001 and 003): ``e_i = u_i x u_i*``.

``L_i = -[u_i*]_x M_i`` (``docs/math.md`` section 6), stacked over the visible legs
(18 x 6 with all six), ``tau = -lambda L^+ e``, ``q_dot = J_inv tau``. One call of
the compiled core (:func:`controllers.law_kernel.direction_kernel`, generated from the
task's block :func:`controllers.tasks.leg_direction.direction_block`) computes the
step, for every interaction choice; hidden legs are its zero-weight rows.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from controllers.base import ControllerContext, GoalBatch, Observation, ObservationBatch
from controllers.law_kernel import LawKernel, direction_kernel
from controllers.law_tools import goal_directions
from controllers.laws import Selection, VisionLaw


class LegDirectionController(VisionLaw):
    """Leg-direction law: error ``u x u*``, interaction ``-[u*]_x M`` (seeds 001/003).

    The options of :class:`~controllers.laws.VisionLaw` (``gain``, ``adaptive_gain``,
    ``interaction``, ``threshold``, ``damping``, ``leg_rate_feedforward``; documented
    there), and:

    Args:
        compiled: Evaluate the core (:mod:`controllers.law_kernel`) compiled to C (False:
            the CasADi virtual machine evaluates the same expression, slower).
    """

    name = "leg-direction"
    features = frozenset({"lengths", "directions"})
    unit = "legs"

    def __init__(self, gain: float = 1.0, adaptive_gain: Sequence[float] | None = None,
                 interaction: str = "current", threshold: float = 1e-6,
                 damping: float = 0.0, compiled: bool = True,
                 leg_rate_feedforward: bool = False) -> None:
        super().__init__(gain, adaptive_gain, interaction, threshold, damping,
                         leg_rate_feedforward)
        self.compiled = bool(compiled)
        self._u_star = np.zeros((6, 3))
        self._goal_visible = np.ones(6, dtype=bool)

    def _reset_features(self, context: ControllerContext) -> None:
        us, vis = goal_directions(self.name, context.goal)
        self._u_star = np.where(vis[:, None], us, 0.0)
        self._install_goal(self._u_star, us, vis,
                           lambda: direction_kernel(self.interaction, self.compiled))

    def _install_goal(self, desired: np.ndarray, us: np.ndarray, vis: np.ndarray,
                      make: Callable[[], LawKernel]) -> None:
        """Set the goal's visibility and the compiled core's goal inputs.

        Args:
            desired: The core's desired feature (zeros where unknown).
            us: (6, 3) desired leg directions (``+z`` where unknown: the fill of hidden ones).
            vis: (6,) which desired directions are known.
            make: Builds the core when no kept one is reused.
        """
        self._goal_visible = vis
        self._fill = us
        self._goal_all_visible = bool(vis.all())
        kernel = self._reuse_kernel(make)
        kernel.set("desired", desired)
        if "desired_directions" in kernel.inputs:  # the legs' goal state (DESIRED / MEAN)
            kernel.set("desired_directions", us)
        kernel.set("base_points", self._A)
        kernel.set("weights", vis)
        self.kernel = kernel
        self._k_features = kernel.inputs["features"].reshape(6, 3)

    def desired_features(self) -> np.ndarray:
        """(6, 3) the desired leg directions (zeros where unknown)."""
        return np.asarray(self._u_star, dtype=float)

    def measured_features(self, obs: Observation) -> tuple[np.ndarray, np.ndarray]:
        """(6, 3) measured leg directions and (6,) which are usable."""
        vis = np.asarray(obs.direction_visible, dtype=bool) & self._goal_visible
        return np.asarray(obs.directions, dtype=float), vis

    def _batch_features(self, obs: ObservationBatch) -> tuple[np.ndarray | None,
                                                               np.ndarray | None]:
        if obs.directions is None:
            return None, None
        n = len(obs)
        vis = np.all(np.asarray(obs.direction_visible, dtype=bool).reshape(n, 6), axis=1)
        return np.asarray(obs.directions, dtype=float).reshape(n, 18), vis

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

    def _load_kernel(self, obs: Observation, q: np.ndarray) -> bool:
        vis = obs.direction_visible
        if not (self._goal_all_visible and (vis.all() if type(vis) is np.ndarray
                                            else np.all(np.asarray(vis, dtype=bool)))):
            return False
        self._k_features[...] = obs.directions
        self._common_inputs(q)
        return True

    def _select(self, obs: Observation, q: np.ndarray) -> Selection:
        u_obs = np.asarray(obs.directions, dtype=float)
        vis = np.asarray(obs.direction_visible, dtype=bool) & self._goal_visible
        est = self.estimate
        est.predict_hidden(~vis, self._A, self._dt)
        est.directions[vis] = u_obs[vis]
        est.observed[:] = vis
        known = np.isfinite(est.directions[:, 0])
        # J_inv of a leg never seen: its desired direction (exact at the goal).
        est.in_use[:] = np.where(known[:, None], est.directions,
                                 np.where(self._goal_visible[:, None], self._u_star, np.nan))
        return Selection(np.where(vis[:, None], u_obs, self._fill), vis, vis,
                         est.in_use.copy(), self._hidden_notes(vis, known))

    def _hidden_notes(self, vis: np.ndarray, known: np.ndarray) -> list[str]:
        """The notes of a step with hidden legs."""
        notes = [self._usage_note(vis, 6)]
        predicted = np.flatnonzero(~vis & known)
        if len(predicted):
            notes.append("predicted directions of hidden legs "
                         + ", ".join(str(int(i)) for i in predicted))
        approx = np.flatnonzero(~known & self._goal_visible)
        if len(approx):
            notes.append("desired direction used for never-seen legs "
                         + ", ".join(str(int(i)) for i in approx))
        return notes
