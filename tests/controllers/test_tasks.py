"""Every task's Jacobian and second-order term against finite differences of the true
kinematics: the platform moved by a constant twist (``integrate_pose``), the state
recomputed exactly at each pose (``TaskState.at_pose``: leg directions, lengths, edge
normals of the cylinders), never a copy of the formulas."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from controllers.law_kernel import feature_law_kernel
from controllers.tasks import (
    LEG_DIRECTIONS,
    JointLengthTask,
    LegEdgeTask,
    PlatformPoseTask,
    Task,
    TaskState,
)
from hexapod.geometry import HexapodGeometry
from hexapod.se3 import exp_so3, integrate_pose
from hexapod.workspace import home_pose
from tests.controllers.interaction_oracle import direction_task, edge_line_task, edge_normal_task
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
        "directions": LEG_DIRECTIONS.task_of(goal.directions[0]),
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


def test_the_direction_task_is_the_compiled_cores_definition(geometry: HexapodGeometry,
                                                              rng: np.random.Generator) -> None:
    """The task and the compiled leg-direction core evaluate one expression
    (``direction_block``): the core's error and ``J_inv`` are the tasks' to the last bit,
    its ``N = L^T L`` the task's to rounding; the numpy oracle agrees to rounding."""
    A, E, R, t, _ = _world(geometry, rng)
    s = TaskState.at_pose(A, E, R, t, geometry.leg_radius)
    task = _tasks(geometry, A, E, rng)["directions"]
    kernel = feature_law_kernel(LEG_DIRECTIONS)
    kernel.set("desired", task.desired)
    kernel.set("base_points", A)
    kernel.set("gain", (1.0, 1.0, 0.0))
    for k in range(N):
        kernel.set("features", s.directions[k])
        kernel.set("lengths", s.lengths[k])
        out = kernel.evaluate()
        row = TaskState(s.base_points[k:k + 1], s.directions[k:k + 1], s.lengths[k:k + 1])
        L = task.jacobian(row)[0]
        assert np.array_equal(out.error, task.error(row)[0])
        assert np.array_equal(out.J, JointLengthTask(s.lengths[k]).jacobian(row)[0])
        np.testing.assert_allclose(out.N, L.T @ L, rtol=1e-13, atol=1e-13 * np.abs(out.N).max())
        e, L_np = direction_task(s.directions[k], task.desired, A, s.lengths[k])
        assert e is not None
        np.testing.assert_allclose(out.error, e.reshape(18), rtol=0, atol=1e-15)
        np.testing.assert_allclose(L, L_np.reshape(18, 6), rtol=0, atol=1e-13)


def test_the_edge_tasks_agree_with_the_numpy_oracle(geometry: HexapodGeometry,
                                                    rng: np.random.Generator) -> None:
    """The edge tasks' CasADi blocks against the numpy rank-one blocks of
    ``tests/controllers/interaction_oracle.py`` (rounding)."""
    A, E, R, t, _ = _world(geometry, rng)
    s = TaskState.at_pose(A, E, R, t, geometry.leg_radius)
    tasks = _tasks(geometry, A, E, rng)
    assert s.normals is not None
    u2 = np.repeat(s.directions, 2, axis=-2).reshape(-1, 3)
    A2 = np.repeat(s.base_points, 2, axis=-2).reshape(-1, 3)
    q2 = np.repeat(s.lengths, 2, axis=-1).reshape(-1)
    n12 = s.normals.reshape(-1, 3)
    for kind in ("normals", "lines"):
        task = tasks[kind]
        assert isinstance(task, LegEdgeTask)
        f = task.feature.features_of(s.normals, task.line_matrix_inv_t).reshape(-1, 3)
        star = np.broadcast_to(task.desired, (N, 6, 2, 3)).reshape(-1, 3)
        if kind == "lines":
            L_np = edge_line_task(f, star, n12, u2, A2, q2, task.line_matrix,
                                  task.line_matrix_inv_t)
        else:
            L_np = edge_normal_task(n12, star, u2, A2, q2)
        np.testing.assert_allclose(task.error(s).reshape(-1, 3), np.cross(f, star),
                                   rtol=0, atol=1e-15)
        np.testing.assert_allclose(task.jacobian(s).reshape(-1, 3, 6), L_np, rtol=0,
                                   atol=1e-12 * np.abs(L_np).max())


def test_a_line_task_needs_the_line_matrix() -> None:
    with pytest.raises(ValueError, match="line_matrix"):
        LegEdgeTask(np.zeros((6, 2, 3)), "lines")
    with pytest.raises(ValueError, match="kind"):
        LegEdgeTask(np.zeros((6, 2, 3)), "pixels")
