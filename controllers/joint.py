"""Joint-space baseline: leg lengths servoed to the nominal inverse kinematics of the goal.

``q_dot = -lambda (q - q*)`` with ``q* = goal.lengths`` (the desired pose through the
nominal inverse kinematics). It needs no camera; its accuracy is that of the
nominal model and of the joint offsets.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from controllers.base import (
    Command,
    CommandBatch,
    Controller,
    ControllerContext,
    Goal,
    GoalBatch,
    ObservationBatch,
    usable_observation_problem,
)
from controllers.exceptions import ContextError
from controllers.law_tools import goal_lengths
from controllers.laws import Gain


class JointSpaceController(Controller):
    """Joint-space law ``q_dot = -lambda (q - q*)`` with ``q*`` the goal's nominal lengths.

    Args:
        gain: Constant gain ``lambda`` [1/s].
        adaptive_gain: ``(lambda0, lambda_inf, lambda0')`` (overrides ``gain``),
            with ``x = |q - q*|_inf`` [m].
    """

    name = "joint-space"
    features = frozenset({"lengths"})

    def __init__(self, gain: float = 1.0, adaptive_gain: Sequence[float] | None = None) -> None:
        self.gain = Gain.from_options(self.name, gain, adaptive_gain)
        self._q_star: np.ndarray | None = None

    def reset_trial(self, context: ControllerContext) -> None:
        """Read ``goal.lengths``.

        Raises:
            ContextError: The goal has no valid lengths.
        """
        self.retarget_trial(context.goal)

    def retarget_trial(self, goal: Goal) -> None:
        """A new goal (the law keeps no other state: the same as :meth:`reset_trial`).

        Raises:
            ContextError: The goal has no valid lengths.
        """
        self._q_star = goal_lengths(self.name, goal)

    def reset_batch(self, contexts: Sequence[ControllerContext]) -> None:
        """Read ``goal.lengths`` of every trial (as :meth:`reset_trial`).

        Raises:
            ContextError: A goal without valid lengths.
        """
        stars = []
        for ctx in contexts:
            self.reset_trial(ctx)
            assert self._q_star is not None
            stars.append(self._q_star)
        self._b_q_star = np.array(stars).reshape(len(stars), 6)
        self.trial_instances = [self]

    def retarget_batch(self, trials: np.ndarray, goals: GoalBatch) -> None:
        """New goals of some trials (row ``j`` for trial ``trials[j]``), as
        :meth:`retarget_trial`.

        Raises:
            ContextError: A goal without 6 finite lengths, or no reset yet.
        """
        if not self.trial_instances:
            raise ContextError(self.name, "context", "retarget(goal) before reset(context)")
        trials = np.asarray(trials, dtype=int)
        qs = None if goals.lengths is None else np.asarray(goals.lengths, dtype=float)
        if qs is None or qs.shape != (len(trials), 6) or not np.all(np.isfinite(qs)):
            for j, k in enumerate(trials.tolist()):  # one by one: the goal at fault raises
                self.retarget_trial(goals.item(j))
                self._b_q_star[k] = self._q_star
            return
        self._b_q_star[trials] = qs

    def step_batch(self, observations: ObservationBatch) -> CommandBatch:
        """``q_dot = -lambda (q - q*)`` for every row (a row with non-finite lengths or
        time is refused, as one trial alone)."""
        obs = observations
        n = len(obs)
        q = np.asarray(obs.lengths, dtype=float)
        e = q - self._b_q_star[np.asarray(obs.trials, dtype=int)]
        out = CommandBatch.zeros(n)
        good = np.isfinite(q).all(axis=1) & np.isfinite(np.asarray(obs.t, dtype=float))
        x = np.abs(e).max(axis=1)
        for k in range(n):
            if not good[k]:
                out.put(k, self._refusal(obs, k))
                continue
            out.velocities[k] = -self.gain(float(x[k])) * e[k]
            out.error_norm[k] = math.sqrt(float(e[k] @ e[k]))
        out.details = lambda k: None if out.reasons[k] is not None else Command(
            out.velocities[k].copy(), error=e[k].copy(), error_norm=float(out.error_norm[k]),
            rank=6, condition=1.0, features_used=6)
        return out

    def _refusal(self, obs: ObservationBatch, k: int) -> Command:
        problem = usable_observation_problem(obs.item(k), self.features)
        return Command.refuse(problem or "invalid observation")
