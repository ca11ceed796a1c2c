"""Tracking a reference trajectory with many trials at once (``reset_batch`` /
``step_batch``): the batch form of :class:`controllers.tracking.TrackingController`.

Each trial's goals on the control grid are computed once, at reset, as by the per-trial
wrapper (:func:`controllers.tracking.tracking_plan`), and stacked over the trials. Each
period, the rows whose period changed get their new goal in one call of the wrapped
batch's ``retarget_batch(trials, goals)`` (the vision laws write the desired features
into their compiled core's inputs as arrays; :mod:`controllers.law_batch`), or, for a
batch that is a loop over per-trial controllers (:class:`controllers.batch.PerTrialLoop`),
each trial's controller is retargeted as the per-trial wrapper does. Then one
``step_batch`` of the wrapped batch, and the feed-forward of each row's period added to
the velocity commands. The rows are those of the per-trial wrapper (tested).

Which wrapped batches it takes: :func:`tracks_in_batch`.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from controllers.base import (
    Actuation,
    Command,
    CommandBatch,
    ControllerContext,
    ObservationBatch,
)
from controllers.batch import PerTrialLoop, actuation_of
from controllers.goal_batch import GOAL_FIELDS, GoalBatch
from controllers.tracking import TrackingPlan, retarget, tracking_plan

log = logging.getLogger(__name__)


def tracks_in_batch(inner: Any) -> bool:
    """Whether :class:`TrackingBatch` can wrap a batch object: it has
    ``retarget_batch(trials, goals)`` (the built-in vision laws, ``model-based``,
    ``joint-space``) or is a :class:`~controllers.batch.PerTrialLoop`."""
    return isinstance(inner, PerTrialLoop) or callable(getattr(inner, "retarget_batch", None))


def observation_rows(obs: ObservationBatch, rows: np.ndarray) -> ObservationBatch:
    """The rows ``rows`` of a batch of observations."""
    def take(value: Any) -> Any:
        return None if value is None else np.asarray(value)[rows]

    return ObservationBatch(
        trials=np.asarray(obs.trials)[rows], t=np.asarray(obs.t)[rows],
        lengths=np.asarray(obs.lengths)[rows], normals=take(obs.normals),
        lines=take(obs.lines), directions=take(obs.directions),
        edge_visible=np.asarray(obs.edge_visible)[rows],
        direction_visible=np.asarray(obs.direction_visible)[rows],
        image_t=take(obs.image_t), q_dot=take(obs.q_dot))


class TrackingBatch:
    """A batch of trials tracking their references (see the module docstring).

    A trial whose context has no reference is the wrapped batch's row, unchanged.

    Args:
        inner: The wrapped batch object (:func:`tracks_in_batch`), reset and stepped
            through this wrapper only; its controllers must not sample the reference
            themselves (``tracks_reference``: then step the wrapped batch directly).
        feed_forward: Add the nominal leg-length rate of the reference to velocity
            commands.
        name: The controller's name (in error messages).
    """

    def __init__(self, inner: Any, feed_forward: bool = True, name: str = "controller"
                 ) -> None:
        if not tracks_in_batch(inner):
            raise TypeError(f"{name}: a batch without retarget_batch cannot track in a batch "
                            "(use a PerTrialLoop of TrackingController)")
        self.inner = inner
        self.name = str(name)
        self.actuation: Actuation = actuation_of(inner)
        self.feed_forward = bool(feed_forward)
        self._plans: list[TrackingPlan | None] = []
        self._contexts: list[ControllerContext] = []
        self._has = np.zeros(0, dtype=bool)
        self._told: dict[int, Any] = {}

    # ------------------------------------------------------------------ reset
    def reset_batch(self, contexts: Sequence[ControllerContext]) -> None:
        """Every trial's goals on the control grid; the wrapped batch reset with the
        first goal of each.

        Raises:
            ContextError: A trial's reference cannot be sampled, or its goals are not
                finite (as the per-trial wrapper).
        """
        self._contexts = list(contexts)
        plans = [None if getattr(ctx, "reference", None) is None
                 else tracking_plan(ctx, self.name) for ctx in self._contexts]
        self._plans = plans
        n = len(plans)
        self._has = np.array([p is not None for p in plans], dtype=bool)
        self._k = np.where(self._has, 0, -1)
        self._dt = np.array([1.0 if p is None else p.dt for p in plans])
        self._last = np.array([0 if p is None else p.steps - 1 for p in plans], dtype=int)
        size = int(self._last.max()) + 1 if n else 0
        self._q_rate = np.zeros((n, size, 6))
        self._goals: dict[str, np.ndarray | None] = {}
        #: Every trial with a plan has the same goal fields (else goals go one by one).
        self._uniform = True
        for name in GOAL_FIELDS:
            arrays = [p.goals[name] for p in plans if p is not None]
            present = [a is not None for a in arrays]
            if not all(present):
                self._uniform &= not any(present)
                self._goals[name] = None
                continue
            first = np.asarray(arrays[0])
            stacked = np.zeros((n, size, *first.shape[1:]), dtype=first.dtype)
            for i, p in enumerate(plans):
                if p is not None:
                    self._fill(stacked[i], np.asarray(p.goals[name]))
            self._goals[name] = stacked
        for i, p in enumerate(plans):
            if p is not None:
                self._fill(self._q_rate[i], p.q_rate)
        self.inner.reset_batch([ctx if p is None else replace(ctx, goal=p.goal(0))
                                for ctx, p in zip(self._contexts, plans, strict=True)])
        #: The per-trial controllers told the feed-forward before each step (those with a
        #: ``velocity_offset``; none for a batch object).
        per_trial = getattr(self.inner, "controllers", None) or []
        self._told = {trial: c for trial, c in enumerate(per_trial)
                      if callable(getattr(c, "velocity_offset", None))}

    @staticmethod
    def _fill(out: np.ndarray, values: np.ndarray) -> None:
        """``values`` (steps, ...) into ``out`` (size, ...), the last one repeated."""
        m = len(values)
        out[:m] = values
        out[m:] = values[-1]

    # ------------------------------------------------------------------ step
    def step_batch(self, observations: ObservationBatch) -> CommandBatch:
        """The wrapped batch's commands for the goals of this period, plus the
        feed-forward (a tracking row whose time is not finite is refused)."""
        obs = observations
        trials = np.asarray(obs.trials, dtype=int)
        has = self._has[trials]
        if not has.any():
            return self.inner.step_batch(obs)  # type: ignore[no-any-return]
        t = np.asarray(obs.t, dtype=float)
        finite = np.isfinite(t)
        rows = np.flatnonzero(has & finite)
        tr = trials[rows]
        k = np.zeros(len(trials), dtype=int)
        k[rows] = np.clip(np.rint(t[rows] / self._dt[tr]), 0, self._last[tr]).astype(int)
        moved = k[rows] != self._k[tr]
        if moved.any():
            self._retarget(tr[moved], k[rows][moved])
            self._k[tr[moved]] = k[rows][moved]
        if self._told and self.feed_forward and self.actuation is Actuation.VELOCITY:
            for row, trial in zip(rows.tolist(), tr.tolist(), strict=True):
                if trial in self._told:
                    self._told[trial].velocity_offset(self._q_rate[trial, k[row]])
        bad = np.flatnonzero(has & ~finite)
        if len(bad):
            out = CommandBatch.zeros(len(trials), self.actuation)
            for j in bad.tolist():
                out.put(j, Command.refuse(f"time is {float(t[j])} (not finite)",
                                          actuation=self.actuation))
            good = np.flatnonzero(~(has & ~finite))
            if len(good):
                sub = self.inner.step_batch(observation_rows(obs, good))
                for j, row in enumerate(good.tolist()):
                    out.velocities[row] = sub.velocities[j]
                    if out.forces is not None and sub.forces is not None:
                        out.forces[row] = sub.forces[j]
                    out.error_norm[row] = sub.error_norm[j]
                    out.reasons[row] = sub.reasons[j]
        else:
            out = self.inner.step_batch(obs)
        if self.feed_forward and out.actuation is Actuation.VELOCITY and len(rows):
            ok = np.array([out.reasons[j] is None for j in rows.tolist()], dtype=bool)
            add = rows[ok]
            out.velocities[add] = out.velocities[add] + self._q_rate[trials[add], k[add]]
        return out

    def _retarget(self, trials: np.ndarray, periods: np.ndarray) -> None:
        """Give ``trials`` the goals of ``periods``."""
        inner = self.inner
        batch = getattr(inner, "retarget_batch", None)
        if callable(batch) and self._uniform:
            batch(trials, GoalBatch(**{name: None if arr is None else arr[trials, periods]
                                       for name, arr in self._goals.items()}))
            return
        for tr, k in zip(trials.tolist(), periods.tolist(), strict=True):
            plan = self._plans[tr]
            assert plan is not None
            if callable(batch):
                batch(np.array([tr]), GoalBatch.of(plan.goal(k)))
            else:  # a PerTrialLoop: the per-trial wrapper's retarget
                retarget(inner.controllers[tr], replace(self._contexts[tr], goal=plan.goal(k)))
