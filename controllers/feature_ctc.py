"""Computed torque in the space of the leg features: ``leg-edge-ctc`` (Özgür, Andreff and
Martinet, ICRA 2011) and ``leg-direction-ctc``.

The feature error (the leg-edge task ``e = n x n*``, or the leg-direction task
``e = u x u*``, :mod:`controllers.tasks`, camera frame) is given the second-order
dynamics ``e_ddot + 2 zeta omega_n e_dot + omega_n^2 e = 0`` through the NOMINAL inverse
dynamic model (:class:`~controllers.solvers.computed_torque.ComputedTorqueSolver`, least
squares over the rows seen). Models, never the world's truth:

- the task's state: the edge normals (or directions) the camera sees, the ESTIMATED base
  points ``A_i`` (context, camera frame) and the encoder lengths;
- the pose for the dynamic model and the task's frame: the nominal forward kinematics
  of the encoders; the twist ``K^-1 q_dot`` (nominal ``K``), brought to the camera frame
  through the ESTIMATED camera pose;
- the reference ``s*(t)``: the features the estimated camera would see of the NOMINAL
  robot along the reference pose trajectory (``context.reference``, or a quintic line
  from the first measured pose to ``goal.rotation``/``goal.translation``), anchored at the
  TAUGHT goal features as :mod:`controllers.tracking` does (``s* = s_taught +
  s_model(t) - s_model(end)``, renormalised): the path's end is the taught goal, reached
  whatever the calibration error; without a smooth goal, ``s*`` is the taught goal.

Only legs whose two edges (or whose direction) are seen take part; fewer than six
independent rows give a refusal with the reason.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from controllers.base import ControllerContext, Goal, Observation
from controllers.cartesian_ctc import directions_seen, pose_measurement
from controllers.exceptions import ContextError
from controllers.task_ctc import (
    Measured,
    TaskComputedTorque,
    camera_and_base_points,
    goal_pose_of,
)
from controllers.tasks import LegDirectionTask, LegEdgeTask, Task, TaskState
from controllers.tracking import anchor_goals, reference_goals

#: A unit vector standing in for a hidden leg's features (its rows are not used).
_DUMMY = np.array([0.0, 0.0, 1.0])


class FeatureCTC(TaskComputedTorque):
    """Computed torque on a leg-feature task (see the module docstring).

    Args:
        natural_frequency: ``f_n`` [Hz] (default 2 Hz: ``omega_n dt = 0.25`` at 20 ms).
        damping: ``zeta`` (default 1).
        smooth_goal: Reach a fixed goal along the features of a quintic line (False: the
            taught features as a step).
    """

    #: The goal field holding the taught features.
    key = "normals"

    def prepare(self, context: ControllerContext) -> None:
        """Check the estimated camera pose and base points.

        Raises:
            ContextError: Naming the missing or bad field.
        """
        cam, A = camera_and_base_points(self.name, context)
        self._frame = cam
        self._A = A
        self._grid: tuple[object, np.ndarray] | None = None

    def take_goal(self, goal: Goal) -> None:
        """The taught features (``goal.normals`` or ``goal.directions``).

        Raises:
            ContextError: They are missing.
        """
        value = getattr(goal, self.key)
        if value is None:
            raise ContextError(self.name, f"goal.{self.key}", "missing (the taught features)")
        self._taught = np.asarray(value, dtype=float)

    def goal_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """The goal pose, the end of the smooth line (nominal base frame)."""
        assert self.context is not None
        return goal_pose_of(self.name, self.context.goal)

    def measure(self, observation: Observation, q: np.ndarray, q_dot: np.ndarray
                ) -> Measured | str:
        """Encoders' pose and twist; the seen features as the task state."""
        assert self.context is not None and self.model is not None
        R, t = self.encoder_pose(q)
        m = pose_measurement(self.model, R, t, q, q_dot)
        feats = self.features_seen(observation)
        if isinstance(feats, str):
            return feats
        u, normals, rows = feats
        m.state = TaskState(self._A[None], u[None], q[None],
                            None if normals is None else normals[None])
        m.frame, m.rows = self._frame, rows
        return m

    def features_seen(self, observation: Observation
                      ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray] | str:
        """Directions (6, 3), normals (6, 2, 3) or None, and the rows to use."""
        raise NotImplementedError

    def make_task(self, desired: np.ndarray) -> Task:
        """The task towards ``desired`` features."""
        raise NotImplementedError

    def tasks_at(self, times: np.ndarray | None, measured: Measured) -> list[Task]:
        """The task towards the anchored model features at ``times``, or the taught goal.

        The features of the instants around the control grid ``k dt`` are computed once
        for the whole reference (one batched camera model call); other instants on
        demand."""
        ctx = self.context
        if times is None or self.reference is None or ctx is None:
            return [self.make_task(self._taught)]
        dt = float(ctx.dt)
        k = round(float(times[1]) / dt)
        if abs(float(times[1]) - k * dt) < 1e-9 and k >= 0:
            if self._grid is None or self._grid[0] is not self.reference:
                n = int(np.ceil(float(self.reference.duration) / dt)) + 3
                grid_times = (dt * np.arange(n)[:, None] + (times - times[1])).ravel()
                self._grid = (self.reference, self._anchored(grid_times).reshape(
                    n, 3, *self._taught.shape))
            grid = self._grid[1]
            rows = grid[min(k, len(grid) - 1)]
            return [self.make_task(rows[i]) for i in range(3)]
        return [self.make_task(f) for f in self._anchored(times)]

    def _anchored(self, times: np.ndarray) -> np.ndarray:
        """(m, ...) the nominal features of the reference at ``times``, anchored at the
        taught goal."""
        ctx = self.context
        assert ctx is not None and self.reference is not None
        end = float(self.reference.duration) + 1.0
        goals = reference_goals(replace(ctx, reference=self.reference),
                                np.append(times, end))
        anchor_goals(goals, replace(ctx.goal, **{self.key: self._taught}))
        return np.asarray(goals[self.key][:-1])

    def retarget(self, goal: Goal) -> None:
        """A new fixed goal; with a reference the taught features anchor it."""
        super().retarget(goal)
        if self.context is not None and self.context.reference is not None:
            self.take_goal(goal)


class LegEdgeCTC(FeatureCTC):
    """Computed torque on the leg edges (edge normals, ``e = n x n*``; see the module
    docstring)."""

    name = "leg-edge-ctc"
    features = frozenset({"lengths", "normals"})
    key = "normals"

    def features_seen(self, observation: Observation
                      ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray] | str:
        if observation.normals is None:
            return "needs the edge normals (Observation.normals)"
        n = np.asarray(observation.normals, dtype=float)
        u, legs = directions_seen(None, n, None, observation.edge_visible)
        legs &= np.all(np.isfinite(n), axis=(-2, -1))
        u = np.where(legs[:, None], u, _DUMMY)
        n = np.where(legs[:, None, None], n, np.cross(_DUMMY, [1.0, 0.0, 0.0]))
        return u, n, np.repeat(legs, 6)

    def make_task(self, desired: np.ndarray) -> Task:
        return LegEdgeTask(desired, "normals")


class LegDirectionCTC(FeatureCTC):
    """Computed torque on the leg directions (``e = u x u*``; see the module docstring)."""

    name = "leg-direction-ctc"
    features = frozenset({"lengths", "directions"})
    key = "directions"

    def features_seen(self, observation: Observation
                      ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray] | str:
        u, legs = directions_seen(observation.directions, observation.normals,
                                  observation.direction_visible, observation.edge_visible)
        u = np.where(legs[:, None], u, _DUMMY)
        return u, None, np.repeat(legs, 3)

    def make_task(self, desired: np.ndarray) -> Task:
        return LegDirectionTask(desired)
