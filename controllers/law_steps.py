"""The batch side of :class:`~controllers.laws.VisionLaw`: one instance per trial, the
compiled core over the rows of the common case.

:class:`VisionLawBatch` resets one instance of the law per context (their estimates
rows of one batch estimate, their compiled cores' inputs rows of one
:class:`~controllers.law_rows.KernelRows`), retargets them (a goal the compiled core
takes as it is written into the batch's inputs at once, read by the instance when it
next needs it) and steps the common rows in one C loop, leaving the others to their
instances (:meth:`VisionLawBatch.step_row`). :class:`~controllers.laws.VisionLaw`
(:mod:`controllers.laws`) derives from it and sets the law, its solver and its core.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from controllers.base import (
    Command,
    CommandBatch,
    Controller,
    ControllerContext,
    Goal,
    GoalBatch,
    Observation,
    ObservationBatch,
)
from controllers.estimators import LegDirectionEstimate
from controllers.exceptions import ContextError
from controllers.law_rows import KernelRows
from controllers.leg_rate import LegRateFeedForward
from controllers.solvers.base import Solver
from controllers.tasks.leg_direction import LegDirections
from controllers.tasks.leg_edge import EdgeFeature

__all__ = ["ObservedFeature", "VisionLawBatch"]

#: What a vision law reads from an observation (its field, visibility mask and shape).
ObservedFeature = EdgeFeature | LegDirections


class VisionLawBatch(LegRateFeedForward, Controller):
    """The batched stepping of the image-based laws (the base of
    :class:`~controllers.laws.VisionLaw`, which sets :attr:`solver`)."""

    solver: Solver
    #: What every trial of the batch reads from an observation (None: not the same
    #: feature, the trials step alone), set by :meth:`reset_batch`.
    batch_feature: ObservedFeature | None = None

    # ----------------------------------------------------------------- the batch
    def _batch_features(self, obs: ObservationBatch) -> tuple[np.ndarray | None,
                                                               np.ndarray | None]:
        """The rows' measured features for the compiled core, (n, F), and the mask (n,)
        of rows whose features are all visible. (None, None): none to step as arrays."""
        seen = self.batch_feature
        arr = None if seen is None else getattr(obs, seen.field)
        if seen is None or arr is None:
            return None, None
        n = len(obs)
        vis = np.all(np.asarray(getattr(obs, seen.visibility), dtype=bool).reshape(n, seen.units),
                     axis=1)
        return np.asarray(arr, dtype=float).reshape(n, 3 * seen.units), vis

    def _batch_desired(self, goals: GoalBatch) -> tuple[np.ndarray | None, np.ndarray]:
        """The compiled core's desired-feature input of each goal, (m, D), and the mask
        (m,) of goals that the law would read into exactly that with its compiled core
        (every feature visible and finite, the CURRENT interaction). (None, mask): no
        such shortcut; every goal then goes through its instance's ``retarget_trial``."""
        return None, np.zeros(len(goals), dtype=bool)

    def reset_batch(self, contexts: Sequence[ControllerContext]) -> None:
        """One instance per context (this one first, the others built with its options),
        each reset with its context; their estimates become rows of one batch estimate
        and their compiled cores' inputs rows of one array.

        Raises:
            ContextError: A context the law cannot use (as :meth:`reset_trial`).
        """
        super().reset_batch(contexts)
        trials = self.trial_instances
        #: The estimates of every trial (the instances' estimates are its rows).
        self.batch_estimate = LegDirectionEstimate.fresh(len(trials))
        for k, inst in enumerate(trials):
            inst.estimate = self.batch_estimate.row(k)
        self._core_rows = KernelRows(len(trials))
        for k, inst in enumerate(trials):
            self._core_rows.take(k, inst.kernel if inst.batch_core else None)
        #: Goals given to ``retarget_batch`` not yet read by the trial's instance.
        self._pending: dict[int, tuple[GoalBatch, int]] = {}
        self.solver.batch_reset([t.solver for t in trials])
        seen = {t.observed_feature for t in trials}
        self.batch_feature = seen.pop() if len(seen) == 1 else None
        self.batch_reset_leg_rate(trials)

    def retarget_batch(self, trials: np.ndarray, goals: GoalBatch) -> None:
        """New goals for some trials (row ``j`` of ``goals`` for trial ``trials[j]``),
        keeping their state, as each instance's :meth:`retarget_trial`.

        In a batch of many trials, a goal that the compiled core takes as it is
        (:meth:`_batch_desired`) is written into the batch's inputs at once and read by
        the instance only when that trial next needs it (a row the core cannot finish);
        any other goal, and the goal of a batch of one, is read by the instance now.

        Raises:
            ContextError: A goal the law cannot use, or no reset yet.
        """
        if not self.trial_instances:
            raise ContextError(self.name, "context", "retarget(goal) before reset(context)")
        trials = np.asarray(trials, dtype=int)
        desired, quick = self._batch_desired(goals)
        if desired is not None and len(self.trial_instances) > 1:  # (one reads it now)
            quick = self._core_rows.write_desired(trials, desired, quick)
            for j in np.flatnonzero(quick).tolist():
                self._pending[int(trials[j])] = (goals, j)
        else:
            quick = np.zeros(len(trials), dtype=bool)
        for j in np.flatnonzero(~quick).tolist():
            k = int(trials[j])
            self._pending.pop(k, None)
            self._retarget_instance(k, goals.item(j))

    def _retarget_instance(self, trial: int, goal: Goal) -> None:
        inst = self.trial_instances[trial]
        inst.retarget_trial(goal)
        self._core_rows.take(trial, inst.kernel if inst.batch_core else None)

    def step_arrays(self, observations: ObservationBatch, out: CommandBatch) -> np.ndarray:
        """The common case of the rows through the compiled core as arrays; returns the
        other rows (see the module docstring)."""
        obs = observations
        n = len(obs)
        trials = np.asarray(obs.trials, dtype=int)
        slow = np.ones(n, dtype=bool)
        rows_core = self._core_rows
        feats, visible = (self._batch_features(obs) if rows_core.function is not None
                          else (None, None))
        if feats is not None and visible is not None:
            q = np.asarray(obs.lengths, dtype=float)
            with np.errstate(invalid="ignore"):
                fast = (rows_core.ready[trials] & visible & np.isfinite(feats).all(axis=1)
                        & np.isfinite(q).all(axis=1) & (q.min(axis=1) > 0)
                        & np.isfinite(np.asarray(obs.t, dtype=float)))
            rows = np.flatnonzero(fast)
            if len(rows):
                done = rows_core.step(rows, trials[rows], feats[rows], q[rows],
                                      self.solver, self.batch_estimate, out)
                slow[rows[done]] = False
                self.feed_rows(rows[done], trials[rows[done]], obs, out)
        return np.flatnonzero(slow)

    def step_row(self, trial: int, observation: Observation) -> Command:
        """One row by its trial's instance, which first reads a goal given to
        :meth:`retarget_batch` that it has not read yet."""
        pending = self._pending.pop(trial, None) if self._pending else None
        if pending is not None:
            self._retarget_instance(trial, pending[0].item(pending[1]))
        return self.trial_instances[trial].step_trial(observation)  # type: ignore[no-any-return]
