"""The status per row of the compiled computed-torque steps (``controllers/ctc_status.py``).

Each kernel returns a ``status`` in its output layout; a regular row has 0, and rows
made to fail one way each get that way's code (the input's own problems first: too few
rows in the mask, too few legs seen for the fit; then the pose not converged, a
non-finite value). The laws' refusals are the codes' words
(:func:`~controllers.ctc_status.status_reason`), the same through the per-trial step
and through the batch.
"""

from __future__ import annotations

import numpy as np
import pytest

from controllers import registry
from controllers.base import Observation, ObservationBatch
from controllers.computed_torque import ComputedTorqueController
from controllers.ctc_rows import refusal
from controllers.ctc_status import Status, status_reason
from controllers.solvers import compiled_ctc
from controllers.task_ctc import TaskComputedTorque
from hexapod import deltalab, sample_poses
from hexapod.dynamics import DynamicModel
from hexapod.kinematics import legs_in_frame
from hexapod.se3 import exp_so3
from hexapod.workspace import home_pose
from tests.controllers.ctc_world import DT, CtcWorld
from vision.legs import leg_edges


def _observation(world: CtcWorld, R: np.ndarray, t: np.ndarray, time: float) -> Observation:
    legs = legs_in_frame(world.truth, R, t, world.camera.camera_from_base)
    normals, _ = leg_edges(legs.base_points, legs.directions, world.truth.leg_radius)
    twist = np.array([0.004, -0.002, 0.001, 0.02, -0.01, 0.015])
    rates = DynamicModel(world.truth).legs_batch(R[None], t[None], twist[None])[0][0]
    return Observation(time, legs.lengths, normals=normals, directions=legs.directions,
                       q_dot=rates)


def _stepped(name: str) -> tuple[TaskComputedTorque, CtcWorld, Observation]:
    """A law after one regular step (its input row holds a regular row)."""
    world = CtcWorld.make(deltalab())
    R, t = sample_poses(world.truth, 2, rng=np.random.default_rng(6), max_translation=0.01)
    law = registry.create(name)
    assert isinstance(law, TaskComputedTorque)
    law.reset(world.context(world.goal(R[1], t[1])))
    obs = _observation(world, R[0], t[0], 0.0)
    assert law.step(obs).reason is None
    return law, world, obs


def _far_guess() -> np.ndarray:
    """A pose row (``R`` column-major, ``t``) 50 degrees and 8 cm from home."""
    R, t = home_pose(deltalab())
    R = exp_so3(np.array([0.6, -0.5, 0.3])) @ R
    return np.concatenate([R.T.ravel(), t + np.array([0.05, -0.04, 0.05])])


def _unconverged(law: TaskComputedTorque, x0: np.ndarray) -> np.ndarray:
    """The row ``x0`` with a pose that does not converge: lengths a twentieth of theirs
    (no pose has them: the encoders' Newton steps stall); for the visual fit a guess
    50 degrees off (its four Newton steps do not reach the tolerance)."""
    assert law.compiled is not None
    x = x0.copy()
    if law.compiled.fk:
        x[law.compiled.inputs["q"]] *= 0.05
    else:
        x[law.compiled.inputs["pose"]] = _far_guess()
    return x


def _status(law: TaskComputedTorque, x: np.ndarray) -> int:
    assert law.compiled is not None
    y = law.compiled.function.single(x)
    return int(y[law.compiled.outputs.index("status")])


@pytest.mark.parametrize("name", ["cartesian-ctc", "vision-ctc", "leg-edge-ctc",
                                  "leg-direction-ctc"])
def test_task_kernels_give_each_problem_its_code(name: str) -> None:
    law, _, _ = _stepped(name)
    assert law.compiled is not None
    inputs, x0 = law.compiled.inputs, law.compiled.row.copy()
    assert _status(law, x0) == Status.OK
    x = x0.copy()
    x[inputs["q_dot"]] = 1e200  # forces that overflow
    assert _status(law, x) == Status.NON_FINITE
    x = _unconverged(law, x0)
    assert _status(law, x) == Status.NOT_CONVERGED
    if "mask" in inputs:  # five legs' rows of six: enough; five rows: too few
        m = inputs["mask"].stop - inputs["mask"].start
        x = x0.copy()
        x[inputs["mask"]] = np.repeat([1.0, 1.0, 0.0, 1.0, 1.0, 1.0], m // 6)
        assert _status(law, x) == Status.OK
        x[inputs["mask"]] = (np.arange(m) < 5).astype(float)
        x = _unconverged(law, x)
        assert _status(law, x) == Status.TOO_FEW_ROWS  # (before the pose's own)
    if "seen" in inputs:  # the visual fit: three legs are enough, two are not
        x = x0.copy()
        x[inputs["seen"]] = [1.0, 0.0, 1.0, 0.0, 1.0, 0.0]
        assert _status(law, x) in (Status.OK, Status.NOT_CONVERGED)  # (a first call)
        x[inputs["seen"]] = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0]
        assert _status(law, x) == Status.TOO_FEW_LEGS


def test_the_joint_kernel_gives_its_codes() -> None:
    world = CtcWorld.make(deltalab())
    R, t = home_pose(world.truth)
    ctrl = registry.create("computed-torque", smooth_goal=False)
    assert isinstance(ctrl, ComputedTorqueController)
    ctrl.reset(world.context(world.goal(R, t + np.array([0.002, 0.0, 0.0]))))
    obs = _observation(world, R, t, 0.0)
    assert ctrl.step(obs).reason is None
    f = compiled_ctc.joint_step()
    assert ctrl._row is not None
    x0 = ctrl._row.copy()  # the trial's input row, as its last step wrote it
    status = compiled_ctc.OUTPUTS.index("status")
    assert f.single(x0)[status] == Status.OK
    x = x0.copy()
    x[compiled_ctc.INPUTS["q_dot"]] = 1e200
    assert f.single(x)[status] == Status.NON_FINITE
    x = x0.copy()
    x[compiled_ctc.INPUTS["q"]] *= 0.05  # lengths no pose has
    y = f.single(x)
    assert y[status] == Status.NOT_CONVERGED
    reason = refusal(y, status, compiled_ctc.OUTPUTS.index("fk_residual"),
                     compiled_ctc.OUTPUTS["factor"], ctrl.solver.threshold)
    assert reason is not None and reason.startswith(
        "nominal model failed: forward kinematics of the lengths did not converge")


@pytest.mark.parametrize("name", ["vision-ctc", "leg-edge-ctc", "leg-direction-ctc"])
def test_a_refusal_has_the_words_of_its_code_per_trial_and_in_a_batch(name: str) -> None:
    """Legs 0 and 3 seen: too few legs for ``vision-ctc``'s fit (a code of the kernel),
    12 edge rows of rank < 6 for ``leg-edge-ctc`` (the rank test); leg 0 alone: 3 rows,
    too few for ``leg-direction-ctc`` (a code of the kernel). The per-trial step and a
    batch (the row left by the one call, refused by its trial's step) say the same."""
    law, world, first = _stepped(name)
    R, t = sample_poses(world.truth, 1, rng=np.random.default_rng(9), max_translation=0.01)
    few = np.array([True, False, False, name != "leg-direction-ctc", False, False])
    o = _observation(world, R[0], t[0], DT)
    visible = np.repeat(few[:, None], 2, axis=1)
    hidden = Observation(o.t, o.lengths, normals=o.normals, directions=o.directions,
                         q_dot=o.q_dot, edge_visible=visible, direction_visible=few)
    batch = registry.create(name)
    batch.reset_batch([law.context])
    batch.step_batch(ObservationBatch.of(first))  # as the trial's: the same guess
    cmd = law.step(hidden)
    rows = batch.step_batch(ObservationBatch.of(hidden))
    assert cmd.reason is not None and rows.reasons == [cmd.reason]
    np.testing.assert_array_equal(cmd.values, np.zeros(6))
    np.testing.assert_array_equal(rows.values, np.zeros((1, 6)))
    if name == "vision-ctc":
        assert cmd.reason == f"{name}: {status_reason(Status.TOO_FEW_LEGS, legs=[0, 3])}"
    elif name == "leg-direction-ctc":
        assert cmd.reason == f"{name}: {status_reason(Status.TOO_FEW_ROWS, rows=3)}"
    else:
        assert cmd.reason.startswith(f"{name}: Jacobian of rank < 6 (condition "), cmd.reason


def test_every_code_has_its_own_words_and_ok_has_none() -> None:
    words = {code: status_reason(code, residual=1e-9, condition=1e9, rows=5, legs=[1, 2])
             for code in Status if code is not Status.OK}
    assert len(set(words.values())) == len(words)  # no two codes worded alike
    assert "did not converge (residual 1e-09)" in words[Status.NOT_CONVERGED]
    assert "condition 1e+09" in words[Status.RANK_DEFICIENT]
    assert "5 task rows" in words[Status.TOO_FEW_ROWS]
    assert "only 2 legs seen (legs [1, 2])" in words[Status.TOO_FEW_LEGS]
    with pytest.raises(ValueError, match="status 0"):
        status_reason(Status.OK)
    with pytest.raises(ValueError):
        status_reason(42)
