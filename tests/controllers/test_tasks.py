"""Every task's Jacobian and second-order term against finite differences of the true
kinematics: the platform moved by a constant twist (``integrate_pose``), the state
recomputed exactly at each pose (``TaskState.at_pose``: leg directions, lengths, edge
normals of the cylinders), never a copy of the formulas."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from controllers.interaction import direction_task
from controllers.tasks import (
    JointLengthTask,
    LegDirectionTask,
    LegEdgeTask,
    PlatformPoseTask,
    Task,
    TaskState,
)
from hexapod.geometry import HexapodGeometry
from hexapod.se3 import exp_so3, integrate_pose
from hexapod.workspace import home_pose
from vision.cameras import front_camera

H = 1e-5  # time step of the central differences [s]
N = 5  # poses (a batch of trials)


def _world(geometry: HexapodGeometry, rng: np.random.Generator
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Base points in the camera frame, platform points, and N random platform poses
    (camera frame) with N random twists."""
    cam = front_camera(geometry)
    c = cam.camera_from_base
    A = c.apply(geometry.base_points)
    R0, t0 = home_pose(geometry)
    Rb = exp_so3(rng.uniform(-0.08, 0.08, (N, 3))) @ R0
    tb = t0 + rng.uniform(-0.02, 0.02, (N, 3))
    R = c.rotation @ Rb
    t = tb @ c.rotation.T + c.translation
    twist = np.concatenate([rng.uniform(-0.05, 0.05, (N, 3)),
                            rng.uniform(-0.3, 0.3, (N, 3))], axis=1)
    return A, np.asarray(geometry.platform_points, float), R, t, twist


def _setup(kind: str, geometry: HexapodGeometry, rng: np.random.Generator
           ) -> tuple[Task, Callable[[float], TaskState], np.ndarray]:
    """A task, the exact state after moving each pose by its twist for ``dt`` [s], and the
    twists."""
    A, E, R, t, twist = _world(geometry, rng)
    task = _tasks(geometry, A, E, rng)[kind]

    def at(dt: float) -> TaskState:
        Rm, tm = integrate_pose(R, t, twist, dt)
        return TaskState.at_pose(A, E, Rm, tm, geometry.leg_radius)

    return task, at, twist


def _tasks(geometry: HexapodGeometry, A: np.ndarray, E: np.ndarray, rng: np.random.Generator
           ) -> dict[str, Task]:
    """Each task with a goal: the state at another random pose."""
    cam = front_camera(geometry)
    R0, t0 = home_pose(geometry)
    Rg = cam.camera_from_base.rotation @ exp_so3(rng.uniform(-0.05, 0.05, 3)) @ R0
    tg = cam.camera_from_base.apply(t0 + rng.uniform(-0.01, 0.01, 3))
    goal = TaskState.at_pose(A, E, Rg[None], tg[None], geometry.leg_radius)
    assert goal.normals is not None
    K = np.asarray(cam.line_matrix, float)
    lines_goal = goal.normals[0] @ np.linalg.inv(K)  # rows (K^-T n)^T
    lines_goal /= np.linalg.norm(lines_goal, axis=-1, keepdims=True)
    return {
        "directions": LegDirectionTask(goal.directions[0]),
        "normals": LegEdgeTask(goal.normals[0]),
        "lines": LegEdgeTask(lines_goal, "lines", K),
        "lengths": JointLengthTask(goal.lengths[0]),
        "pose": PlatformPoseTask(Rg, tg),
    }


KINDS = ["directions", "normals", "lines", "lengths", "pose"]


@pytest.mark.parametrize("kind", KINDS)
def test_jacobian_is_the_derivative_of_the_error_along_the_twist(
        kind: str, geometry: HexapodGeometry, rng: np.random.Generator) -> None:
    task, at, twist = _setup(kind, geometry, rng)
    s0 = at(0.0)
    ep = task.error(at(H))
    em = task.error(at(-H))
    numeric = (ep - em) / (2 * H)
    L = task.jacobian(s0)
    assert L.shape == (*numeric.shape, 6)
    analytic = np.einsum("nij,nj->ni", L, twist)
    scale = np.abs(numeric).max()
    assert scale > 1e-3
    np.testing.assert_allclose(analytic, numeric, rtol=0, atol=1e-7 * max(scale, 1.0))


@pytest.mark.parametrize("kind", KINDS)
def test_second_order_term_is_the_derivative_of_the_jacobian_along_the_motion(
        kind: str, geometry: HexapodGeometry, rng: np.random.Generator) -> None:
    task, at, twist = _setup(kind, geometry, rng)
    s0 = at(0.0)

    def rate(dt: float) -> np.ndarray:
        return np.einsum("nij,nj->ni", task.jacobian(at(dt)), twist)

    numeric = (rate(H) - rate(-H)) / (2 * H)
    analytic = task.jacobian_dot_twist(s0, twist)
    assert analytic.shape == numeric.shape
    scale = np.abs(numeric).max()
    assert scale > 1e-4
    np.testing.assert_allclose(analytic, numeric, rtol=0, atol=1e-6 * max(scale, 1.0))
    # and the second difference of the error itself (e_ddot = L_dot tau at constant tau)
    e = [task.error(at(dt)) for dt in (-1e-4, 0.0, 1e-4)]
    second = (e[2] - 2 * e[1] + e[0]) / 1e-8
    np.testing.assert_allclose(analytic, second, rtol=0, atol=1e-3 * max(scale, 1.0))


def test_a_task_is_batched_row_by_row(geometry: HexapodGeometry,
                                      rng: np.random.Generator) -> None:
    """Row k of a batch is the task evaluated on trial k alone."""
    A, E, R, t, twist = _world(geometry, rng)
    s = TaskState.at_pose(A, E, R, t, geometry.leg_radius)
    for task in _tasks(geometry, A, E, rng).values():
        batch = (task.error(s), task.jacobian(s), task.jacobian_dot_twist(s, twist))
        for k in (0, N - 1):
            one = TaskState.at_pose(A, E, R[k:k + 1], t[k:k + 1], geometry.leg_radius)
            single = (task.error(one), task.jacobian(one),
                      task.jacobian_dot_twist(one, twist[k:k + 1]))
            for b, x in zip(batch, single, strict=True):
                np.testing.assert_allclose(b[k], x[0], rtol=0, atol=1e-15)


def test_the_direction_task_is_the_laws_definition(geometry: HexapodGeometry,
                                                   rng: np.random.Generator) -> None:
    """The task and the leg-direction law use one definition (interaction.direction_task)."""
    A, E, R, t, _ = _world(geometry, rng)
    s = TaskState.at_pose(A, E, R, t, geometry.leg_radius)
    task = _tasks(geometry, A, E, rng)["directions"]
    e, L = direction_task(s.directions[0], task.desired, s.base_points[0], s.lengths[0])
    assert e is not None
    assert np.array_equal(task.error(s)[0], e.reshape(18))
    assert np.array_equal(task.jacobian(s)[0], L.reshape(18, 6))


def test_a_line_task_needs_the_line_matrix() -> None:
    with pytest.raises(ValueError, match="line_matrix"):
        LegEdgeTask(np.zeros((6, 2, 3)), "lines")
    with pytest.raises(ValueError, match="kind"):
        LegEdgeTask(np.zeros((6, 2, 3)), "pixels")
