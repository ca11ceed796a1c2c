"""Tracking a reference trajectory with any controller: a time-varying goal and a
feed-forward term.

A trajectory task gives the controller a reference pose trajectory
(``ControllerContext.reference``, a :class:`hexapod.trajectory.PoseTrajectory` in the
base frame) instead of a fixed goal. :class:`TrackingController` wraps any controller
built for a fixed goal; every goal is computed once, at ``reset_batch``, on the control
grid:

- the goal of period ``k`` is the reference at ``t_k = k dt`` seen through the NOMINAL
  model, anchored at the taught goal (:func:`anchor_goals`), its nominal inverse
  kinematics and the pose itself. Nothing is taught along the path: under a calibration
  error the features in between carry the model's error of the feature CHANGE, and the
  end of the path is reached as accurately as by a point-to-point task;
- the controller is retargeted every period (``retarget_batch``: the built-in vision
  laws keep their state; by default a reset with the new goal);
- a velocity command gets the feed-forward ``(q*(t_{k+1}) - q*(t_k)) / dt``, the
  nominal leg lengths' change over the coming period (for a vision law, the term
  ``L^+ ds*/dt`` written in joint space: with the nominal model exact, a robot on the
  reference stays on it).

A controller that tracks ``context.reference`` itself (``tracks_reference = True``: the
computed-torque laws) is passed through: reset with the trial's context, never
retargeted, no feed-forward added.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from controllers.base import Controller
from controllers.batch import actuation_of
from controllers.control_grid import chunks, grid_times, model_world
from controllers.data import (
    FEATURE_FIELDS,
    GOAL_FIELDS,
    Command,
    CommandBatch,
    ControllerContext,
    Goal,
    GoalBatch,
    ObservationBatch,
)
from controllers.exceptions import ContextError
from hexapod.actuation import Actuation
from hexapod.se3 import norms


def model_goals(context: ControllerContext, rotation: np.ndarray, translation: np.ndarray,
                fields: Collection[str] | None = None) -> dict[str, np.ndarray]:
    """The goals of the nominal model at poses (a reference's samples).

    Args:
        context: With ``geometry`` and ``camera``.
        rotation: (m, 3, 3) platform orientations (base frame).
        translation: (m, 3) platform positions (base frame) [m].
        fields: The goal fields wanted of ``lengths``, ``normals``, ``lines``,
            ``directions`` and ``edge_visible`` (None: all).

    Returns:
        ``rotation`` (m, 3, 3), ``translation`` (m, 3), ``lengths`` (m, 6) [m], and when the
        context has a camera ``normals`` (m, 6, 2, 3), ``lines`` (m, 6, 2, 3) or None,
        ``directions`` (m, 6, 3), ``edge_visible`` (m, 6, 2).
    """
    from hexapod.kinematics import inverse_kinematics

    def wanted(name: str) -> bool:
        return fields is None or name in fields

    out: dict[str, Any] = {"rotation": rotation, "translation": translation}
    if wanted("lengths"):
        out["lengths"] = inverse_kinematics(context.geometry, rotation, translation)
    camera = context.camera
    if camera is not None and any(wanted(f) for f in ("normals", "lines", "directions",
                                                      "edge_visible")):
        from vision.legs import directions_from_edges, observe_edges

        seen, visible = observe_edges(camera, context.geometry, rotation, translation)
        normals = np.array(seen) if visible.all() else np.where(visible[..., None], seen,
                                                                   np.nan)
        with np.errstate(invalid="ignore"):
            if wanted("lines"):
                out["lines"] = (camera.normal_to_line(normals)
                                if getattr(camera, "kind", None) == "perspective" else None)
            if wanted("directions"):
                both = np.asarray(visible.all(axis=-1))
                u = directions_from_edges(normals)
                out["directions"] = u if both.all() else np.where(both[..., None], u, np.nan)
        if wanted("normals"):
            out["normals"] = normals
        if wanted("edge_visible"):
            out["edge_visible"] = visible
    return out


def anchored(model: np.ndarray, end: np.ndarray, taught: np.ndarray) -> np.ndarray:
    """The model's unit vectors ``model`` (..., 3) anchored at the taught ones: ``s* =
    unit(s_taught + s_model - s_model(end))`` (``end`` and ``taught`` broadcast to
    ``model``; the model's own where a taught vector is not finite)."""
    with np.errstate(invalid="ignore"):
        shifted = model - end
        shifted += taught  # (a sum commutes: s_taught + (model - end))
        shifted /= norms(shifted, keepdims=True)  # (np.linalg.norm's bits)
    known = np.all(np.isfinite(taught), axis=-1)
    return shifted if known.all() else np.where(known[..., None], shifted, model)


def anchor_goals(goals: dict[str, Any], taught: Goal) -> None:
    """Anchor the model's features at the taught goal (in place, :func:`anchored`); the
    model's last sample is the end pose. A feature the goal did not see stays the
    model's."""
    for key, _, _ in FEATURE_FIELDS:
        model = goals.get(key)
        value = getattr(taught, key, None)
        if model is None or value is None:
            continue
        s_taught = np.asarray(value, dtype=float)
        if s_taught.shape == model.shape[1:]:
            goals[key] = anchored(model, model[-1], s_taught)


@dataclass
class TrackingPlan:
    """The goals of one trial on the control grid, up to the reference's end (computed
    once, at reset).

    Attributes:
        dt: Control period [s].
        goals: The goal fields (:data:`controllers.base.GOAL_FIELDS`), (steps, ...)
            arrays, or None when the context gives no such feature.
        q_rate: (steps, 6) the feed-forward ``(q*(t_{k+1}) - q*(t_k)) / dt`` [m/s] (zero
            at the last period).
    """

    dt: float
    goals: dict[str, np.ndarray | None]
    q_rate: np.ndarray

    def goal(self, k: int) -> Goal:
        """The goal of period ``k``."""
        return Goal(**{name: None if arr is None else arr[k]
                       for name, arr in self.goals.items()})


def tracking_plan(context: ControllerContext, name: str) -> TrackingPlan:
    """The goals of ``context.reference`` on the control grid (see the module docstring).

    Raises:
        ContextError: The period is not positive, the reference cannot be sampled, or
            its nominal inverse kinematics is not finite.
    """
    return tracking_plans([context], name)[0]


def tracking_plans(contexts: Sequence[ControllerContext], name: str) -> list[TrackingPlan]:
    """:func:`tracking_plan` of every context, the nominal model's goals of a chunk of
    contexts that share a model world (camera and robot,
    :func:`controllers.control_grid.chunks`) in one call of :func:`model_goals` over all
    their samples (each sample's goals are its own numbers).

    Raises:
        ContextError: As :func:`tracking_plan`, for the first context at fault.
    """
    samples = []
    for context in contexts:
        dt = float(context.dt)
        if not (math.isfinite(dt) and dt > 0):
            raise ContextError(name, "dt", f"must be positive and finite, got {dt}")
        reference = context.reference
        samples.append(reference.at(grid_times(reference.duration, dt)))
    goals: list[dict[str, Any]] = [{} for _ in contexts]
    for members in chunks([model_world(context) for context in contexts]):
        both = model_goals(contexts[members[0]],
                           np.concatenate([samples[k].rotation for k in members]),
                           np.concatenate([samples[k].translation for k in members]))
        start = 0
        for k in members:
            end = start + len(samples[k].translation)
            goals[k] = {key: None if value is None else value[start:end]
                        for key, value in both.items()}
            start = end
    plans = []
    for context, found in zip(contexts, goals, strict=True):
        anchor_goals(found, context.goal)
        q = found["lengths"]
        if not np.all(np.isfinite(q)):
            raise ContextError(name, "reference", "the nominal inverse kinematics of the "
                               "reference is not finite")
        dt = float(context.dt)
        q_rate = np.zeros((len(q), 6))
        q_rate[:-1] = np.diff(q, axis=0) / dt
        plans.append(TrackingPlan(dt, {key: found.get(key) for key in GOAL_FIELDS}, q_rate))
    return plans


class TrackingController(Controller):
    """Any controller made to track ``context.reference``, over a batch of trials (module
    docstring): each period one ``retarget_batch`` of the rows whose period changed, one
    ``step_batch``, the feed-forward added (a trial without a reference passes through).

    Args:
        inner: The controller (reset and stepped through this wrapper only).
        feed_forward: Add the nominal leg-length rate of the reference to velocity
            commands.
    """

    def __init__(self, inner: Controller, feed_forward: bool = True) -> None:
        self.inner = inner
        self.name = str(getattr(inner, "name", "controller"))
        self.features = frozenset(getattr(inner, "features", frozenset({"lengths"})))
        self.actuation = actuation_of(inner)
        self.feed_forward = bool(feed_forward)
        self._plans: list[TrackingPlan | None] = []
        self._has = np.zeros(0, dtype=bool)
        self._told: dict[int, Any] = {}

    # ------------------------------------------------------------------ reset
    def reset_batch(self, contexts: Sequence[ControllerContext]) -> None:
        """Every trial's goals on the control grid; the wrapped controller reset with the
        first goal of each.

        Raises:
            ContextError: A trial's reference cannot be sampled, or its goals are not
                finite.
        """
        contexts = list(contexts)
        itself = bool(getattr(self.inner, "tracks_reference", False))
        tracking = [k for k, ctx in enumerate(contexts)
                    if not itself and getattr(ctx, "reference", None) is not None]
        plans: list[TrackingPlan | None] = [None] * len(contexts)
        for k, plan in zip(tracking, tracking_plans([contexts[k] for k in tracking],
                                                    self.name), strict=True):
            plans[k] = plan
        self._plans = plans
        n = len(plans)
        self._has = np.array([p is not None for p in plans], dtype=bool)
        self._k = np.where(self._has, 0, -1)
        self._dt = np.array([1.0 if p is None else p.dt for p in plans])
        self._last = np.array([0 if p is None else len(p.q_rate) - 1 for p in plans], dtype=int)
        size = int(self._last.max()) + 1 if n else 0
        self._q_rate = np.zeros((n, size, 6))
        #: The goals of every trial and period, row ``trial * size + period`` (flat views
        #: of (n, size, ...) arrays: one ``take`` of a period's rows).
        self._goals: dict[str, np.ndarray | None] = {}
        self._size = size
        #: Every trial with a plan has the same goal fields (else goals go one by one).
        self._uniform = True
        for name in GOAL_FIELDS:
            arrays = [p.goals[name] for p in plans if p is not None]
            present = [a is not None for a in arrays]
            if not arrays or not all(present):  # (no trial tracks: nothing to stack)
                self._uniform &= not any(present)
                self._goals[name] = None
                continue
            first = np.asarray(arrays[0])
            stacked = np.zeros((n, size, *first.shape[1:]), dtype=first.dtype)
            for i, p in enumerate(plans):
                if p is not None:
                    self._fill(stacked[i], np.asarray(p.goals[name]))
            self._goals[name] = stacked.reshape(n * size, *stacked.shape[2:])
        for i, p in enumerate(plans):
            if p is not None:
                self._fill(self._q_rate[i], p.q_rate)
        self.inner.reset_batch([ctx if p is None else replace(ctx, goal=p.goal(0))
                                for ctx, p in zip(contexts, plans, strict=True)])
        self.trial_instances = [self] * n
        #: The trials' instances told the feed-forward before each step (those with a
        #: ``velocity_offset``: the predictive controllers').
        self._told = {trial: c for trial, c in enumerate(self.inner.trial_instances)
                      if callable(getattr(c, "velocity_offset", None))}

    @staticmethod
    def _fill(out: np.ndarray, values: np.ndarray) -> None:
        """``values`` (steps, ...) into ``out`` (size, ...), the last one repeated."""
        m = len(values)
        out[:m] = values
        out[m:] = values[-1]

    # ------------------------------------------------------------------ step
    def step_batch(self, observations: ObservationBatch) -> CommandBatch:
        """The wrapped controller's commands for the goals of this period, plus the
        feed-forward (a tracking row whose time is not finite is refused)."""
        self.crashes = {}
        if (unreset := self.checked_batch(observations)) is not None:
            return unreset
        obs = observations
        trials = np.asarray(obs.trials, dtype=int)
        has = self._has[trials]
        if not has.any():
            out = self.inner.step_batch(obs)
            self.crashes = self.inner.crashes  # the rows are the inner batch's
            return out
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
            self.crashes = {}
            if len(good):
                sub = self.inner.step_batch(obs.rows(good))
                for j, row in enumerate(good.tolist()):
                    out.put(row, sub.command(j))
                self.crashes = {int(good[j]): exc for j, exc in self.inner.crashes.items()}
        else:
            out = self.inner.step_batch(obs)
            self.crashes = self.inner.crashes
        if self.feed_forward and out.actuation is Actuation.VELOCITY and len(rows):
            ok = np.array([out.reasons[j] is None for j in rows.tolist()], dtype=bool)
            add = rows[ok]
            out.velocities[add] = out.velocities[add] + self._q_rate[trials[add], k[add]]
        return out

    def _retarget(self, trials: np.ndarray, periods: np.ndarray) -> None:
        """Give ``trials`` the goals of ``periods``."""
        if self._uniform:
            rows = trials * self._size + periods
            self.inner.retarget_batch(trials, GoalBatch(
                **{name: None if arr is None else arr.take(rows, axis=0)
                   for name, arr in self._goals.items()}))
            return
        for tr, k in zip(trials.tolist(), periods.tolist(), strict=True):
            plan = self._plans[tr]
            assert plan is not None
            self.inner.retarget_batch(np.array([tr]), GoalBatch.of(plan.goal(k)))
