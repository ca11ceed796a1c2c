"""The compiled computed-torque step against the numpy step it replaced.

:func:`controllers.solvers.compiled_ctc.joint_step` composes the forward kinematics, the
dynamics' terms, the solve and the inverse dynamics into one C function; the numpy step
(:func:`tests.controllers.ctc_oracles.numpy_joint_step`, separate compiled calls, an SVD
solve and :meth:`DynamicModel.inverse`) is the oracle. They must agree to rounding on
random states, and the controller must refuse, with the reason, off the compiled step's
happy path.
"""

from __future__ import annotations

import numpy as np
import pytest

from controllers import registry
from controllers.base import Observation
from controllers.computed_torque import FK_TOLERANCE, ComputedTorqueController
from controllers.ctc_rows import FK_MAX_CALLS, evaluate_rows, rank_condition
from controllers.joint_ctc_rows import FORCES, POSE_IN, POSE_OUT, RESIDUAL
from controllers.solvers import compiled_ctc
from hexapod import deltalab, sample_poses
from hexapod.dynamics import DynamicModel
from hexapod.kinematics import inverse_kinematics
from tests.controllers.ctc_oracles import numpy_joint_step
from tests.controllers.ctc_world import CtcWorld

#: Relative agreement of the forces (and the condition number) [-].
FORCE_RTOL = 1e-9


def _controller() -> tuple[ComputedTorqueController, CtcWorld]:
    world = CtcWorld.make(deltalab())
    g = world.nominal
    R, t = sample_poses(g, 1, rng=np.random.default_rng(3), max_translation=0.01)
    ctrl = registry.create("computed-torque")
    assert isinstance(ctrl, ComputedTorqueController)
    ctrl.reset(world.context(world.goal(R[0], t[0])))
    return ctrl, world


def _compiled_step(ctrl: ComputedTorqueController, q: np.ndarray, qd: np.ndarray,
                   q_s: np.ndarray, qd_s: np.ndarray, qdd_s: np.ndarray
                   ) -> tuple[np.ndarray, float | None, np.ndarray]:
    """The compiled step of the controller's input row with these readings and this
    reference, called from the pose reached until it converges (as the batch's step
    does): its forces, condition number and leg error; the pose found becomes the
    controller's guess."""
    assert ctrl._row is not None
    x = ctrl._row.copy()
    x[compiled_ctc.INPUTS["q"]] = q
    x[compiled_ctc.INPUTS["q_dot"]] = qd
    x[compiled_ctc.INPUTS["desired"]] = np.concatenate([q_s, qd_s, qdd_s])
    Y, converged = evaluate_rows(compiled_ctc.joint_step(), x[None], POSE_IN, POSE_OUT,
                                 RESIDUAL, FK_TOLERANCE, FK_MAX_CALLS)
    assert converged[0]
    ctrl._row[POSE_IN] = Y[0, POSE_OUT]
    condition = rank_condition(Y[0, compiled_ctc.OUTPUTS["factor"]], ctrl.solver.threshold)
    return Y[0, FORCES], condition, q_s - q


def test_compiled_step_equals_the_numpy_path_on_random_states() -> None:
    ctrl, world = _controller()
    g = world.nominal
    model = DynamicModel(g)
    rng = np.random.default_rng(7)
    Rs, ts = sample_poses(g, 40, rng=rng, max_translation=0.03, max_angle=np.deg2rad(6),
                          margin=0.01)
    guesses_R, guesses_t = sample_poses(g, 40, rng=rng, max_translation=0.03,
                                        max_angle=np.deg2rad(6), margin=0.01)
    compared = 0
    for R, t, gR, gt in zip(Rs, ts, guesses_R, guesses_t, strict=True):
        twist = np.concatenate([rng.normal(0, 0.05, 3), rng.normal(0, 0.3, 3)])
        q = inverse_kinematics(g, R, t)
        qd = model.legs_batch(R[None], t[None], twist[None])[0][0]
        q_s = q + rng.normal(0, 2e-3, 6)
        qd_s = rng.normal(0, 0.02, 6)
        qdd_s = rng.normal(0, 0.2, 6)
        ctrl._pose = (gR, gt)
        f_fast, condition, error = _compiled_step(ctrl, q, qd, q_s, qd_s, qdd_s)
        assert condition is not None, "the compiled path refused a regular state"
        pose_fast = ctrl._pose
        ctrl._pose = (gR, gt)
        slow = numpy_joint_step(ctrl, q, qd, q_s, qd_s, qdd_s)
        assert slow.reason is None
        f_slow = np.asarray(slow.forces)
        scale = float(np.abs(f_slow).max())
        assert scale > 1.0  # forces of a real robot under gravity, not zeros
        np.testing.assert_allclose(f_fast, f_slow, rtol=0, atol=FORCE_RTOL * scale)
        assert condition == pytest.approx(slow.condition, rel=FORCE_RTOL)
        assert slow.rank == 6
        np.testing.assert_allclose(error, slow.error, rtol=0, atol=1e-15)
        assert pose_fast is not None and ctrl._pose is not None
        np.testing.assert_allclose(pose_fast[0], ctrl._pose[0], atol=1e-12)
        np.testing.assert_allclose(pose_fast[1], ctrl._pose[1], atol=1e-12)
        # the pose found is the one the lengths came from
        np.testing.assert_allclose(pose_fast[1], t, atol=1e-9)
        compared += 1
    assert compared == 40


def test_the_step_takes_the_compiled_path_on_a_regular_trajectory() -> None:
    ctrl, world = _controller()
    g = world.nominal
    Rs, ts = sample_poses(g, 10, rng=np.random.default_rng(1), max_translation=0.01)
    for k, (R, t) in enumerate(zip(Rs, ts, strict=True)):
        cmd = ctrl.step(Observation(0.02 * k, inverse_kinematics(g, R, t), q_dot=np.zeros(6)))
        assert cmd.reason is None
    assert ctrl.compiled_steps == 10


def test_unreachable_lengths_are_refused_with_the_reason() -> None:
    """Lengths that could each be a leg of deltalab (stroke 345 to 485 mm) without a pose
    together fail the nominal model; a length no leg can have is refused before it."""
    ctrl, _ = _controller()
    no_pose = np.array([0.21, 0.62, 0.21, 0.62, 0.21, 0.62])
    cmd = ctrl.step(Observation(0.0, no_pose, q_dot=np.zeros(6)))
    assert cmd.reason is not None and "nominal model failed" in cmd.reason, cmd.reason
    assert np.all(np.isfinite(cmd.forces)) and not np.any(cmd.forces)
    assert "forward kinematics" in cmd.reason and ctrl.compiled_steps == 0
    far = np.array([0.2, 0.2, 0.2, 0.2, 0.2, 5.0])
    cmd = ctrl.step(Observation(0.02, far, q_dot=np.zeros(6)))
    assert cmd.reason is not None and "measured lengths: leg 0 at 0.2 m, where no leg" in \
        cmd.reason and not np.any(cmd.forces)
