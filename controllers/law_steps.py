"""The batch side of :class:`~controllers.laws.VisionLaw` (:class:`VisionLawBatch`): one
instance of the law per context (their estimates rows of one batch estimate, their
compiled cores' inputs rows of one :class:`KernelRows`), goals the compiled core takes
as they are written into the rows at once (read by the instance when it next needs
them), and the common rows stepped in one C loop through the lean core, the others by
their instances (:meth:`VisionLawBatch.step_row`).
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
from controllers.law_kernel import LawKernel
from controllers.leg_rate import LegRateFeedForward
from controllers.solvers.base import Solver
from controllers.tasks.leg_direction import LegDirections
from controllers.tasks.leg_edge import EdgeFeature
from hexapod.compiled import CompiledFunction, Layout

__all__ = ["KernelRows", "ObservedFeature", "VisionLawBatch"]

#: What a vision law reads from an observation (its field, visibility mask and shape).
ObservedFeature = EdgeFeature | LegDirections


class KernelRows:
    """The inputs of the compiled cores of a batch's trials, one row per trial, and the
    lean core that evaluates any rows of them in one C loop.

    Args:
        n: Trials of the batch.
    """

    def __init__(self, n: int) -> None:
        #: The first trial's compiled core, whose lean core steps the rows (None until a
        #: trial has a compiled core).
        self.kernel: LawKernel | None = None
        #: The lean core (None until it first steps rows: built then, not at the reset, so a
        #: batch whose rows all step alone never builds it).
        self.function: CompiledFunction | None = None
        #: Where each named input lies in a row, and each named output in a result (the
        #: lean core's layouts; empty until a trial has a compiled core).
        self.slices: Layout = Layout((), "law core input")
        self.outputs: Layout = Layout((), "law core output")
        self.n = n
        self.X = np.zeros((0, 0))
        #: (n,) the trials whose row holds its core's inputs (the lean core may step them).
        self.ready = np.zeros(n, dtype=bool)
        #: (n,) the rows holding a core's constants (a retarget may write its desired
        #: features alone).
        self.filled = np.zeros(n, dtype=bool)

    def take(self, trial: int, kernel: LawKernel | None) -> None:
        """Copy a trial's core inputs into its row (None: the trial has no lean core)."""
        self.ready[trial] = kernel is not None
        if kernel is None:
            return
        if self.kernel is None:
            self.kernel = kernel
            self.slices = kernel.slices
            self.outputs = kernel.outputs
            self.X = np.zeros((self.n, kernel.input_vector.size))
        self.X[trial] = kernel.input_vector
        self.filled[trial] = True

    def write_desired(self, trials: np.ndarray, desired: np.ndarray, quick: np.ndarray
                      ) -> np.ndarray:
        """Write the desired features ``desired`` (m, D) of the goals ``quick`` (m,) into
        the rows of ``trials`` (m,) that hold their constants; returns the mask of the
        goals written."""
        if self.kernel is None:
            return np.zeros(len(trials), dtype=bool)
        quick = quick & self.filled[trials]
        rows = np.flatnonzero(quick)
        if len(rows):
            self.X[trials[rows], self.slices["desired"]] = desired[rows]
            self.ready[trials[rows]] = True
        return quick  # type: ignore[no-any-return]

    def step(self, rows: np.ndarray, trials: np.ndarray, features: np.ndarray,
             lengths: np.ndarray, solver: Solver, estimate: LegDirectionEstimate,
             out: CommandBatch) -> np.ndarray:
        """The lean core over the batch rows ``rows`` of ``trials`` with their measured
        ``features`` and ``lengths`` [m]; returns the mask (m,) of the rows whose result
        is the command (finite, rank 6, ``solver.batch_accept``): those update the batch's
        ``estimate`` as a commanded step and fill ``out``, the others are left to their
        trial's own step (which says why)."""
        X = self.X[trials]
        X[:, self.slices["features"]] = features
        X[:, self.slices["lengths"]] = lengths
        if self.function is None:
            assert self.kernel is not None, "take() sets the kernel before a row is ready"
            self.function = self.kernel.lean_function
        Y = self.function.batch(X)
        o = self.outputs
        with np.errstate(invalid="ignore"):
            ok = (np.isfinite(Y[:, o["error_norm"].start]) & np.isfinite(Y[:, o["n_sum"].start])
                  & (Y[:, o["rank"].start] >= 6) & (Y[:, o["qdot_check"].start] == 0.0))
        ok &= solver.batch_accept(trials, lengths, Y[:, o["qdot"]])
        if ok.all():  # the common case: no row copies
            Ya, tr, qa, ra = Y, trials, lengths, rows
        else:
            acc = np.flatnonzero(ok)
            Ya, tr, qa, ra = Y[acc], trials[acc], lengths[acc], rows[acc]
        estimate.measured_all(Ya[:, o["directions"]].reshape(-1, 6, 3), tr)
        estimate.commanded(Ya[:, o["tau"]], qa, tr)
        out.velocities[ra] = Ya[:, o["qdot"]]
        out.error_norm[ra] = Ya[:, o["error_norm"].start]
        return ok  # type: ignore[no-any-return]


class VisionLawBatch(LegRateFeedForward, Controller):
    """The batched stepping of the image-based laws (the base of
    :class:`~controllers.laws.VisionLaw`, which sets :attr:`solver`)."""

    solver: Solver
    #: What every trial of the batch reads from an observation (None: not the same
    #: feature, the trials step alone), set by :meth:`reset_batch`.
    batch_feature: ObservedFeature | None = None

    # ----------------------------------------------------------------- the batch
    def _batch_desired(self, goals: GoalBatch) -> tuple[np.ndarray | None, np.ndarray]:
        """The compiled core's desired input of each goal (m, D), and the mask (m,) of the
        goals the law would read into exactly that (None, mask: every goal goes through
        its instance's ``retarget_trial``)."""
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
        self._core_rows = KernelRows(len(trials))
        for k, inst in enumerate(trials):
            inst.estimate = self.batch_estimate.row(k)
            self._core_rows.take(k, inst.kernel if inst.batch_core else None)
        #: Goals given to ``retarget_batch`` not yet read by the trial's instance.
        self._pending: dict[int, tuple[GoalBatch, int]] = {}
        self.solver.batch_reset([t.solver for t in trials])
        seen = {t.observed_feature for t in trials}
        self.batch_feature = seen.pop() if len(seen) == 1 else None
        self.batch_reset_leg_rate(trials)

    def retarget_batch(self, trials: np.ndarray, goals: GoalBatch) -> None:
        """New goals for some trials (row ``j`` of ``goals`` for trial ``trials[j]``),
        keeping their state, as each instance's :meth:`retarget_trial`; in a batch of
        many trials, a goal the compiled core takes as it is (:meth:`_batch_desired`) is
        read by the instance only when that trial next needs it (module docstring).

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
        seen = self.batch_feature  # the rows' measured features, where all are visible
        arr = None if seen is None else getattr(obs, seen.field)
        if rows_core.kernel is not None and seen is not None and arr is not None:
            feats = np.asarray(arr, dtype=float).reshape(n, 3 * seen.units)
            visible = np.all(np.asarray(getattr(obs, seen.visibility), dtype=bool)
                             .reshape(n, seen.units), axis=1)
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
