"""The time axis of a trajectory task (``[task] kind = "trajectory"``): each trial's
reference trajectory, the pose its error is measured against at every period, and its
controllers made to track it (:class:`controllers.tracking.TrackingController`).

A point-to-point task goes through the same functions unchanged: its target is the goal
pose at every period and its controllers are built as before.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from benchmarks.scenario_sections import TaskConfig
from benchmarks.sim.inputs import SimScenario
from benchmarks.sim.world import TrialSetup
from controllers.batch import ForeignController, batch_controller
from hexapod.trajectory import PoseTrajectory


def trajectory_end(task: TaskConfig, start_rotation: np.ndarray,
                   start_translation: np.ndarray, goal_rotation: np.ndarray,
                   goal_translation: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The goal pose of a trial of ``task``: where its reference ends (the start pose
    for a closed curve), else the drawn goal."""
    if task.kind != "trajectory" or task.shape == "line":
        return goal_rotation, goal_translation
    return np.array(start_rotation, dtype=float), np.array(start_translation, dtype=float)


def trial_reference(sc: SimScenario, setup: TrialSetup) -> PoseTrajectory | None:
    """The reference of a trial from its start (and, for a line, goal) pose, with the
    task's limits in SI units (None for a point-to-point task)."""
    task = sc.task
    if task.kind != "trajectory":
        return None
    return PoseTrajectory(
        task.shape, task.profile, setup.start_rotation, setup.start_translation,
        1e-3 * task.speed_mm_s, 1e-3 * task.acceleration_mm_s2,
        goal_rotation=setup.goal_rotation, goal_translation=setup.goal_translation,
        angular_speed=float(np.deg2rad(task.angular_speed_deg_s)),
        angular_acceleration=float(np.deg2rad(task.angular_acceleration_deg_s2)),
        radius=1e-3 * task.radius_mm, laps=task.laps, plane=task.plane,
        jerk=1e-3 * task.jerk_mm_s3,
        angular_jerk=float(np.deg2rad(task.angular_jerk_deg_s3)),
        peak_acceleration=(1e-3 * task.peak_acceleration_mm_s2
                           if task.peak_acceleration_mm_s2 > 0 else None))


class Targets:
    """The pose each trial of a group is measured against at each period: its goal, or
    its reference at ``step dt`` (sampled once on the control grid).

    Attributes:
        duration: (n,) the references' durations [s] (a trajectory task), else None.
    """

    def __init__(self, sc: SimScenario, group: list[TrialSetup]) -> None:
        self.rotation = np.array([s.goal_rotation for s in group])
        self.translation = np.array([s.goal_translation for s in group])
        self._grid: tuple[np.ndarray, np.ndarray] | None = None
        self.duration: np.ndarray | None = None
        if sc.task.kind == "trajectory" and group:
            times = sc.dt * np.arange(sc.task.max_steps + 1)
            references = [trial_reference(sc, s) for s in group]
            self.duration = np.array([r.duration for r in references])  # type: ignore[union-attr]
            samples = [r.at(times) for r in references]  # type: ignore[union-attr]
            # time-major (a period's poses are one block of memory)
            self._grid = (np.stack([r.rotation for r in samples], axis=1),
                          np.stack([r.translation for r in samples], axis=1))

    def __call__(self, step: int, idx: np.ndarray | slice) -> tuple[np.ndarray, np.ndarray]:
        """(n, 3, 3) rotations and (n, 3) translations of rows ``idx`` (indices, or a
        slice: then views, read only)."""
        if self._grid is None:
            return self.rotation[idx], self.translation[idx]
        return self._grid[0][step][idx], self._grid[1][step][idx]


def task_batch_controller(sc: SimScenario, spec: Any, batched: bool = True) -> Any:
    """The controller of ``spec`` for the task of ``sc`` (``reset_batch``, ``step_batch``):
    as registered, wrapped in a :class:`~controllers.tracking.TrackingController` for a
    trajectory task (which passes the trials of a controller that samples the reference
    itself through). Without ``batched``, the per-trial engine's: one such controller per
    trial, each a batch of one (a :class:`~controllers.batch.ForeignController`: the
    reference the batched rows are compared with)."""
    def task_controller() -> Any:
        ctrl = batch_controller(spec.name, spec.options)
        if sc.task.kind != "trajectory":
            return ctrl
        from controllers.tracking import TrackingController

        return TrackingController(ctrl, feed_forward=sc.task.feed_forward)

    return task_controller() if batched else ForeignController(task_controller)
