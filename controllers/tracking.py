"""Tracking a reference trajectory with any controller: a time-varying goal and a
feed-forward term.

A trajectory task gives the controller a reference pose trajectory
(``ControllerContext.reference``, a :class:`hexapod.trajectory.PoseTrajectory` in the
base frame) instead of a fixed goal. :class:`TrackingController` wraps any controller
built for a fixed goal:

- the goal of period ``k`` is the reference at ``t_k = k dt`` seen through the NOMINAL
  model, anchored at the taught goal: the features taught at the end pose (the
  context's goal, measured there as for a point-to-point task) plus the change the
  nominal model predicts between the end pose and the reference pose (edge normals,
  image lines and leg directions as the estimated camera would see the nominal robot,
  renormalised); the nominal inverse kinematics of the reference pose; the pose itself.
  Nothing is taught along the path: under a calibration error the features in between
  carry the model's error of the feature CHANGE, and the end of the path is the taught
  goal, reached as accurately as by a point-to-point task;
- the controller is retargeted to that goal every period: its ``retarget(goal)`` when it
  has one (the built-in vision laws keep their state: the dead-reckoned directions of
  hidden legs, the last twist, the warm starts; the goal moved, the robot did not), else
  ``reset`` with the new goal (the law's state starts afresh);
- a velocity command (not a force command) gets the feed-forward
  ``(q*(t_{k+1}) - q*(t_k)) / dt``, the nominal leg lengths' change over the coming
  period. For a vision law it is the feature-rate
  term ``L^+ ds*/dt`` written in joint space: with the nominal model exact, a robot on
  the reference stays on it (tested in the kinematic world).

Every time-varying goal is computed once, at ``reset``, on the control grid.

A controller that tracks ``context.reference`` itself (``tracks_reference = True``: the
computed-torque laws, which need the reference's derivatives and sample it at their own
instants) is passed through: reset with the trial's context (the TAUGHT goal and the
reference), never retargeted, no feed-forward added.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from controllers.base import (
    Actuation,
    Command,
    Controller,
    ControllerContext,
    Goal,
    Observation,
)
from controllers.batch import actuation_of
from controllers.exceptions import ContextError
from controllers.goal_batch import GOAL_FIELDS

log = logging.getLogger(__name__)


def reference_goals(context: ControllerContext, times: np.ndarray) -> dict[str, np.ndarray]:
    """The goals of a reference at ``times`` [s] from the nominal model.

    Args:
        context: With ``reference`` (anything with ``at(times)`` returning a
            :class:`hexapod.trajectory.ReferenceSample`), the nominal ``geometry`` and the
            estimated ``camera``.
        times: (m,) times [s].

    Returns:
        ``rotation`` (m, 3, 3), ``translation`` (m, 3), ``lengths`` (m, 6) [m], and when the
        context has a camera ``normals`` (m, 6, 2, 3), ``lines`` (m, 6, 2, 3) or None,
        ``directions`` (m, 6, 3), ``edge_visible`` (m, 6, 2).
    """
    from hexapod.kinematics import inverse_kinematics

    ref = context.reference
    sample = ref.at(times)
    out: dict[str, Any] = {
        "rotation": sample.rotation, "translation": sample.translation,
        "lengths": inverse_kinematics(context.geometry, sample.rotation, sample.translation)}
    camera = context.camera
    if camera is not None:
        from vision.legs import directions_from_edges, observe_legs

        seen = observe_legs(camera, context.geometry, sample.rotation, sample.translation)
        visible = np.asarray(seen.edge_visible, dtype=bool)
        normals = np.where(visible[..., None], seen.normals, np.nan)
        with np.errstate(invalid="ignore"):
            out["lines"] = (camera.normal_to_line(normals)
                            if getattr(camera, "kind", None) == "perspective" else None)
            both = np.asarray(visible.all(axis=-1))
            out["directions"] = np.where(both[..., None], directions_from_edges(normals),
                                         np.nan)
        out["normals"] = normals
        out["edge_visible"] = visible
    return out


def anchor_goals(goals: dict[str, Any], taught: Goal) -> None:
    """Anchor the model's features at the taught goal (in place): ``s* = s_taught +
    s_model(t) - s_model(end)``, unit vectors renormalised; the model's last sample is
    the end pose. A feature the goal did not see stays the model's."""
    for key in ("normals", "lines", "directions"):
        model = goals.get(key)
        value = getattr(taught, key, None)
        if model is None or value is None:
            continue
        s_taught = np.asarray(value, dtype=float)
        if s_taught.shape != model.shape[1:]:
            continue
        with np.errstate(invalid="ignore"):
            shifted = s_taught + (model - model[-1])
            shifted /= np.linalg.norm(shifted, axis=-1, keepdims=True)
        known = np.all(np.isfinite(s_taught), axis=-1)
        goals[key] = np.where(known[..., None], shifted, model)


def retarget(controller: Any, context: ControllerContext) -> None:
    """Give ``controller`` the goal of ``context``: its ``retarget(goal)`` when it has
    one (keeping its state), else ``reset(context)``."""
    method = getattr(controller, "retarget", None)
    if callable(method):
        method(context.goal)
    else:
        controller.reset(context)


def announce_offset(controller: Any, q_rate: np.ndarray) -> None:
    """Tell ``controller`` the feed-forward [m/s] about to be added to its coming command
    (its ``velocity_offset(q_dot)`` when it has one: the predictive controllers' drive
    model needs it; the other laws do not)."""
    method = getattr(controller, "velocity_offset", None)
    if callable(method):
        method(q_rate)


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

    @property
    def steps(self) -> int:
        """Periods of the grid."""
        return len(self.q_rate)

    def goal(self, k: int) -> Goal:
        """The goal of period ``k``."""
        return Goal(**{name: None if arr is None else arr[k]
                       for name, arr in self.goals.items()})

    def period(self, t: float) -> int:
        """The period of time ``t`` [s] (finite), clipped to the grid."""
        return min(max(round(t / self.dt), 0), self.steps - 1)


def tracking_plan(context: ControllerContext, name: str) -> TrackingPlan:
    """The goals of ``context.reference`` on the control grid (see the module docstring).

    Raises:
        ContextError: The period is not positive, the reference cannot be sampled, or
            its nominal inverse kinematics is not finite.
    """
    reference = context.reference
    dt = float(context.dt)
    if not (math.isfinite(dt) and dt > 0):
        raise ContextError(name, "dt", f"must be positive and finite, got {dt}")
    steps = math.ceil(float(reference.duration) / dt) + 2
    times = dt * np.arange(steps)
    goals = reference_goals(context, times)
    anchor_goals(goals, context.goal)
    q = goals["lengths"]
    if not np.all(np.isfinite(q)):
        raise ContextError(name, "reference", "the nominal inverse kinematics of the "
                           "reference is not finite")
    q_rate = np.zeros((steps, 6))
    q_rate[:-1] = np.diff(q, axis=0) / dt
    return TrackingPlan(dt, {key: goals.get(key) for key in GOAL_FIELDS}, q_rate)


def tracks_itself(controller: Any) -> bool:
    """Whether a controller samples ``context.reference`` itself (then passed through)."""
    return bool(getattr(controller, "tracks_reference", False))


class TrackingController(Controller):
    """Any controller made to track ``context.reference`` (see the module docstring).

    Without a reference in the context it is the wrapped controller, unchanged. Many
    trials at once: :class:`controllers.tracking_batch.TrackingBatch`.

    Args:
        inner: The controller (reset and stepped through this wrapper only).
        feed_forward: Add the nominal leg-length rate of the reference to velocity
            commands.
    """

    def __init__(self, inner: Any, feed_forward: bool = True) -> None:
        self.inner = inner
        self.name = str(getattr(inner, "name", "controller"))
        self.features = frozenset(getattr(inner, "features", frozenset({"lengths"})))
        self.actuation = actuation_of(inner)
        self.feed_forward = bool(feed_forward)
        self._contexts: list[ControllerContext] = []
        self._plan: TrackingPlan | None = None
        self._k = -1

    def reset(self, context: ControllerContext) -> None:
        """Compute the goals of the control grid up to the reference's end and reset the
        wrapped controller with the first.

        Raises:
            ContextError: The reference cannot be sampled, or its goals are not finite.
        """
        reference = getattr(context, "reference", None)
        self._contexts = []
        self._plan = None
        self._k = -1
        if reference is None or tracks_itself(self.inner):
            self.inner.reset(context)
            return
        plan = tracking_plan(context, self.name)
        self._contexts = [replace(context, goal=plan.goal(k)) for k in range(plan.steps)]
        self._plan = plan
        self._k = 0
        self.inner.reset(self._contexts[0])

    def step(self, observation: Observation) -> Command:
        """The wrapped controller's command for the goal of this period, plus the
        feed-forward."""
        plan = self._plan
        if plan is None:
            return self.inner.step(observation)  # type: ignore[no-any-return]
        t = float(observation.t)
        if not math.isfinite(t):
            return Command.refuse(f"time is {t} (not finite)", actuation=self.actuation)
        k = plan.period(t)
        if k != self._k:
            retarget(self.inner, self._contexts[k])
            self._k = k
        if self.feed_forward and self.actuation is Actuation.VELOCITY:
            announce_offset(self.inner, plan.q_rate[k])
        cmd: Command = self.inner.step(observation)
        if self.feed_forward and cmd.reason is None and cmd.actuation is Actuation.VELOCITY:
            cmd.velocities = np.asarray(cmd.velocities, dtype=float) + plan.q_rate[k]
        return cmd
