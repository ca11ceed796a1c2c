"""A goal no leg of the robot can reach (its lengths or its pose's legs further from the
nominal stroke than the stroke's span: millimetres for metres) is refused when it is
given, at reset or at a new goal, with the leg, the value and a hint; goals near the
stroke are taken."""

from __future__ import annotations

import numpy as np
import pytest

from controllers import registry
from controllers.base import ControllerContext, Goal
from controllers.exceptions import ContextError
from controllers.plausible import implausible_lengths, implausible_pose, plausible_range
from hexapod import deltalab
from hexapod.kinematics import inverse_kinematics
from hexapod.workspace import home_pose
from vision.cameras import front_camera
from vision.legs import observe_legs

ROBOT = deltalab()
CAMERA = front_camera(ROBOT)
R0, T0 = home_pose(ROBOT)[:2]
SEEN = observe_legs(CAMERA, ROBOT, R0, T0)
A = CAMERA.camera_from_base.apply(ROBOT.base_points)

#: The built-ins that steer to ``goal.lengths`` (the image laws read them for their
#: desired interaction matrix).
BY_LENGTHS = ["joint-space", "computed-torque", "leg-edge", "leg-direction", "leg-edge-qp",
              "leg-edge-mpc"]
#: The built-ins that steer to ``goal.rotation``/``goal.translation`` at reset.
BY_POSE = ["model-based", "cartesian-ctc"]


def _goal(**fields: object) -> Goal:
    values: dict[str, object] = dict(
        normals=SEEN.normals, lines=SEEN.lines, directions=SEEN.directions,
        edge_visible=SEEN.edge_visible, lengths=SEEN.lengths, rotation=R0, translation=T0)
    values.update(fields)
    return Goal(**values)  # type: ignore[arg-type]


def _reset(name: str, goal: Goal) -> object:
    law = registry.create(name)
    law.reset(ControllerContext(A, ROBOT, CAMERA, 0.02, goal))
    return law


@pytest.mark.parametrize("name", BY_LENGTHS)
def test_goal_lengths_in_millimetres_are_refused_at_reset_and_at_a_new_goal(name: str
                                                                            ) -> None:
    text = (rf"goal\.lengths.*leg 0 at {SEEN.lengths[0] * 1e3:.6g} m, where no leg of the "
            r"nominal robot can be \(its stroke 345 to 485 mm\) \(millimetres\? SI units: "
            r"metres\)")
    with pytest.raises(ContextError, match=text) as at_reset:
        _reset(name, _goal(lengths=SEEN.lengths * 1e3))
    law = _reset(name, _goal())
    with pytest.raises(ContextError, match=text) as at_retarget:
        law.retarget(_goal(lengths=SEEN.lengths * 1e3))  # type: ignore[attr-defined]
    # named by the controller the user made (a predictive one holds a QP law)
    assert str(at_reset.value).startswith(f"{name}: context field 'goal.lengths'")
    assert str(at_retarget.value).startswith(f"{name}: context field 'goal.lengths'")


@pytest.mark.parametrize("name", BY_POSE)
def test_a_goal_translation_in_millimetres_is_refused_with_the_hint(name: str) -> None:
    with pytest.raises(ContextError, match=r"goal\.rotation/translation.*the pose puts leg "
                                           r"\d at [\d.]+ m, where no leg .*; the "
                                           r"translation in millimetres\? SI units: metres"):
        _reset(name, _goal(translation=T0 * 1e3))


def test_a_pose_half_a_metre_off_is_refused_without_the_millimetre_hint() -> None:
    problem = implausible_pose(ROBOT, R0, T0 + np.array([0.0, 0.0, 0.5]))
    assert problem is not None and problem.startswith("the pose puts leg")
    assert "millimetres" not in problem


@pytest.mark.parametrize("name", BY_LENGTHS + BY_POSE)
def test_goals_near_the_stroke_are_taken(name: str) -> None:
    """A goal 60 mm past the stroke's end (a leg at an end stop, a calibration offset,
    well within the span of 140 mm) is the controller's to reach or refuse, not this
    check's."""
    q = SEEN.lengths.copy()
    q[3] = ROBOT.stroke[1] + 0.06
    _reset(name, _goal(lengths=q, translation=T0 + np.array([0.0, 0.0, 0.05])))


def test_the_range_is_the_stroke_widened_by_its_span_and_checked_on_every_leg() -> None:
    assert plausible_range((0.345, 0.485)) == pytest.approx((0.205, 0.625))
    assert plausible_range((0.1, 0.5)) == (0.0, 0.9)  # never below zero
    q = inverse_kinematics(ROBOT, R0, T0)
    assert implausible_lengths(q, ROBOT.stroke) is None
    for leg in range(6):
        bad = q.copy()
        bad[leg] = 0.2
        assert implausible_lengths(bad, ROBOT.stroke) == (
            f"leg {leg} at 0.2 m, where no leg of the nominal robot can be (its stroke 345 "
            "to 485 mm)")
    # not finite, not numbers: left to the callers' own checks
    assert implausible_lengths([np.nan] * 6, ROBOT.stroke) is None
    assert implausible_lengths("abc", ROBOT.stroke) is None


@pytest.mark.parametrize("name", BY_POSE)
@pytest.mark.parametrize("rotation", [R0 * 1.01, R0 @ np.diag([1.0, 1.0, -1.0])],
                         ids=["scaled", "reflection"])
def test_a_goal_rotation_that_is_not_one_is_refused(name: str, rotation: np.ndarray) -> None:
    """Both pose laws check the goal pose in one place (``goal_pose_of``): a scaled
    matrix or a reflection is no orientation (`cartesian-ctc` took them)."""
    with pytest.raises(ContextError, match=r"goal\.rotation.*not a rotation matrix "
                                           r"\(\|R\^T R - I\| = "):
        _reset(name, _goal(rotation=rotation))


@pytest.mark.parametrize("name", ["leg-edge-ctc", "leg-direction-ctc", "leg-edge-force-mpc"])
def test_a_feature_ctc_refuses_at_reset_the_goal_it_cannot_use(name: str) -> None:
    """A goal without a pose (the README's goal of features and lengths) or without a
    seen feature: the law took it at reset and refused every step after ("nominal model
    failed: ...", or "0 task rows in use (the features seen)", blaming the image); its
    siblings refuse it at reset, naming the field: these do now. Without the smooth line
    (``smooth_goal = False``) no pose is needed."""
    with pytest.raises(ContextError, match=rf"^{name}: .*'goal.rotation/translation': "
                                           r"missing"):
        _reset(name, _goal(rotation=None, translation=None))
    with pytest.raises(ContextError, match=rf"^{name}: .*no finite desired feature"):
        _reset(name, _goal(normals=np.full_like(SEEN.normals, np.nan),
                           directions=np.full_like(SEEN.directions, np.nan),
                           edge_visible=np.zeros_like(SEEN.edge_visible)))
    law = registry.create(name, smooth_goal=False)
    law.reset(ControllerContext(A, ROBOT, CAMERA, 0.02, _goal(rotation=None, translation=None)))


def test_the_latency_wrapper_names_itself_for_its_law_s_goal() -> None:
    with pytest.raises(ContextError, match=r"^latency-compensated: .*no visible desired edge"):
        _reset("latency-compensated", _goal(normals=np.full_like(SEEN.normals, np.nan),
                                            edge_visible=np.zeros_like(SEEN.edge_visible)))
