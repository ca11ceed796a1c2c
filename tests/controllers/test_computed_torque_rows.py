"""``computed-torque``'s step on its own input row (the pose guess kept in the row, the
desired legs written in place) against an oracle that builds every row afresh.

The oracle is the plain use of :func:`controllers.solvers.compiled_ctc.joint_step`:
a fresh input row from the documented layout (the guess ``R`` column-major and ``t``,
the lengths, their rates, ``desired(t)``, the nominal points, the model's parameters,
the drives and the gains), :meth:`CompiledFunction.single` called again from the pose
reached until the length residual is below ``FK_TOLERANCE``, LAPACK's ``syevd`` of
``K^T K`` for the condition number. The controller must give the same numbers bitwise
whatever the guess (the previous pose, one set from outside, the home pose), after a
deep copy and after pickling. ``desired`` itself is checked against the quintic's
definition (end points, derivatives by central differences) and against the reference.
"""

from __future__ import annotations

import copy
import math
import pickle

import numpy as np
import pytest
from scipy.linalg.lapack import dsyevd

from controllers import registry
from controllers.base import Command, Observation
from controllers.computed_torque import (
    FK_TOLERANCE,
    QUINTIC_PEAK_SPEED,
    ComputedTorqueController,
)
from controllers.solvers import compiled_ctc
from hexapod import deltalab, sample_poses
from hexapod.dynamics import DynamicModel
from hexapod.kinematics import inverse_kinematics
from hexapod.trajectory import PoseTrajectory
from hexapod.workspace import home_pose
from tests.controllers.ctc_world import CtcWorld


def _controller(reference: object = None) -> tuple[ComputedTorqueController, CtcWorld]:
    world = CtcWorld.make(deltalab())
    R, t = sample_poses(world.nominal, 1, rng=np.random.default_rng(3), max_translation=0.01)
    ctrl = registry.create("computed-torque")
    assert isinstance(ctrl, ComputedTorqueController)
    ctrl.reset(world.context(world.goal(R[0], t[0]), reference=reference))
    return ctrl, world


def _observations(world: CtcWorld, n: int, seed: int) -> list[Observation]:
    """Poses 3 cm and 6 degrees apart (several Newton rounds each) with leg rates."""
    g = world.nominal
    rng = np.random.default_rng(seed)
    Rs, ts = sample_poses(g, n, rng=rng, max_translation=0.03, max_angle=np.deg2rad(6),
                          margin=0.01)
    return [Observation(0.02 * k, inverse_kinematics(g, R, t), q_dot=rng.normal(0, 0.01, 6))
            for k, (R, t) in enumerate(zip(Rs, ts, strict=True))]


def _oracle(ctrl: ComputedTorqueController, obs: Observation,
            guess: tuple[np.ndarray, np.ndarray] | None) -> tuple[np.ndarray, float, int]:
    """Forces, condition number and Newton rounds of one step from a fresh row."""
    assert ctrl._ctx is not None
    g = ctrl._ctx.geometry
    d = g.drives
    R0, t0 = home_pose(g) if guess is None else guess
    q_s, qd_s, qdd_s = ctrl.desired(obs.t)
    row = np.concatenate([
        R0.T.ravel(), t0, obs.lengths, obs.q_dot, q_s, qd_s, qdd_s, g.base_points.ravel(),
        g.platform_points.ravel(), DynamicModel(g).parameters,
        *(np.broadcast_to(np.asarray(c, dtype=float), (6,))
          for c in (d.rotor_inertia, d.viscous, d.coulomb)),
        [ctrl.kp, ctrl.kd]])
    fn = compiled_ctc.joint_step()
    y = fn.single(row)
    rounds = 1
    while not y[54] < FK_TOLERANCE:
        row[0:12] = y[0:12]
        y = fn.single(row)
        rounds += 1
    assert y[55] == 1.0
    w, _, info = dsyevd(y[12:48].reshape(6, 6), compute_v=0)
    assert info == 0
    return y[48:54], math.sqrt(float(w[-1])) / math.sqrt(float(w[0])), rounds


def _same(a: Command, b: Command) -> None:
    assert a.reason is None and b.reason is None
    np.testing.assert_array_equal(a.forces, b.forces)
    np.testing.assert_array_equal(a.error, b.error)
    assert (a.error_norm, a.condition, a.rank) == (b.error_norm, b.condition, b.rank)


def test_every_step_equals_a_fresh_row_from_its_guess() -> None:
    ctrl, world = _controller()
    rng = np.random.default_rng(11)
    rounds = []
    for k, obs in enumerate(_observations(world, 30, seed=5)):
        if k % 5 == 3:  # a guess set from outside (as the tests and the numpy path do)
            R, t = sample_poses(world.nominal, 1, rng=rng, max_translation=0.02)
            ctrl._pose = (R[0], t[0])
        guess = ctrl._pose
        cmd = ctrl.step(obs)
        f, condition, n = _oracle(ctrl, obs, guess)
        assert cmd.reason is None, cmd.reason
        np.testing.assert_array_equal(cmd.forces, f)
        assert cmd.condition == condition
        rounds.append(n)
    assert ctrl.compiled_steps == 30
    assert min(rounds) == 1 and max(rounds) >= 2  # both the one-round and the loop path


def _replayed(observations: list[Observation]) -> ComputedTorqueController:
    ctrl, _ = _controller()
    for o in observations:
        assert ctrl.step(o).reason is None
    return ctrl


def test_copies_and_pickles_step_like_the_original_and_apart_from_it() -> None:
    _, world = _controller()
    obs = _observations(world, 12, seed=8)
    ctrl = _replayed(obs[:4])
    for c in (copy.deepcopy(ctrl), pickle.loads(pickle.dumps(ctrl))):
        assert c._row is not None and ctrl._row is not None
        assert not np.shares_memory(c._row, ctrl._row)  # its own state
        twin = _replayed(obs[:4])
        _same(c.step(obs[4]), twin.step(obs[4]))  # the pose guess travelled with the copy
        assert c.step(obs[9]).reason is None  # the copy moves on
    twin = _replayed(obs[:4])  # the original is untouched by its copies' steps
    for o in obs[4:8]:
        _same(ctrl.step(o), twin.step(o))


@pytest.mark.filterwarnings("ignore:overflow encountered")
def test_an_overflowing_sum_of_squares_is_left_to_encoder_readings() -> None:
    ctrl, _ = _controller()
    cmd = ctrl.step(Observation(0.0, np.full(6, 1e200), q_dot=np.zeros(6)))
    # finite values: not refused as "not finite" but as lengths no leg can have
    assert cmd.reason is not None and cmd.reason.startswith(
        "computed-torque: measured lengths: leg 0 at 1e+200 m, where no leg"), cmd.reason
    assert np.all(np.isfinite(cmd.forces)) and not np.any(cmd.forces)
    assert ctrl.compiled_steps == 0


def test_the_fixed_goal_quintic_is_the_leg_space_quintic() -> None:
    ctrl, world = _controller()
    obs = _observations(world, 1, seed=2)[0]
    start = 0.5
    ctrl.step(Observation(start, obs.lengths, q_dot=np.zeros(6)))
    q0, q1 = obs.lengths, ctrl._q_star
    T = QUINTIC_PEAK_SPEED * np.abs(q1 - q0).max() / world.nominal.max_speed
    assert T > 0.1
    q_a, qd_a, qdd_a = ctrl.desired(start)
    np.testing.assert_array_equal(q_a, q0)
    assert not np.any(qd_a) and not np.any(qdd_a)
    q_b, qd_b, _ = ctrl.desired(start + T)
    np.testing.assert_allclose(q_b, q1, rtol=0, atol=1e-15)
    np.testing.assert_allclose(qd_b, 0.0, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(ctrl.desired(start + 2 * T)[0], q_b)
    h = 1e-5
    for x in (0.1, 0.3, 0.5, 0.8):
        tk = start + x * T
        q_m, qd_m, _ = ctrl.desired(tk - h)
        q_p, qd_p, _ = ctrl.desired(tk + h)
        q_k, qd_k, qdd_k = ctrl.desired(tk)
        np.testing.assert_allclose(qd_k, (q_p - q_m) / (2 * h), rtol=1e-6, atol=1e-12)
        np.testing.assert_allclose(qdd_k, (qd_p - qd_m) / (2 * h), rtol=1e-6, atol=1e-10)
        s = (q_k - q0) / (q1 - q0)  # the same fraction of the way on every leg
        np.testing.assert_allclose(s, 10 * x**3 - 15 * x**4 + 6 * x**5, rtol=1e-9)
    # peak leg speed at mid-course: the nominal speed limit
    assert np.abs(ctrl.desired(start + T / 2)[1]).max() == pytest.approx(
        world.nominal.max_speed, rel=1e-12)


def test_desired_on_a_reference_is_its_legs_on_and_off_the_grid() -> None:
    world = CtcWorld.make(deltalab())
    R0, t0 = home_pose(world.nominal)
    ref = PoseTrajectory("circle", "quintic", R0, t0, speed=0.01, acceleration=0.05,
                         radius=0.005)
    ctrl, _ = _controller(reference=ref)
    dt = 0.02
    end = float(ref.duration)
    for t in (0.0, 3 * dt, 0.5 * end, end - 0.5 * dt, end):
        direct = ctrl.reference_legs(np.array([t]))[0]
        np.testing.assert_allclose(np.stack(ctrl.desired(t)), direct, rtol=0, atol=1e-12)
    off = 3.37 * dt  # off the grid: evaluated at that instant, not the nearest node
    np.testing.assert_array_equal(np.stack(ctrl.desired(off)),
                                  ctrl.reference_legs(np.array([off]))[0])
    last = np.stack(ctrl.desired(end + 5.0))  # at rest at the end
    np.testing.assert_allclose(last[0], ctrl.reference_legs(np.array([end]))[0][0],
                               rtol=0, atol=1e-12)
    assert np.abs(last[1:]).max() < 1e-12
