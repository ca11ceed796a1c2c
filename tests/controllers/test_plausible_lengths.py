"""Every built-in controller's per-trial step refuses leg lengths no leg of the robot can
have (millimetres for metres, a sign slip), before commanding anything, and steps on
lengths near the stroke as before."""

from __future__ import annotations

import numpy as np
import pytest

from controllers import BUILTIN_SPECS, registry
from controllers.base import ControllerContext, Goal, Observation
from controllers.plausible import implausible_lengths
from hexapod import deltalab
from hexapod.se3 import exp_so3
from hexapod.workspace import home_pose
from vision.cameras import front_camera
from vision.legs import observe_legs

ROBOT = deltalab()
CAMERA = front_camera(ROBOT)
R0, T0 = home_pose(ROBOT)[:2]
SEEN = observe_legs(CAMERA, ROBOT, R0, T0)
GOAL = Goal(normals=SEEN.normals, lines=SEEN.lines, directions=SEEN.directions,
            lengths=SEEN.lengths, edge_visible=SEEN.edge_visible, rotation=R0,
            translation=T0)
NOW = observe_legs(CAMERA, ROBOT, exp_so3(np.array([0.02, -0.01, 0.03])) @ R0,
                   T0 + np.array([0.005, 0.0, 0.0]))


def _stepped(name: str, lengths: np.ndarray) -> object:
    law = registry.create(name)
    law.reset(ControllerContext(CAMERA.camera_from_base.apply(ROBOT.base_points), ROBOT,
                                CAMERA, 0.02, GOAL))
    return law.step(Observation(0.0, lengths, normals=NOW.normals, lines=NOW.lines,
                                directions=NOW.directions, edge_visible=NOW.edge_visible,
                                q_dot=np.zeros(6)))


@pytest.mark.parametrize("name", sorted(BUILTIN_SPECS))
def test_lengths_in_millimetres_or_negative_are_refused_by_every_controller(name: str
                                                                             ) -> None:
    cmd = _stepped(name, NOW.lengths * 1000.0)
    assert not cmd.ok  # type: ignore[attr-defined]
    assert cmd.reason == (  # type: ignore[attr-defined]
        f"lengths: leg 0 reads {NOW.lengths[0] * 1000:.6g} m, where no leg of the nominal "
        "robot can be (its stroke 345 to 485 mm) (millimetres? SI units: metres)")
    values = cmd.forces if cmd.forces is not None else cmd.velocities  # type: ignore[attr-defined]
    assert np.array_equal(values, np.zeros(6))
    q = NOW.lengths.copy()
    q[4] = -q[4]
    cmd = _stepped(name, q)
    assert cmd.reason is not None and cmd.reason.startswith(  # type: ignore[attr-defined]
        f"lengths: leg 4 reads {q[4]:.6g} m, where no leg")


@pytest.mark.parametrize("name", ["leg-edge", "joint-space", "model-based", "leg-edge-qp"])
def test_lengths_near_the_stroke_are_stepped(name: str) -> None:
    """50 mm beyond the stroke's end (a third of its span): a command, not this refusal."""
    q = NOW.lengths.copy()
    q[2] = ROBOT.stroke[1] + 0.05
    cmd = _stepped(name, q)
    assert cmd.reason is None or "no leg of the nominal robot" not in cmd.reason  # type: ignore[attr-defined]


def test_the_bounds_are_the_stroke_widened_by_its_span() -> None:
    stroke = (0.345, 0.485)  # span 0.14: (0.205, 0.625)
    assert implausible_lengths(np.full(6, 0.2051), stroke) is None
    assert implausible_lengths([0.6249] * 6, stroke) is None
    assert "leg 3 reads 0.204 m" in str(implausible_lengths([0.3, 0.3, 0.3, 0.204, 0.3, 0.3],
                                                            stroke))
    assert "leg 5 reads 0.626 m" in str(implausible_lengths([0.3] * 5 + [0.626], stroke))
    # not six numbers, or not finite: left to the controller's own checks
    for odd in ([0.3] * 5, None, "abcdef", [np.nan] * 6, [0.3] * 5 + [np.inf]):
        assert implausible_lengths(odd, stroke) is None


def test_another_reset_of_the_batch_leaves_the_old_bounds_out() -> None:
    """``reset`` set the bounds; ``reset_batch`` with a robot of another stroke steps
    on lengths the first robot could not have (the bounds are not carried over)."""
    law = registry.create("joint-space")
    A = CAMERA.camera_from_base.apply(ROBOT.base_points)
    law.reset(ControllerContext(A, ROBOT, CAMERA, 0.02, GOAL))
    longer = ROBOT.replace(stroke=(0.8, 1.0))
    law.reset_batch([ControllerContext(A, longer, CAMERA, 0.02, Goal(lengths=np.full(6, 0.9)))])
    cmd = law.step(Observation(0.0, np.full(6, 0.95)))
    assert cmd.ok, cmd.reason
