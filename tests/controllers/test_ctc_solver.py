"""The computed-torque solver's pieces against finite differences of the true motion and
against the dynamic model's forward dynamics with drives (a second formulation)."""

from __future__ import annotations

import numpy as np
import pytest

from controllers.solvers.computed_torque import (
    ComputedTorqueSolver,
    SecondOrderGains,
    task_in_model_twist,
)
from controllers.tasks import JointLengthTask, LegEdgeTask, PlatformPoseTask, TaskState
from hexapod import HexapodGeometry
from hexapod.dynamics import DynamicModel
from hexapod.kinematics import legs_in_frame
from hexapod.se3 import exp_so3
from hexapod.trajectory import PoseTrajectory
from hexapod.workspace import home_pose
from tests.controllers.ctc_solver_oracle import acceleration, reference_terms
from vision.cameras import front_camera
from vision.legs import leg_edges

H = 1e-4


def _motion(R0: np.ndarray, t0: np.ndarray, twist: np.ndarray, acc: np.ndarray, h: float
            ) -> tuple[np.ndarray, np.ndarray]:
    """A smooth path through ``(R0, t0)`` whose model twist is ``twist`` and whose model
    acceleration is ``acc`` at ``h = 0`` (``t_dot = v``, ``R_dot = [w]_x R``)."""
    v, w, a, alpha = twist[:3], twist[3:], acc[:3], acc[3:]
    return exp_so3(w * h + alpha * h * h / 2) @ R0, t0 + v * h + a * h * h / 2


def _state(g: HexapodGeometry, R: np.ndarray, t: np.ndarray, frame: object) -> TaskState:
    legs = legs_in_frame(g, R, t, frame)  # type: ignore[arg-type]
    normals, _ = leg_edges(legs.base_points, legs.directions, g.leg_radius)
    return TaskState(legs.base_points[None], legs.directions[None], legs.lengths[None],
                     normals[None], R[None], t[None])


@pytest.mark.parametrize("task_kind", ["lengths", "edges"])
def test_task_in_model_twist_against_the_motion(geometry: HexapodGeometry,
                                                task_kind: str) -> None:
    """``e_dot = (L G) tau`` and ``e_ddot = (L G) tau_dot + L_dot tau_s + L G_dot tau``
    along a true motion, tasks in the camera frame."""
    rng = np.random.default_rng(3)
    frame = front_camera(geometry).camera_from_base
    R0, t0 = home_pose(geometry)
    R0 = exp_so3(rng.normal(scale=0.03, size=3)) @ R0
    t0 = t0 + rng.normal(scale=0.01, size=3)
    twist = np.concatenate([rng.normal(scale=0.05, size=3), rng.normal(scale=0.3, size=3)])
    acc = rng.normal(scale=0.5, size=6)
    s0 = _state(geometry, R0, t0, frame)
    if task_kind == "lengths":
        task = JointLengthTask(s0.lengths[0] + 0.01)
    else:
        assert s0.normals is not None
        task = LegEdgeTask(s0.normals[0] @ exp_so3(np.array([0.02, 0.01, -0.01])).T)
    e = [task.error(_state(geometry, *_motion(R0, t0, twist, acc, k * H), frame))[0]
         for k in (-1, 0, 1)]
    L, tau_s, gdot = task_in_model_twist(task.jacobian(s0)[0], t0, twist, frame)
    ldot = task.jacobian_dot_twist(s0, tau_s[None])[0]
    scale = np.abs(e[1] - e[0]).max() / H
    np.testing.assert_allclose(L @ twist, (e[2] - e[0]) / (2 * H), atol=1e-6 * scale)
    second = (e[2] - 2 * e[1] + e[0]) / H**2
    np.testing.assert_allclose(L @ acc + ldot + gdot, second,
                               atol=1e-4 * np.abs(second).max())


def test_joint_lengths_in_model_twist_are_the_inverse_jacobian(geometry: HexapodGeometry
                                                               ) -> None:
    """In the base frame the joint-length task's ``L G`` is the dynamic model's ``K``."""
    R, t = home_pose(geometry)
    R = exp_so3(np.array([0.03, -0.02, 0.01])) @ R
    s = _state(geometry, R, t, None)
    L, _, _ = task_in_model_twist(JointLengthTask(s.lengths[0]).jacobian(s)[0], t,
                                  np.zeros(6))
    K = DynamicModel(geometry).terms_batch(R[None], t[None], np.zeros((1, 6)))[2][0]
    np.testing.assert_allclose(L, K, atol=1e-12)


def test_reference_terms_against_the_motion(geometry: HexapodGeometry) -> None:
    """A pose task whose desired pose moves along a rotating line while the platform
    moves: the error's total second derivative is ``L tau_dot + L_dot tau + e_tt``."""
    R0, t0 = home_pose(geometry)
    R1 = R0 @ exp_so3(np.array([0.03, 0.02, -0.02]))
    ref = PoseTrajectory("line", "quintic", R0, t0, 0.02, 0.1, goal_rotation=R1,
                         goal_translation=t0 + np.array([0.01, 0.01, -0.005]),
                         angular_speed=0.05, angular_acceleration=0.2)
    tr = 0.3 * ref.duration
    Rx, tx = R0 @ exp_so3(np.array([0.01, 0.0, 0.02])), t0 + np.array([0.003, -0.002, 0.001])
    twist = np.array([0.01, -0.02, 0.005, 0.1, -0.05, 0.2])
    acc = np.array([0.2, 0.1, -0.3, 1.0, 0.5, -0.4])

    def task_at(time: float) -> PlatformPoseTask:
        s = ref.at(np.array([time]))
        return PlatformPoseTask(s.rotation[0], s.translation[0])

    def state(R: np.ndarray, t: np.ndarray) -> TaskState:
        return TaskState(np.zeros((1, 6, 3)), np.zeros((1, 6, 3)), np.zeros((1, 6)), None,
                         R[None], t[None])

    h = 1e-3
    e = [task_at(tr + k * h).error(state(*_motion(Rx, tx, twist, acc, k * h)))[0]
         for k in (-1, 0, 1)]
    s0 = state(Rx, tx)
    task = task_at(tr)
    L, tau_s, gdot = task_in_model_twist(task.jacobian(s0)[0], tx, twist)
    ldot = task.jacobian_dot_twist(s0, tau_s[None])[0] + gdot
    e_t, e_tt = reference_terms(lambda k: task_at(tr + k * 1e-3), s0, tau_s)
    np.testing.assert_allclose(L @ twist + e_t, (e[2] - e[0]) / (2 * h), rtol=1e-5,
                               atol=1e-9)
    second = (e[2] - 2 * e[1] + e[0]) / h**2
    np.testing.assert_allclose(L @ acc + ldot + e_tt, second, rtol=1e-3,
                               atol=1e-4 * np.abs(second).max())
    assert np.abs(e_tt).max() > 0.01 * np.abs(second).max()  # the reference's share counts


def test_rank_deficient_task_is_refused_or_damped() -> None:
    rng = np.random.default_rng(0)
    L = rng.normal(size=(8, 5)) @ rng.normal(size=(5, 6))  # rank 5
    e = rng.normal(size=8)
    gains = SecondOrderGains(2.0, 1.0)
    sol = acceleration(ComputedTorqueSolver(gains), e, L, np.zeros(8), np.zeros(6))
    assert sol.reason is not None and "rank 5 < 6" in sol.reason
    np.testing.assert_array_equal(sol.acc, np.zeros(6))
    damped = acceleration(ComputedTorqueSolver(gains), e, L, np.zeros(8), np.zeros(6),
                          damping=0.1)
    assert damped.reason is None and np.all(np.isfinite(damped.acc))


def test_forces_give_the_acceleration_through_the_drives(geometry: HexapodGeometry) -> None:
    """The solver's forces, applied through the forward dynamics WITH the drives (rotor
    inertia as a leg-space mass, friction subtracted), give back the acceleration."""
    model = DynamicModel(geometry)
    R, t = home_pose(geometry)
    R = exp_so3(np.array([0.02, 0.01, -0.03])) @ R
    twist = np.array([0.01, 0.02, -0.01, 0.1, -0.2, 0.05])
    acc = np.array([0.3, -0.2, 0.5, 1.0, 0.4, -0.7])
    q_dot = model.legs_batch(R[None], t[None], twist[None])[0][0]
    f, a = ComputedTorqueSolver.forces(model, R, t, twist, acc, q_dot,
                                       coulomb_velocity=q_dot)
    d = geometry.drives
    friction = d.viscous * q_dot + d.coulomb * np.tanh(q_dot / 1e-4)
    back, _, q_ddot = model.forward_drives_batch(R[None], t[None], twist[None],
                                                 (f - friction)[None],
                                                 np.asarray(d.rotor_inertia))
    np.testing.assert_allclose(back[0], acc, rtol=1e-8, atol=1e-9)
    np.testing.assert_allclose(q_ddot[0], a, rtol=1e-8, atol=1e-9)
