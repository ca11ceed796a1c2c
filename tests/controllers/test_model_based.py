"""The model-based controller: what it commands against the rates of the motion it is
documented to command (inverse kinematics and scipy's rotations only); its one pose
servo (the CasADi kernel, in C or in the CasADi virtual machine) against the numpy
oracle (the compilation), near a half-turn too, per trial and in a batch; its one step
(a batch's rows are batches of one, bit for bit); refusals from the kernel's status, the
readings and the forward kinematics."""

from __future__ import annotations

import copy

import casadi as ca
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from controllers import registry
from controllers.base import ControllerContext, ObservationBatch
from controllers.model_based import (
    _IN,
    HALF_TURN,
    ModelBasedController,
    pose_servo_kernel,
    sx_log_so3,
)
from hexapod.se3 import log_so3
from hexapod.workspace import home_pose
from tests.controllers.controller_world import World, make_camera
from tests.controllers.model_based_oracle import numpy_pose_servo

#: Angles of the orientation error [rad]: small, ordinary, each side of the half-turn
#: branch, close to and at pi.
ANGLES = [0.0, 1e-9, 1e-4, 0.7, 2.5, HALF_TURN - 1e-7, HALF_TURN + 1e-7, np.pi - 1e-6,
          np.pi - 1e-12, np.pi]


@pytest.fixture(scope="module")
def log_function() -> ca.Function:
    M = ca.SX.sym("M", 3, 3)
    return ca.Function("log", [M], [sx_log_so3(M)])


@pytest.mark.parametrize("angle", ANGLES)
def test_log_equals_log_so3_and_scipy(log_function: ca.Function, angle: float,
                                      rng: np.random.Generator) -> None:
    """The kernel's log is hexapod.se3.log_so3 to the last bit (the same formulas), and
    scipy's rotation vector up to its sign at a half-turn (where both are the same
    rotation)."""
    axes = rng.normal(size=(40, 3))
    axes[:3] = np.eye(3)  # the axes of the tie-breaking rule
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    for axis in axes:
        R = Rotation.from_rotvec(axis * angle).as_matrix()
        w = np.asarray(log_function(R)).ravel()
        np.testing.assert_array_equal(w, log_so3(R))
        ref = Rotation.from_matrix(R).as_rotvec()
        if angle > HALF_TURN and np.dot(w, ref) < 0:
            ref = -ref
        np.testing.assert_allclose(w, ref, atol=1e-9)
        assert abs(np.linalg.norm(w) - angle) < 1e-9


def _turned(world: World, rng: np.random.Generator, turn: float, n: int
            ) -> list[tuple[ControllerContext, np.ndarray, np.ndarray]]:
    """``n`` reachable poses ``(R, t)``, each with a context whose goal is that pose turned
    by ``turn`` about a random axis and moved by up to 5 mm: ``(context, R, t)``."""
    Rs, ts = world.poses(n, rng, max_translation=0.02, max_angle=np.deg2rad(4), margin=0.03)
    cases = []
    for R, t in zip(Rs, ts, strict=True):
        axis = rng.normal(size=3)
        goal = world.goal(R, t)
        goal.rotation = Rotation.from_rotvec(axis / np.linalg.norm(axis) * turn).as_matrix() @ R
        goal.translation = t + rng.uniform(-0.005, 0.005, 3)
        cases.append((world.context(goal, 0.02), R, t))
    return cases


@pytest.mark.parametrize("camera", ["perspective", "unified"])
@pytest.mark.parametrize("compiled", [True, False])
@pytest.mark.parametrize("turn", [0.0, 0.3, HALF_TURN + 1e-6, np.pi - 1e-9, np.pi])
def test_step_equals_numpy_oracle(other_geometry, rng: np.random.Generator,  # type: ignore[no-untyped-def]
                                  camera: str, compiled: bool, turn: float) -> None:
    """Every output of a step is the oracle's at the forward kinematics' pose (in C and in
    the virtual machine), up to a half-turn of orientation error, the twist in the
    camera frame."""
    world = World(other_geometry, make_camera(camera, other_geometry))
    for ctx, R, t in _turned(world, rng, turn, 3):
        ctrl = registry.create("model-based", adaptive_gain=(3.0, 0.5, 20.0),
                               compiled=compiled)
        assert isinstance(ctrl, ModelBasedController) and ctrl.kernel is None
        ctrl.reset(ctx)
        assert ctrl.kernel is not None and ctrl.kernel.compiled is compiled
        cmd = ctrl.step(world.observation(R, t))
        assert cmd.ok, cmd.reason
        goal = ctx.goal
        assert goal.rotation is not None and goal.translation is not None
        ref = numpy_pose_servo(ctrl.estimate.rotation, ctrl.estimate.translation,
                               goal.rotation, goal.translation, ctrl.base_points,
                               ctrl.platform_points, ctrl.gain, world.camera.camera_from_base)
        # The half-turn branch is the one taken where the turn is beyond it.
        assert np.linalg.norm(ref.error[3:]) == pytest.approx(turn, abs=1e-9)
        scale = np.abs(ref.velocities).max()
        np.testing.assert_allclose(cmd.velocities, ref.velocities, rtol=1e-10,
                                   atol=1e-13 * scale)
        assert cmd.twist is not None and ref.twist is not None
        np.testing.assert_allclose(cmd.twist, ref.twist, rtol=1e-10, atol=1e-13 * scale)
        np.testing.assert_allclose(cmd.error, ref.error, rtol=1e-10, atol=1e-15)
        assert cmd.error_norm == pytest.approx(ref.error_norm, rel=1e-12)
        assert cmd.condition == pytest.approx(ref.condition, rel=1e-9)
        assert cmd.rank == 6 and cmd.notes[0].startswith("forward kinematics: ")


def _batch(world: World, Rs: np.ndarray, ts: np.ndarray) -> ObservationBatch:
    n = len(Rs)
    return ObservationBatch(
        trials=np.arange(n), t=np.zeros(n),
        lengths=np.array([world.observation(R, t).lengths for R, t in zip(Rs, ts, strict=True)]),
        normals=None, lines=None, directions=None, edge_visible=np.ones((n, 6, 2), bool),
        direction_visible=np.ones((n, 6), bool))


def test_leg_velocities_are_the_rates_of_the_documented_motion(  # type: ignore[no-untyped-def]
        other_geometry, rng: np.random.Generator) -> None:
    """What the law commands, from its definition and not from a second copy of its
    formula (the numpy oracle above checks the compilation only): the platform origin
    moves straight towards ``t*`` at rate ``lam`` and the platform turns about the axis of
    ``log(R* R^T)`` at rate ``lam``, so the leg velocities are the central differences of
    the inverse kinematics along ``(exp(lam s log(R* R^T)) R, t + lam s (t* - t))``
    (rotations by scipy). A law without the ``- w x t`` term of the base-frame twist (its
    origin moving on an arc) fails here and nowhere else."""
    from hexapod import inverse_kinematics

    world = World(other_geometry, make_camera("perspective", other_geometry))
    Rs, ts = world.poses(4, rng, max_translation=0.02, max_angle=np.deg2rad(4), margin=0.03)
    lam, h = 2.0, 1e-6
    for R, t in zip(Rs, ts, strict=True):
        axis = rng.normal(size=3)
        R_goal = Rotation.from_rotvec(0.1 * axis / np.linalg.norm(axis)).as_matrix() @ R
        t_goal = t + rng.uniform(-0.005, 0.005, 3)
        ctrl = registry.create("model-based", gain=lam)
        ctrl.reset(world.context(world.goal(R_goal, t_goal), 0.02))
        cmd = ctrl.step(world.observation(R, t))
        assert cmd.ok, cmd.reason
        rot = Rotation.from_matrix(R_goal @ R.T).as_rotvec()

        def lengths(s: float, R: np.ndarray = R, t: np.ndarray = t, rot: np.ndarray = rot,
                    t_goal: np.ndarray = t_goal) -> np.ndarray:
            return inverse_kinematics(other_geometry,
                                      Rotation.from_rotvec(lam * s * rot).as_matrix() @ R,
                                      t + lam * s * (t_goal - t))

        rates = (lengths(h) - lengths(-h)) / (2 * h)
        assert np.abs(rates).max() > 1e-3  # a motion of several mm/s
        np.testing.assert_allclose(cmd.velocities, rates, atol=1e-7)


def test_batch_computes_every_row_with_the_kernel(other_geometry,  # type: ignore[no-untyped-def]
                                                  rng: np.random.Generator) -> None:
    """A batch with half-turn goals commands every row, and its commands are the
    per-trial steps' (batches of one) to the last bit."""
    world = World(other_geometry, make_camera("perspective", other_geometry))
    cases = [case for turn in (0.0, 0.5, HALF_TURN + 1e-6, np.pi)
             for case in _turned(world, rng, turn, 1)]
    contexts = [ctx for ctx, _, _ in cases]
    obs = _batch(world, np.array([R for _, R, _ in cases]), np.array([t for _, _, t in cases]))
    batch = registry.create("model-based")
    batch.reset_batch(contexts)
    out = batch.step_batch(obs)
    assert out.reasons == [None] * len(obs)
    for k, ctx in enumerate(contexts):
        single = registry.create("model-based")
        single.reset(ctx)
        cmd = single.step(obs.item(k))
        assert cmd.ok
        np.testing.assert_array_equal(out.velocities[k], cmd.velocities)
        assert out.error_norm[k] == cmd.error_norm


def test_non_finite_command_is_refused_from_the_status(other_geometry,  # type: ignore[no-untyped-def]
                                                       rng: np.random.Generator) -> None:
    """A NaN in the servo's input (here the goal rotation, written past the checks) gives
    the kernel's NON_FINITE status: the step and the batch refuse the row with its
    reason and a zero command; the other rows are commands."""
    world = World(other_geometry, make_camera("perspective", other_geometry))
    Rs, ts = world.poses(3, rng, max_translation=0.02, max_angle=np.deg2rad(4), margin=0.03)
    ctx = world.context(world.goal(Rs[0], ts[0]), 0.02)
    for compiled in (True, False):
        ctrl = registry.create("model-based", compiled=compiled)
        assert isinstance(ctrl, ModelBasedController)
        ctrl.reset(ctx)
        ctrl.servo_input[_IN["R_star"].start] = np.nan
        cmd = ctrl.step(world.observation(Rs[1], ts[1]))
        assert not cmd.ok and cmd.reason == "non-finite command (numerical failure)"
        assert np.array_equal(cmd.velocities, np.zeros(6))
    batch = registry.create("model-based")
    assert isinstance(batch, ModelBasedController)
    batch.reset_batch([ctx, ctx])
    batch.trial_instances[1].servo_input[_IN["R_star"].start] = np.nan
    out = batch.step_batch(_batch(world, Rs[1:], ts[1:]))
    assert out.reasons == [None, "non-finite command (numerical failure)"]
    assert np.all(out.velocities[0] != 0.0) and np.array_equal(out.velocities[1], np.zeros(6))
    assert np.isfinite(out.error_norm).all()


#: Leg lengths [m] of ``other_geometry`` (stroke 380 to 560 mm) that could be legs, each
#: alone, and have no pose together.
NO_POSE = np.array([0.21, 0.73, 0.21, 0.73, 0.21, 0.73])


def test_failed_forward_kinematics_is_refused_and_restarts_from_home(  # type: ignore[no-untyped-def]
        other_geometry, rng: np.random.Generator) -> None:
    """Lengths without a pose: the row is refused with the forward kinematics' failure
    (its iterations and residual) and its trial's warm start goes back to the home pose;
    the other row is a command and keeps its pose."""
    world = World(other_geometry, make_camera("perspective", other_geometry))
    Rs, ts = world.poses(3, rng, max_translation=0.02, max_angle=np.deg2rad(4), margin=0.03)
    ctx = world.context(world.goal(Rs[0], ts[0]), 0.02)
    obs = _batch(world, Rs[1:], ts[1:])
    batch = registry.create("model-based")
    assert isinstance(batch, ModelBasedController)
    batch.reset_batch([ctx, ctx])
    assert batch.step_batch(obs).reasons == [None, None]
    moved = batch.trial_instances[1].estimate.translation.copy()
    assert not np.array_equal(moved, home_pose(other_geometry)[1])
    obs.lengths[1] = NO_POSE  # (lengths ten times too long are refused before it)
    done = batch.step_batch(obs)
    assert done.reasons[0] is None and np.array_equal(done.velocities[1], np.zeros(6))
    reason = done.reasons[1]
    assert reason is not None and reason.startswith(
        "forward kinematics failed: forward kinematics (newton) failed after ")
    assert "iterations" in reason and "(residual " in reason
    R0, t0 = home_pose(other_geometry)
    est = batch.trial_instances[1].estimate
    assert np.array_equal(est.rotation, R0) and np.array_equal(est.translation, t0)
    assert np.allclose(batch.trial_instances[0].estimate.translation, ts[1], atol=1e-9)


def _row(velocities: np.ndarray, norm: float, reason: str | None,
         ctrl: ModelBasedController) -> tuple[object, ...]:
    """A row's command (velocities, norm, reason) and its trial's estimate, as bytes."""
    est = ctrl.estimate
    return (velocities.tobytes(), np.float64(norm).tobytes(), reason,
            est.rotation.tobytes(), est.translation.tobytes())


def test_batch_rows_equal_batches_of_one(other_geometry,  # type: ignore[no-untyped-def]
                                         rng: np.random.Generator) -> None:
    """Three steps of a batch of four trials (one whose forward kinematics fails at the
    second step, one with a NaN length at the first and an infinite time at the third)
    are, row by row and bit for bit, four batches of one stepped on the same rows: the
    commands, the norms, the refusals' reasons and the warm starts."""
    world = World(other_geometry, make_camera("perspective", other_geometry))
    Rs, ts = world.poses(7, rng, max_translation=0.02, max_angle=np.deg2rad(4), margin=0.03)
    contexts = [world.context(world.goal(R, t), 0.02) for R, t in zip(Rs[:4], ts[:4],
                                                                        strict=True)]
    batch = registry.create("model-based", adaptive_gain=(2.0, 0.5, 10.0))
    assert isinstance(batch, ModelBasedController)
    batch.reset_batch(contexts)
    singles = []
    for ctx in contexts:
        one = registry.create("model-based", adaptive_gain=(2.0, 0.5, 10.0))
        assert isinstance(one, ModelBasedController)
        one.reset(ctx)
        singles.append(one)
    reasons = set()
    for step in range(3):
        obs = _batch(world, Rs[3:], ts[3:])
        obs.t[:] = 0.02 * step
        if step == 0:
            obs.lengths[2, 4] = np.nan
        if step == 1:
            obs.lengths[1] = NO_POSE
        if step == 2:
            obs.t[2] = np.inf
        out = batch.step_batch(obs)
        for k, one in enumerate(singles):
            cmd = one.step(obs.item(k))
            row = _row(out.velocities[k], out.error_norm[k], out.reasons[k],
                       batch.trial_instances[k])
            assert row == _row(cmd.velocities, cmd.error_norm, cmd.reason, one), (step, k)
            reasons.add(cmd.reason)
    assert {r.split(":")[0] if r else r for r in reasons} == {
        None, "lengths", "forward kinematics failed", "time is inf (not finite)"}


def test_a_batch_of_one_is_the_per_trial_command(other_geometry,  # type: ignore[no-untyped-def]
                                                 rng: np.random.Generator) -> None:
    """The per-trial step's command carries the diagnostics (error, twist, rank, condition
    number, the forward kinematics' iterations) and the row of a batch's command."""
    world = World(other_geometry, make_camera("perspective", other_geometry))
    Rs, ts = world.poses(2, rng, max_translation=0.02, max_angle=np.deg2rad(4), margin=0.03)
    ctx = world.context(world.goal(Rs[0], ts[0]), 0.02)
    one, two = registry.create("model-based"), registry.create("model-based")
    one.reset(ctx)
    two.reset_batch([ctx, ctx])
    cmd = one.step(world.observation(Rs[1], ts[1]))
    out = two.step_batch(_batch(world, Rs[1:], ts[1:]))
    assert cmd.ok and cmd.rank == 6 and cmd.features_used == 6 and cmd.twist is not None
    assert cmd.error.shape == (6,) and cmd.error_norm == float(np.linalg.norm(cmd.error))
    assert np.isfinite(cmd.condition) and cmd.condition >= 1.0
    assert len(cmd.notes) == 1 and cmd.notes[0].endswith(" iterations")
    assert int(cmd.notes[0].split()[-2]) % 3 == 0
    assert np.array_equal(out.velocities[0], cmd.velocities)
    assert out.error_norm[0] == cmd.error_norm


def test_a_copy_steps_like_the_original_and_apart_from_it(other_geometry,  # type: ignore[no-untyped-def]
                                                          rng: np.random.Generator) -> None:
    """A deep copy of a stepped batch carries its warm starts and servo inputs as its own
    arrays: it steps as the original would, and the original is untouched by its steps."""
    world = World(other_geometry, make_camera("perspective", other_geometry))
    Rs, ts = world.poses(6, rng, max_translation=0.02, max_angle=np.deg2rad(4), margin=0.03)
    contexts = [world.context(world.goal(R, t), 0.02) for R, t in zip(Rs[:2], ts[:2],
                                                                        strict=True)]
    ctrl = registry.create("model-based")
    assert isinstance(ctrl, ModelBasedController)
    ctrl.reset_batch(contexts)
    ctrl.step_batch(_batch(world, Rs[2:4], ts[2:4]))
    twin = copy.deepcopy(ctrl)
    for a, b in zip(ctrl.trial_instances, twin.trial_instances, strict=True):
        assert not np.shares_memory(a.servo_input, b.servo_input)
        assert not np.shares_memory(a.estimate.rotation, b.estimate.rotation)
        assert np.array_equal(a.estimate.rotation, b.estimate.rotation)
    moved = twin.step_batch(_batch(world, Rs[4:], ts[4:]))
    assert twin.batch_estimate is not ctrl.batch_estimate
    assert not np.array_equal(twin.trial_instances[1].estimate.translation,
                              ctrl.trial_instances[1].estimate.translation)
    same = ctrl.step_batch(_batch(world, Rs[4:], ts[4:]))
    assert moved.reasons == same.reasons == [None, None]
    assert np.array_equal(moved.velocities, same.velocities)
    assert np.array_equal(twin.batch_estimate.translation, ctrl.batch_estimate.translation)


def test_kernel_layouts() -> None:
    """The status is the kernel's last output; compiled and virtual-machine kernels are
    distinct cached objects of the same function."""
    fast, slow = pose_servo_kernel(True), pose_servo_kernel(False)
    assert fast is pose_servo_kernel(True) and slow is not fast and not slow.compiled
    assert fast.outputs.index("status") == fast.n_out - 1
    assert fast.function.serialize() == slow.function.serialize()
