"""The compiled task-space computed-torque step against the numpy step it replaced.

:func:`controllers.solvers.compiled_task_ctc.task_step` composes the pose (forward
kinematics or the rigid fit of the legs seen), the dynamics, the task, the reference's
terms, the solve and the leg forces into one C function per task kind, the laws' only
step; the numpy step (``tests/controllers/task_ctc_oracles.py``: the tasks' numpy error
and Jacobian, an SVD solve, :meth:`DynamicModel.inverse`) is the oracle. They must
agree to rounding on random states (a calibration error between the truth and the
nominal model, a moving reference on and off the control grid, hidden legs, a fixed
goal's first step), and off the happy path the law refuses with the reason of the
step's status.
"""

from __future__ import annotations

import numpy as np
import pytest

from controllers import registry
from controllers.base import Command, Observation
from controllers.task_ctc import TaskComputedTorque
from hexapod import deltalab, sample_poses
from hexapod.dynamics import DynamicModel
from hexapod.kinematics import legs_in_frame
from hexapod.trajectory import PoseTrajectory
from tests.controllers.ctc_world import DT, CtcWorld, perturbed
from tests.controllers.task_ctc_oracles import numpy_law_step, numpy_measure, numpy_task_step
from vision.legs import leg_edges

LAWS = ("cartesian-ctc", "vision-ctc", "leg-edge-ctc", "leg-direction-ctc")
#: Agreement of the forces relative to their largest magnitude [-].
FORCE_RTOL = 1e-9
#: Relative agreement of the condition number (SVD of L against the eigenvalues of L^T L:
#: a relative error of about eps cond^2).
CONDITION_RTOL = 1e-9
#: Agreement of the task errors: both forward kinematics stop below a 1e-12 m length
#: residual, at different Newton iterates (the compiled step runs six per call).
ERROR_ATOL = 1e-10


def _law(name: str, seed: int = 3) -> tuple[TaskComputedTorque, CtcWorld]:
    """A law reset on a nominal model 1 mm off the truth, tracking a circle."""
    truth = deltalab()
    world = CtcWorld.make(truth, perturbed(truth, 1e-3, seed))
    R, t = sample_poses(truth, 2, rng=np.random.default_rng(seed), max_translation=0.01)
    ref = PoseTrajectory("circle", "trapezoidal", R[0], t[0], speed=0.02, acceleration=0.1,
                         radius=0.01, plane="xz")
    law = registry.create(name)
    assert isinstance(law, TaskComputedTorque)
    law.reset(world.context(world.goal(R[1], t[1]), reference=ref))
    return law, world


def _observation(world: CtcWorld, R: np.ndarray, t: np.ndarray, twist: np.ndarray,
                 time: float) -> Observation:
    legs = legs_in_frame(world.truth, R, t, world.camera.camera_from_base)
    normals, _ = leg_edges(legs.base_points, legs.directions, world.truth.leg_radius)
    rates = DynamicModel(world.truth).legs_batch(R[None], t[None], twist[None])[0][0]
    return Observation(time, legs.lengths, normals=normals, directions=legs.directions,
                       q_dot=rates)


def _compiled(law: TaskComputedTorque, obs: Observation) -> Command | str:
    """The law's one step on ``obs`` (a batch of one): its command, or why there is none
    (without the law's name)."""
    cmd = law.step(obs)
    return cmd if cmd.reason is None else cmd.reason.removeprefix(f"{law.name}: ")


def _both(law: TaskComputedTorque, obs: Observation,
          guess: tuple[np.ndarray, np.ndarray]) -> tuple[object, object]:
    """The compiled and the numpy command of one observation from the same FK guess."""
    assert law.compiled is not None
    q, qd = np.asarray(obs.lengths), np.asarray(obs.q_dot)
    law.compiled.guess = guess
    fast = _compiled(law, obs)
    law.compiled.guess = guess
    m = numpy_measure(law, obs, q, qd)
    assert not isinstance(m, str)
    slow = numpy_task_step(law, obs.t, m, qd)
    return fast, slow


def _assert_equal(fast: object, slow: object) -> None:
    assert not isinstance(fast, str), f"the compiled step refused a regular state: {fast}"
    assert fast.reason is None and slow.reason is None, (fast.reason, slow.reason)
    f_fast, f_slow = np.asarray(fast.forces), np.asarray(slow.forces)
    scale = float(np.abs(f_slow).max())
    assert scale > 1.0  # forces of a real robot under gravity, not zeros
    np.testing.assert_allclose(f_fast, f_slow, rtol=0, atol=FORCE_RTOL * scale)
    assert fast.rank == slow.rank == 6
    assert fast.condition == pytest.approx(slow.condition, rel=CONDITION_RTOL)
    assert fast.features_used == slow.features_used
    e_slow = np.asarray(slow.error)
    np.testing.assert_allclose(fast.error, e_slow, rtol=0,
                               atol=ERROR_ATOL * max(1.0, float(np.abs(e_slow).max())))
    assert fast.notes == slow.notes


@pytest.mark.parametrize("name", LAWS)
def test_compiled_step_equals_the_numpy_path_on_random_states(name: str) -> None:
    law, world = _law(name)
    g = world.truth
    rng = np.random.default_rng(11)
    Rs, ts = sample_poses(g, 30, rng=rng, max_translation=0.03, max_angle=np.deg2rad(6),
                          margin=0.01)
    gR, gt = sample_poses(g, 30, rng=rng, max_translation=0.03, max_angle=np.deg2rad(6),
                          margin=0.01)
    duration = float(law.reference.duration)
    moving = 0
    for k in range(30):
        twist = np.concatenate([rng.normal(0, 0.02, 3), rng.normal(0, 0.1, 3)])
        # on the control grid (the cached reference) for even k, anywhere for odd k
        time = DT * rng.integers(0, int(duration / DT) + 5) if k % 2 == 0 else \
            rng.uniform(0.0, duration + 0.1)
        obs = _observation(world, Rs[k], ts[k], twist, time)
        moving += time < duration
        fast, slow = _both(law, obs, (gR[k], gt[k]))
        _assert_equal(fast, slow)
    assert moving >= 20  # most states with a moving reference


@pytest.mark.parametrize("name", ["vision-ctc", "leg-edge-ctc", "leg-direction-ctc"])
def test_hidden_legs_agree_and_too_few_are_refused(name: str) -> None:
    law, world = _law(name)
    R, t = sample_poses(world.truth, 1, rng=np.random.default_rng(5), max_translation=0.02)
    twist = np.array([0.01, -0.005, 0.002, 0.05, -0.03, 0.02])
    obs = _observation(world, R[0], t[0], twist, 0.4)
    visible = np.ones((6, 2), bool)
    visible[2] = False
    hidden = Observation(obs.t, obs.lengths, normals=obs.normals, directions=obs.directions,
                         q_dot=obs.q_dot, edge_visible=visible,
                         direction_visible=visible.all(axis=1))
    fast, slow = _both(law, hidden, (R[0], t[0]))
    _assert_equal(fast, slow)
    if name == "vision-ctc":  # the pose fitted to the five legs seen
        assert fast.notes == ["pose from legs [0, 1, 3, 4, 5]"]
        assert fast.features_used == 6
    else:
        assert fast.features_used == {"leg-edge-ctc": 30, "leg-direction-ctc": 15}[name]
    # one leg seen: the step's status refuses it, with the reason the numpy step gives
    visible[1:] = False
    few = Observation(obs.t, obs.lengths, normals=obs.normals, directions=obs.directions,
                      q_dot=obs.q_dot, edge_visible=visible,
                      direction_visible=visible.all(axis=1))
    assert law.compiled is not None
    reason = _compiled(law, few)
    assert isinstance(reason, str)
    slow = numpy_law_step(law, few)
    assert slow.reason is not None
    if name == "vision-ctc":  # the same words
        assert reason == "only 1 legs seen (legs [0]): the pose needs at least 3"
        assert slow.reason == f"vision-ctc: {reason}"
    else:
        assert "rank < 6" in reason and "rank 2 < 6" in slow.reason, (reason, slow.reason)
    before = law.compiled_steps
    cmd = law.step(few)
    assert cmd.reason == f"{name}: {reason}" and law.compiled_steps == before
    assert not np.any(np.asarray(cmd.forces))


@pytest.mark.parametrize("name", LAWS)
def test_the_step_takes_the_compiled_path_on_a_regular_trajectory(name: str) -> None:
    law, world = _law(name)
    ref = law.reference
    for k in range(20):
        s = ref.at(np.array([k * DT]))
        obs = _observation(world, s.rotation[0], s.translation[0], s.twist[0], k * DT)
        cmd = law.step(obs)
        assert cmd.reason is None
    # the same observation again: the pose's Newton steps start where they converged
    # (a zero step once made 0/0 in the rigid fit)
    for _ in range(5):
        assert law.step(obs).reason is None
    assert law.compiled_steps == 25


@pytest.mark.parametrize("name", LAWS)
def test_a_fixed_goal_first_step_is_compiled_and_equal(name: str) -> None:
    """The first step of a fixed goal (the line starts at the pose the step measures)
    through the compiled step equals the numpy step's, and so does a later one."""
    truth = deltalab()
    world = CtcWorld.make(truth, perturbed(truth, 1e-3, 4))
    R, t = sample_poses(truth, 2, rng=np.random.default_rng(8), max_translation=0.01)
    twist = np.array([0.004, -0.002, 0.001, 0.02, -0.01, 0.015])
    for smooth in (True, False):
        fast, slow = (registry.create(name, smooth_goal=smooth) for _ in range(2))
        assert isinstance(fast, TaskComputedTorque) and isinstance(slow, TaskComputedTorque)
        for law in (fast, slow):
            law.reset(world.context(world.goal(R[1], t[1])))
        obs = _observation(world, R[0], t[0], twist, 0.1)
        first, oracle = fast.step(obs), numpy_law_step(slow, obs)
        _assert_equal(first, oracle)
        assert fast.started and fast.reference_start == 0.1 == slow.reference_start
        if smooth:  # the same line, from the pose each measured
            a, b = fast.reference.at(np.array([0.3])), slow.reference.at(np.array([0.3]))
            np.testing.assert_allclose(a.translation, b.translation, rtol=0, atol=1e-11)
            np.testing.assert_allclose(a.rotation, b.rotation, rtol=0, atol=1e-11)
        else:
            assert fast.reference is None
        later = _observation(world, R[0], t[0], np.full(6, 0.01), 0.3)
        _assert_equal(*_both(fast, later, (R[0], t[0])))


def test_rigid_fit_equals_the_kabsch_fit_of_the_predictive_controller() -> None:
    from controllers.cartesian_ctc import rigid_fit
    from controllers.mpc.prediction import fit_pose
    from hexapod.se3 import exp_so3

    rng = np.random.default_rng(2)
    E = deltalab().platform_points  # coplanar: C has rank 2
    for k in range(20):
        R = exp_so3(rng.normal(0, 1.0, 3))
        t = rng.normal(0, 0.3, 3)
        B = E @ R.T + t + rng.normal(0, 1e-4 * (k % 2), (6, 3))  # exact, then noisy
        keep = slice(None) if k < 10 else slice(0, 4)
        Rf, tf = rigid_fit(B[keep], E[keep])
        Rk, tk = fit_pose(B[keep], E[keep])
        np.testing.assert_allclose(Rf, Rk, atol=1e-12)
        np.testing.assert_allclose(tf, tk, atol=1e-12)
        if k % 2 == 0:
            np.testing.assert_allclose(Rf, R, atol=1e-12)


def test_the_compiled_rigid_fit_from_the_exact_pose_takes_a_zero_step() -> None:
    """Joints ``B = E`` exactly, camera = base, guess the identity: ``S = C`` is exactly
    symmetric, the Newton step is exactly zero and the pose stays the identity (the
    step's Rodrigues coefficients once made 0/0 there)."""
    from controllers.solvers.compiled_task_ctc import layout, task_step
    from controllers.tasks import PLATFORM_POSE

    inputs, outputs = layout(PLATFORM_POSE, False)
    E = deltalab().platform_points
    x = np.zeros(task_step(PLATFORM_POSE, False).n_in)
    x[inputs["pose"]] = np.concatenate([np.eye(3).ravel(), np.zeros(3)])
    x[inputs["q"]] = 1.0
    x[inputs["points"]][18:] = E.ravel()
    x[inputs["directions"]] = E.ravel()  # B = A + q u = E with A = 0, q = 1
    x[inputs["frame"]] = np.concatenate([np.eye(3).ravel(), np.zeros(3)])
    x[inputs["seen"]] = 1.0  # every leg
    y = task_step(PLATFORM_POSE, False).single(x)
    assert y[outputs["fk_residual"]][0] < 1e-8
    np.testing.assert_array_equal(y[outputs["pose"]],
                                  np.concatenate([np.eye(3).ravel(), np.zeros(3)]))


def test_a_law_without_a_compiled_step_refuses_naming_it() -> None:
    """A subclass that neither names a kind nor makes its own step has no step at all
    (there is no numpy path): every period is refused with that reason."""
    from controllers.cartesian_ctc import CartesianCTC

    class NoStep(CartesianCTC):
        name = "no-step-ctc"
        compiled_kind = None

    law, world = _law("cartesian-ctc")
    ctx = law.context
    bare = NoStep()
    bare.reset(ctx)
    s = law.reference.at(np.array([0.0]))
    cmd = bare.step(_observation(world, s.rotation[0], s.translation[0], s.twist[0], 0.0))
    assert cmd.reason == ("no-step-ctc: no compiled step (compiled_kind is None and the law "
                          "made none at reset)")
    assert not np.any(np.asarray(cmd.forces))
