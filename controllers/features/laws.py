"""The first-order controllers of a :class:`~controllers.tasks.leg_feature.LegFeature`:
pseudo-inverse (``-pinv``), limit QP (``-qp``) and predictive (``-mpc``).

A feature law is the built-in leg-direction law (its reading of observations, hidden
legs, batched rows) with the feature's compiled core
(:func:`~controllers.law_kernel.feature_law_kernel`) and the feature of the goal's legs
as its desired value. The predictive controller's local problem reads the tasks through
``L^T L``, ``L^T e`` and ``J_inv`` only: the built-in compiled problem serves every
feature.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from typing import Any

import numpy as np

from controllers.base import ControllerContext, GoalBatch
from controllers.exceptions import ContextError, OptionError
from controllers.law_tools import goal_directions
from controllers.leg_direction import LegDirectionController
from controllers.mpc.controller import MPCLaw
from controllers.solvers.limit_qp import LimitQPSolver


class FeatureLaw(LegDirectionController):
    """``tau = -lambda L^+ e`` on a leg feature (``q_dot = J_inv tau``); the class's
    ``feature`` is set by :func:`~controllers.features.controllers_for`.

    The options of :class:`~controllers.laws.VisionLaw` (the DESIRED interaction at the
    legs' goal state) but ``leg_rate_feedforward``.
    """

    def __init__(self, gain: float = 1.0, adaptive_gain: Sequence[float] | None = None,
                 interaction: str = "current", threshold: float = 1e-6,
                 damping: float = 0.0, compiled: bool = True) -> None:
        super().__init__(gain, adaptive_gain, interaction, threshold, damping, compiled)

    def _reset_features(self, context: ControllerContext) -> None:
        """The desired feature: the feature of the goal's legs (directions, lengths)."""
        us, vis = goal_directions(self.name, context.goal)
        if self._q_star is None:
            raise ContextError(self.name, "goal.lengths",
                               f"missing (the desired {self.feature.name} needs the goal's "
                               "leg lengths)")
        f_star = self.feature.desired(us, self._q_star, self.base_points)
        if not np.all(np.isfinite(f_star[vis])):
            bad = np.flatnonzero(~np.all(np.isfinite(f_star), axis=1) & vis)
            raise ContextError(self.name, "goal", f"the desired {self.feature.name} of legs "
                               f"{bad.tolist()} is not finite: {f_star[bad]}")
        self._f_star = np.where(vis[:, None], f_star, 0.0)
        self._u_star = np.where(vis[:, None], us, 0.0)
        self._install_goal(self._f_star, us, vis)

    def desired_features(self) -> np.ndarray:
        """(6, rows) the desired feature (zeros where unknown)."""
        return np.asarray(self._f_star, dtype=float)

    def _batch_desired(self, goals: GoalBatch) -> tuple[np.ndarray | None, np.ndarray]:
        """No shortcut: each new goal is read by its trial's instance."""
        return None, np.zeros(len(goals), dtype=bool)


class FeatureQPLaw(FeatureLaw):
    """The feature's law as the limit QP (stroke with a margin, leg speeds; OSQP).

    The options of :class:`FeatureLaw` and :class:`~controllers.solvers.limit_qp.LimitQPSolver`.
    """

    OPTION_DOCS = (LimitQPSolver,)

    def __init__(self, gain: float = 1.0, adaptive_gain: Sequence[float] | None = None,
                 interaction: str = "current", threshold: float = 1e-6, damping: float = 0.0,
                 regularization: float = 1e-12, stroke_margin: float | None = None,
                 max_speed: float | None = None, eps_abs: float = 1e-6, eps_rel: float = 1e-6,
                 max_iter: int = 4000, shortcut: bool | None = None,
                 compiled: bool = True) -> None:
        FeatureLaw.__init__(self, gain, adaptive_gain, interaction, threshold, damping,
                            compiled)
        self.solver = LimitQPSolver(self.name, self.threshold, regularization, stroke_margin,
                                    max_speed, eps_abs, eps_rel, max_iter, shortcut, damping)


class FeatureMPC(MPCLaw):
    """Predictive control of a leg feature with the local model (the options of
    :class:`~controllers.mpc.controller.MPCLaw`; ``model`` must be ``"local"``: the
    global model predicts the built-in features from a pose)."""

    @functools.wraps(MPCLaw.__init__)  # type: ignore[misc]  # (its declared options)
    def __init__(self, *args: Any, **options: Any) -> None:
        super().__init__(*args, **options)
        if self.model != "local":
            raise OptionError(self.name, "model", f"a feature's predictive controller has the "
                              f"local model only, got {self.model!r}")
