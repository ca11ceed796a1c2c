"""The task-space computed-torque laws' analytic reference terms against central
differences.

The laws take ``e_t`` and ``e_tt`` from the trajectory's own twist and twist rate
(:meth:`controllers.tasks.Task.reference_terms`; for the feature laws, the anchored
model features' rates by the chain rule, :mod:`controllers.solvers.reference_motion`).
:func:`tests.controllers.ctc_solver_oracle.reference_terms` differentiates the task
along the reference numerically (its own test checks it against the total motion); the
two must agree to ``O(h^2)``: the discrepancy falls about four times when ``h`` halves
and stays far below the terms themselves, so a sign or frame error (a twist taken in the
wrong frame, a rate of the wrong sign, the anchoring rotation left out) fails.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from controllers import registry
from controllers.base import Observation
from controllers.feature_ctc import FeatureCTC
from controllers.solvers.computed_torque import task_in_model_twist
from controllers.task_ctc import TaskComputedTorque
from controllers.tracking import anchor_goals, model_goals
from hexapod import deltalab, sample_poses
from hexapod.dynamics import DynamicModel
from hexapod.kinematics import legs_in_frame
from hexapod.se3 import log_so3
from hexapod.trajectory import PoseTrajectory
from tests.controllers.ctc_solver_oracle import reference_terms
from tests.controllers.ctc_world import CtcWorld, perturbed
from tests.controllers.task_ctc_oracles import (
    feature_reference,
    numpy_desired_at,
    numpy_measure,
)
from vision.legs import leg_edges

LAWS = ("cartesian-ctc", "vision-ctc", "leg-edge-ctc", "leg-direction-ctc")


def _setup(name: str, shape: str) -> tuple[TaskComputedTorque, CtcWorld]:
    """A law on a nominal model 1 mm off the truth tracking a quintic circle or line."""
    truth = deltalab()
    world = CtcWorld.make(truth, perturbed(truth, 1e-3, 4))
    R, t = sample_poses(truth, 2, rng=np.random.default_rng(21), max_translation=0.01,
                        max_angle=np.deg2rad(3))
    if shape == "circle":
        ref = PoseTrajectory("circle", "quintic", R[0], t[0], speed=0.03, acceleration=0.2,
                             radius=0.01, plane="xz")
    else:
        ref = PoseTrajectory("line", "quintic", R[0], t[0], speed=0.02, acceleration=0.1,
                             goal_rotation=R[1], goal_translation=t[1], angular_speed=0.05,
                             angular_acceleration=0.2)
    law = registry.create(name)
    assert isinstance(law, TaskComputedTorque)
    law.reset(world.context(world.goal(R[1], t[1]), reference=ref))
    return law, world


def _measured(law: TaskComputedTorque, world: CtcWorld, rng: np.random.Generator
              ) -> tuple[object, np.ndarray]:
    R, t = sample_poses(world.truth, 1, rng=rng, max_translation=0.02,
                        max_angle=np.deg2rad(4))
    twist = np.concatenate([rng.normal(0, 0.02, 3), rng.normal(0, 0.1, 3)])
    legs = legs_in_frame(world.truth, R[0], t[0], world.camera.camera_from_base)
    normals, _ = leg_edges(legs.base_points, legs.directions, world.truth.leg_radius)
    qd = DynamicModel(world.truth).legs_batch(R, t, twist[None])[0][0]
    obs = Observation(0.0, legs.lengths, normals=normals, directions=legs.directions,
                      q_dot=qd)
    m = numpy_measure(law, obs, np.asarray(obs.lengths), qd)
    assert not isinstance(m, str)
    _, tau_s, _ = task_in_model_twist(np.zeros((1, 6)), m.translation, m.twist, m.frame)
    return m, tau_s


@pytest.mark.parametrize("shape", ["circle", "line"])
@pytest.mark.parametrize("name", LAWS)
def test_analytic_reference_terms_match_central_differences(name: str, shape: str) -> None:
    law, world = _setup(name, shape)
    rng = np.random.default_rng(5)
    duration = float(law.reference.duration)
    for tr in (0.13 * duration, 0.5 * duration + 0.0071, 0.81 * duration):
        m, tau_s = _measured(law, world, rng)
        task, rate, acc = numpy_desired_at(law, tr)
        assert rate is not None and acc is not None
        e_t, e_tt = (x[0] for x in task.reference_terms(m.state, tau_s[None], rate[None],
                                                        acc[None]))
        gaps = []
        for h in (2e-3, 1e-3):
            c_t, c_tt = reference_terms(lambda k, h=h, tr=tr: numpy_desired_at(law, tr + k * h)[0],
                                        m.state, tau_s, step=h)
            gaps.append((np.abs(e_t - c_t).max(), np.abs(e_tt - c_tt).max()))
        (gt2, gtt2), (gt1, gtt1) = gaps
        # far below the terms themselves: a sign or frame error would be of their size
        assert gt1 < 1e-5 * np.abs(e_t).max() + 1e-12, (gt1, np.abs(e_t).max())
        assert gtt1 < 1e-4 * np.abs(e_tt).max(), (gtt1, np.abs(e_tt).max())
        # second order in h: halving h divides the gap by about four
        assert 3.0 < gt2 / gt1 < 5.0, (gt2, gt1)
        assert 3.0 < gtt2 / gtt1 < 5.0, (gtt2, gtt1)


def test_vision_reference_is_anchored_at_the_taught_goal() -> None:
    """The anchoring offset is not the identity under the calibration error (so the test
    above checks its twist rotation), and the anchored reference ends at the taught pose."""
    law, _ = _setup("vision-ctc", "line")
    offset = law._offset
    assert offset is not None
    assert np.linalg.norm(log_so3(offset.rotation)) > 1e-4
    taught = law._taught(law.context.goal)
    assert taught is not None
    end = law.pose_reference(float(law.reference.duration) + 1.0)
    np.testing.assert_allclose(end[0:9].reshape(3, 3), taught[0], atol=1e-12)
    np.testing.assert_allclose(end[9:12], taught[1], atol=1e-12)


@pytest.mark.parametrize("name", ["leg-edge-ctc", "leg-direction-ctc"])
def test_anchored_features_equal_the_numpy_model(name: str) -> None:
    """The symbolic model of the desired features (:mod:`controllers.solvers.
    reference_motion`) against :func:`controllers.tracking.model_goals` and
    :func:`~controllers.tracking.anchor_goals` (the camera model of :mod:`vision.legs`)."""
    law, _ = _setup(name, "circle")
    assert isinstance(law, FeatureCTC) and law.context is not None
    times = np.linspace(0.0, float(law.reference.duration) + 0.1, 17)
    rows = law.feature_rows(times)
    sample = law.reference.at(np.append(times, float(law.reference.duration) + 1.0))
    goals = model_goals(law.context, sample.rotation, sample.translation, fields=(law.key,))
    anchor_goals(goals, replace(law.context.goal, **{law.key: law._taught}))
    numpy = goals[law.key][:-1].reshape(len(times), -1)
    assert np.isfinite(numpy).all()
    np.testing.assert_allclose(rows[:, 0], numpy, rtol=0, atol=1e-12)
    # at rest before the start and after the end, moving in between
    assert np.abs(rows[0, 1:]).max() == 0.0 and np.abs(rows[-1, 1:]).max() == 0.0
    assert np.abs(rows[8, 1]).max() > 1e-3


def test_a_new_taught_goal_reanchors_the_feature_reference() -> None:
    """The reference's features end at the taught ones, also after a retarget with the
    same reference (the grid of the old goal is dropped)."""
    law, world = _setup("leg-edge-ctc", "circle")
    assert isinstance(law, FeatureCTC)
    end = 0.02 * (np.ceil(float(law.reference.duration) / 0.02) + 5)  # on the grid, at rest
    first = feature_reference(law, end)[0].reshape(6, 2, 3)
    np.testing.assert_allclose(first, law.context.goal.normals, atol=1e-12)
    R, t = sample_poses(world.truth, 1, rng=np.random.default_rng(9), max_translation=0.01)
    goal = world.goal(R[0], t[0])
    law.retarget(goal)
    second = feature_reference(law, end)[0].reshape(6, 2, 3)
    np.testing.assert_allclose(second, goal.normals, atol=1e-12)
    assert np.abs(second - first).max() > 1e-3
