"""The vision laws over many trials at once (``reset_batch`` / ``step_batch``).

Each trial keeps its own instance of the law (built with the batch's options and reset
with the trial's context), so that every case keeps exactly the per-trial behaviour;
what the law carries between periods is one batch
:class:`~controllers.estimators.LegDirectionEstimate` whose rows are the instances'
estimates (views: a trial stepped by its instance and the same trial stepped in the
batch write the same memory). What changes is the common case (every feature visible
and finite, now and in the goal, a full-rank interaction matrix): there, the rows
of all such trials go through the law's compiled core in one C loop
(:meth:`hexapod.compiled.CompiledFunction.batch`, the same code as the per-trial
:meth:`~controllers.laws.VisionLaw.tasks`), and the estimate is updated by the
same methods as the per-trial step. Any other row (a hidden or non-finite feature, a
refusal, a QP whose unconstrained optimum leaves a bound, a law without a compiled
core) is stepped by its own instance. The results are those of the per-trial loop to
the last bit (tested).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from controllers.base import CommandBatch, ControllerContext, ObservationBatch
from controllers.batch import step_rows_per_trial
from controllers.estimators import LegDirectionEstimate
from controllers.goal_batch import GoalBatch
from controllers.options import RemembersOptions
from controllers.solvers.base import Solver


class BatchedLaw(RemembersOptions):
    """Mixin of :class:`~controllers.laws.VisionLaw`: ``reset_batch`` and ``step_batch``."""

    kernel: Any
    estimate: LegDirectionEstimate
    solver: Solver

    @property
    def batch_core(self) -> bool:  # provided by VisionLaw
        """Whether this trial's common case may be stepped by the batch's lean core."""
        return False

    def reset(self, context: ControllerContext) -> None:  # provided by VisionLaw
        raise NotImplementedError

    def _batch_features(self, obs: ObservationBatch) -> tuple[np.ndarray | None,
                                                               np.ndarray | None]:
        """The rows' measured features for the compiled core, (n, F), and the mask (n,)
        of rows whose features are all visible. (None, None): no compiled core."""
        return None, None

    def _batch_desired(self, goals: GoalBatch) -> tuple[np.ndarray | None, np.ndarray]:
        """The compiled core's desired-feature input of each goal, (m, D), and the mask
        (m,) of goals that the law would read into exactly that with its compiled core
        (every feature visible and finite, the CURRENT interaction). (None, mask): no
        such shortcut; every goal then goes through its instance's ``retarget``."""
        return None, np.zeros(len(goals), dtype=bool)

    def _batch_reset_extra(self) -> None:
        """Per-trial constants of subclasses (the solver's are gathered by
        :meth:`~controllers.solvers.base.Solver.batch_reset`)."""

    # ------------------------------------------------------------------ reset
    def reset_batch(self, contexts: Sequence[ControllerContext]) -> None:
        """One instance per context (built with this controller's options), reset with it.

        Raises:
            ContextError: A context the law cannot use (as :meth:`reset`).
        """
        self._trials: list[Any] = self.clones_reset(contexts)
        trials = self._trials
        n = len(trials)
        #: The estimates of every trial (the instances' estimates are its rows).
        self.batch_estimate = LegDirectionEstimate.fresh(n)
        for k, inst in enumerate(trials):
            inst.estimate = self.batch_estimate.row(k)
        kernels = [t.kernel if t.batch_core else None for t in trials]
        self._has_kernel = np.array([k is not None for k in kernels], dtype=bool)
        #: Rows of ``_X`` holding a compiled core's constants (a retarget may then write
        #: the desired features alone).
        self._x_ready = self._has_kernel.copy()
        #: Goals given to ``retarget_batch`` not yet read by the trial's instance.
        self._pending: dict[int, tuple[GoalBatch, int]] = {}
        self._fn = None
        for k, kern in enumerate(kernels):
            self._take_kernel(k, kern)
        self.solver.batch_reset([t.solver for t in trials])
        self._batch_reset_extra()

    def _take_kernel(self, trial: int, kern: Any) -> None:
        """Copy a trial's compiled-core inputs into its row of the batch's inputs."""
        if kern is None:
            return
        if self._fn is None:
            self._fn = kern.lean_function
            self._slices = kern.slices
            self._outs = kern.outputs
            self._X = np.zeros((len(self._trials), kern.function.n_in))
        self._X[trial] = kern.input_vector
        self._x_ready[trial] = True

    # ------------------------------------------------------------------ retarget
    def retarget_batch(self, trials: np.ndarray, goals: GoalBatch) -> None:
        """New goals for some trials (row ``j`` of ``goals`` for trial ``trials[j]``),
        keeping their state, as each instance's ``retarget``.

        A goal that the compiled core takes as it is (:meth:`_batch_desired`) is written
        into the batch's inputs at once and read by the instance only when that trial
        next needs it (a row the core cannot finish); any other goal is read by the
        instance now.

        Raises:
            ContextError: A goal the law cannot use (as ``retarget``).
        """
        trials = np.asarray(trials, dtype=int)
        desired, quick = self._batch_desired(goals)
        if desired is not None and self._fn is not None:
            quick = quick & self._x_ready[trials]
            rows = np.flatnonzero(quick)
            if len(rows):
                tr = trials[rows]
                self._X[tr, self._slices["desired"]] = desired[rows]
                self._has_kernel[tr] = True
                for j, k in zip(rows.tolist(), tr.tolist(), strict=True):
                    self._pending[k] = (goals, j)
        else:
            quick = np.zeros(len(trials), dtype=bool)
        for j in np.flatnonzero(~quick).tolist():
            k = int(trials[j])
            self._pending.pop(k, None)
            self._retarget_instance(k, goals.item(j))

    def _retarget_instance(self, trial: int, goal: Any) -> None:
        inst = self._trials[trial]
        inst.retarget(goal)
        kern = inst.kernel if inst.batch_core else None
        self._has_kernel[trial] = kern is not None
        self._take_kernel(trial, kern)

    def _apply_pending(self, trials: np.ndarray) -> None:
        """Let the instances of ``trials`` read the goals they were given."""
        for k in np.asarray(trials, dtype=int).tolist():
            pending = self._pending.pop(k, None)
            if pending is not None:
                goals, j = pending
                self._retarget_instance(k, goals.item(j))

    # ------------------------------------------------------------------ step
    def step_batch(self, observations: ObservationBatch) -> CommandBatch:
        """One period of the rows' trials (see the module docstring)."""
        obs = observations
        n = len(obs)
        trials = np.asarray(obs.trials, dtype=int)
        out = CommandBatch.zeros(n)
        slow = np.ones(n, dtype=bool)
        feats, visible = self._batch_features(obs) if self._fn is not None else (None, None)
        if feats is not None and visible is not None:
            q = np.asarray(obs.lengths, dtype=float)
            with np.errstate(invalid="ignore"):
                fast = (self._has_kernel[trials] & visible & np.isfinite(feats).all(axis=1)
                        & np.isfinite(q).all(axis=1) & (q.min(axis=1) > 0)
                        & np.isfinite(np.asarray(obs.t, dtype=float)))
            rows = np.flatnonzero(fast)
            if len(rows):
                done = self._fast(rows, trials[rows], feats[rows], q[rows], out.velocities,
                                  out.error_norm)
                slow[rows[done]] = False
        slow_rows = np.flatnonzero(slow)
        if self._pending and len(slow_rows):
            self._apply_pending(trials[slow_rows])
        step_rows_per_trial(self._trials, obs, trials, slow_rows, out)
        return out

    def _fast(self, rows: np.ndarray, trials: np.ndarray, feats: np.ndarray, q: np.ndarray,
              velocities: np.ndarray, norms: np.ndarray) -> np.ndarray:
        """The compiled core over the rows; fills the accepted ones, returns their mask."""
        assert self._fn is not None
        X = self._X[trials]
        X[:, self._slices["features"]] = feats
        X[:, self._slices["lengths"]] = q
        Y = self._fn.batch(X)
        o = self._outs
        with np.errstate(invalid="ignore"):
            ok = (np.isfinite(Y[:, o["error_norm"].start]) & np.isfinite(Y[:, o["n_sum"].start])
                  & (Y[:, o["rank"].start] >= 6) & (Y[:, o["qdot_check"].start] == 0.0))
        ok &= self.solver.batch_accept(trials, q, Y[:, o["qdot"]])
        if ok.all():  # the common case: no row copies
            Ya, tr, qa, ra = Y, trials, q, rows
        else:
            acc = np.flatnonzero(ok)
            Ya, tr, qa, ra = Y[acc], trials[acc], q[acc], rows[acc]
        est = self.batch_estimate
        est.measured_all(Ya[:, o["directions"]].reshape(-1, 6, 3), tr)
        est.commanded(Ya[:, o["tau"]], qa, tr)
        velocities[ra] = Ya[:, o["qdot"]]
        norms[ra] = Ya[:, o["error_norm"].start]
        return ok
