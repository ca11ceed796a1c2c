"""The one step of :class:`~controllers.laws.VisionLaw` over a batch of trials
(:class:`VisionLawBatch`; a batch of one is the per-trial ``step``): one instance of the
law per context (their estimates rows of one batch estimate, their compiled cores'
inputs rows of a :class:`~controllers.law_rows.LawRows`: one per compiled core, so two
when the trials' cameras make them read lines and normals), goals the compiled core
takes as they are written into the rows at once (read by the instance when it next
needs them), and every row through the C of :mod:`controllers.law_rows`; Python steps
only its RARE rows (a hidden feature, an unusable observation) and its REJECTED ones (a
degenerate core, a limit QP whose optimum touches a bound) by the trial's instance.
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
from controllers.law_rows import ACCEPTED, RARE, REJECTED, LawRows, core_key
from controllers.leg_rate import LegRateFeedForward
from controllers.model_directions import ModelDirections
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
    #: The rows of each compiled core of the batch (:meth:`reset_batch`; None in a copy
    #: until its next batch call, :meth:`_rows_again`).
    _groups: list[LawRows] | None = None

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
            CompilationError: No C compiler (the step is C).
        """
        super().reset_batch(contexts)
        trials = self.trial_instances
        #: The estimates of every trial (the instances' estimates are its rows).
        self.batch_estimate = LegDirectionEstimate.fresh(len(trials))
        for k, inst in enumerate(trials):
            inst.estimate = self.batch_estimate.row(k)
        #: Goals given to ``retarget_batch`` not yet read by the trial's instance.
        self._pending: dict[int, tuple[GoalBatch, int]] = {}
        seen = {t.observed_feature for t in trials}
        self.batch_feature = seen.pop() if len(seen) == 1 else None
        self.batch_reset_leg_rate(trials)
        self._build_rows()

    def __getstate__(self) -> dict[str, object]:
        """A copy's (or a pickle's) state, without the batch's rows (their C context
        holds this batch's addresses): the copy builds its own at its next batch call
        (:meth:`_rows_again`)."""
        state = self.__dict__.copy()
        if "_groups" in state:
            state["_groups"] = None
            state.pop("_core_rows", None)
        return state

    def _batch_rows(self) -> list[LawRows]:
        """The batch's rows of each compiled core (a copy's built again first)."""
        return self._groups if self._groups is not None else self._rows_again()

    def _rows_again(self) -> list[LawRows]:
        """After a copy: the instances' estimates and leg-rate offsets made rows of one
        batch array again (a copy of a view is an array of its own), the rows built from
        the instances, and the desired features of the goals they have not read yet
        written into them as :meth:`retarget_batch` did."""
        trials = self.trial_instances
        estimate = LegDirectionEstimate.fresh(len(trials))
        for k, inst in enumerate(trials):
            row = estimate.row(k)
            for name in ("directions", "observed", "in_use", "twist", "lengths"):
                getattr(row, name)[...] = getattr(inst.estimate, name)
            inst.estimate = row
        self.batch_estimate = estimate
        if self.batch_kappa is not None:
            self.batch_offset = np.array([inst.rate_offset for inst in trials])
            for k, inst in enumerate(trials):
                inst.rate_offset = self.batch_offset[k]
        groups = self._build_rows()
        for trial, (goals, j) in self._pending.items():
            desired, quick = self._batch_desired(goals)
            assert desired is not None
            groups[self._group_of[trial]].write_desired(np.array([trial]), desired[j:j + 1],
                                                        quick[j:j + 1])
        return groups

    def _build_rows(self) -> list[LawRows]:
        """The rows of each compiled core of the batch, from the trials' instances."""
        trials = self.trial_instances
        feedforward = (None if self.batch_kappa is None
                       else (self.batch_kappa, self.batch_offset))
        keys = [core_key(t) for t in trials]
        first = {key: k for k, key in reversed(list(enumerate(keys)))}
        #: The rows of each compiled core of the batch (one, unless its trials read
        #: different features, e.g. perspective and unified cameras), and each trial's.
        self._groups = [LawRows(trials, self.batch_estimate, feedforward, trials[k])
                        for k in sorted(first.values())]
        order = {rows.key: g for g, rows in enumerate(self._groups)}
        self._group_of = np.array([order[key] for key in keys], dtype=np.int64)
        self._core_rows = self._groups[0]
        return self._groups

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
        groups = self._batch_rows()
        trials = np.asarray(trials, dtype=int)
        desired, quick = self._batch_desired(goals)
        if desired is not None and len(self.trial_instances) > 1:  # (one reads it now)
            own = self._group_of[trials]
            for g, rows in enumerate(groups):
                mine = own == g
                quick = np.where(mine, rows.write_desired(trials, desired, quick & mine), quick)
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
        assert self._groups is not None
        self._groups[self._group_of[trial]].take(trial, inst)

    def step_batch(self, observations: ObservationBatch) -> CommandBatch:
        """The commands of every row (module docstring); a batch of one gets the
        per-trial :class:`Command` (the error, rank, condition number and twist).

        Raises:
            CompilationError: The compiled core failed (the batch fails as a whole).
            ValueError: The observations' arrays are not of the batch's shapes.
        """
        obs = observations
        n = len(obs)
        self.crashes = {}
        if (unreset := self.checked_batch(obs)) is not None or not n:
            return unreset or CommandBatch.zeros(0)
        groups = self._batch_rows()
        if len(groups) == 1:
            return self._step_rows(self._core_rows, obs, self.crashes)
        out = CommandBatch.zeros(n)  # trials of several cores: each core's rows apart
        own = self._group_of[np.asarray(obs.trials, dtype=np.int64)]
        for g, rows in enumerate(groups):
            idx = np.flatnonzero(own == g)
            if len(idx):
                crashes: dict[int, BaseException] = {}
                part = self._step_rows(rows, obs.rows(idx), crashes)
                out.velocities[idx] = part.velocities
                out.error_norm[idx] = part.error_norm
                kept = part.commands or [None] * len(idx)
                for k, j in enumerate(idx.tolist()):
                    out.reasons[j] = part.reasons[k]
                    if kept[k] is not None:
                        out.commands = out.commands or [None] * n
                        out.commands[j] = kept[k]
                    if k in crashes:
                        self.crashes[j] = crashes[k]
        return out

    def _step_rows(self, rows: LawRows, obs: ObservationBatch,
                   crashes: dict[int, BaseException]) -> CommandBatch:
        """The commands of the rows of one compiled core's trials (a failure of row ``j``
        kept in ``crashes[j]``)."""
        n = len(obs)
        code, b = rows.step(obs)
        if n == 1:  # the per-trial step: its Command
            cmd = (self._command_of(rows, b.Y[0], b.vel[0].copy()) if code[0] == ACCEPTED
                   else self._python_row(rows, 0, obs, int(code[0]), b.Y[0], crashes))
            return CommandBatch.of_row(cmd, self.actuation)
        out = CommandBatch(b.vel.copy(), b.norm.copy(), [None] * n)
        if code.any():  # rows not accepted (ACCEPTED is 0)
            self._model_ahead(np.flatnonzero(code == RARE), obs)
            for j in np.flatnonzero(code != ACCEPTED).tolist():
                out.put(j, self._python_row(rows, j, obs, int(code[j]), b.Y[j], crashes))
        return out

    def _model_ahead(self, rare: np.ndarray, obs: ObservationBatch) -> None:
        """Give the trials of the ``rare`` rows (two or more, stepped by their instances)
        one :class:`~controllers.model_directions.ModelDirections` of this period: the
        nominal directions of legs never seen, solved for all of them at once if one asks."""
        if len(rare) < 2 or obs.lengths is None:
            return
        laws = [self.trial_instances[int(obs.trials[j])] for j in rare.tolist()]
        ahead = ModelDirections(laws, obs.lengths[rare])
        for k, law in enumerate(laws):
            law.model_ahead = (ahead, k)

    def _python_row(self, rows: LawRows, j: int, obs: ObservationBatch, code: int,
                    y: np.ndarray, crashes: dict[int, BaseException]) -> Command:
        """Row ``j``'s command by :meth:`_rare_row`, or the refusal of its failure (the
        exception kept in ``crashes``)."""
        try:
            return self._rare_row(rows, int(obs.trials[j]), obs.item(j), code, y,
                                  len(obs) == 1)
        except Exception as exc:  # that trial's failure
            crashes[j] = exc
            return Command.refuse(f"{type(exc).__name__}: {exc}")

    @staticmethod
    def _command_of(rows: LawRows, y: np.ndarray, velocities: np.ndarray) -> Command:
        """The per-trial command of an accepted row of a batch of one: the full core's
        outputs ``y`` and the command's leg velocities [m/s]."""
        error, tau, norm, rank, condition = rows.command_outputs
        e = y[error].copy()
        return Command(velocities, twist=y[tau].copy(), error=e, error_norm=float(y[norm]),
                       rank=int(y[rank]), condition=float(y[condition]),
                       features_used=e.shape[0], notes=[], active_constraints=[])

    def _rare_row(self, rows: LawRows, trial: int, observation: Observation, code: int,
                  y: np.ndarray, full: bool) -> Command:
        """A row the C left to Python, by its trial's instance, which first reads a goal
        given to :meth:`retarget_batch` that it has not read yet: a REJECTED row from the
        full core's result, a RARE one by the instance's own step of the cases it
        covers (hidden features, refusals)."""
        result = rows.full_result(trial, y, full) if code == REJECTED else None
        pending = self._pending.pop(trial, None) if self._pending else None
        if pending is not None:
            self._retarget_instance(trial, pending[0].item(pending[1]))
        inst = self.trial_instances[trial]
        if result is None:
            return inst.rare_step(observation)  # type: ignore[no-any-return]
        return inst.rejected_step(observation, result)  # type: ignore[no-any-return]
