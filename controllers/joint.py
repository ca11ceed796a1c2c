"""Joint-space baseline: leg lengths servoed to the nominal inverse kinematics of the goal.

``q_dot = -lambda (q - q*)`` with ``q* = goal.lengths`` (the desired pose through the
nominal inverse kinematics). It needs no camera; its accuracy is that of the
nominal model and of the joint offsets.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from controllers.base import Controller
from controllers.data import (
    Command,
    ControllerContext,
    Goal,
    Observation,
    observation_problem,
)
from controllers.law_tools import Gain, goal_lengths


class JointSpaceController(Controller):
    """Joint-space law ``q_dot = -lambda (q - q*)`` with ``q*`` the goal's nominal lengths.

    Args:
        gain: Constant gain ``lambda`` [1/s].
        adaptive_gain: ``(lambda0, lambda_inf, lambda0')`` (overrides ``gain``),
            with ``x = |q - q*|_inf`` in metres.
    """

    name = "joint-space"
    features = frozenset({"lengths"})

    def __init__(self, gain: float = 1.0, adaptive_gain: Sequence[float] | None = None) -> None:
        self.gain = Gain.from_options(self.name, gain, adaptive_gain)
        self._q_star: np.ndarray | None = None
        self._stroke: tuple[float, float] | None = None

    def reset_trial(self, context: ControllerContext) -> None:
        """Read ``goal.lengths``.

        Raises:
            ContextError: The goal has no valid lengths.
        """
        self._stroke = context.geometry.stroke
        self.retarget_trial(context.goal)

    def retarget_trial(self, goal: Goal) -> None:
        """A new goal (the law keeps no other state: the same as :meth:`reset_trial`).

        Raises:
            ContextError: The goal has no valid lengths.
        """
        self._q_star = goal_lengths(self.name, goal, self._stroke)

    def step_trial(self, observation: Observation) -> Command:
        """``q_dot = -lambda (q - q*)`` (the gain a function of ``|q - q*|_inf``, one
        trial's number: every row of a batch is stepped so)."""
        if self._q_star is None:
            return Command.refuse(f"{self.name}: reset(context) was not called")
        problem = observation_problem(observation, self.features, self._stroke)
        if problem is not None:
            return Command.refuse(problem)
        e = np.asarray(observation.lengths, dtype=float) - self._q_star
        lam = self.gain(float(np.abs(e).max()))
        return Command(-lam * e, error=e, error_norm=math.sqrt(float(e @ e)), rank=6,
                       condition=1.0, features_used=6)
