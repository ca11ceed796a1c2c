"""The estimated base points a controller is given are checked at reset: the unit and
frame slips a calibration error cannot explain are refused with the figures, while
calibration errors far above the studies' are accepted."""

from __future__ import annotations

import numpy as np
import pytest

from controllers import registry
from controllers.base import ControllerContext, Goal
from controllers.exceptions import ContextError
from hexapod import deltalab
from hexapod.kinematics import Transform
from hexapod.se3 import exp_so3
from hexapod.workspace import home_pose
from vision.cameras import front_camera
from vision.legs import observe_legs

#: The built-in controllers that read ``context.base_points`` (the image laws and the
#: feature computed-torque laws).
READERS = ["leg-edge", "leg-direction", "leg-edge-qp", "leg-edge-mpc", "leg-edge-ctc",
           "leg-direction-ctc", "leg-edge-force-mpc", "vision-ctc"]

ROBOT = deltalab()
CAMERA = front_camera(ROBOT)


def _goal() -> Goal:
    R, t = home_pose(ROBOT)[:2]
    o = observe_legs(CAMERA, ROBOT, R, t)
    return Goal(normals=o.normals, lines=o.lines, directions=o.directions,
                lengths=o.lengths, edge_visible=o.edge_visible, rotation=R, translation=t)


def _reset(name: str, base_points: np.ndarray, camera: object = CAMERA) -> None:
    registry.create(name).reset(ControllerContext(base_points, ROBOT, camera, 0.02,
                                                  _goal()))


def _in_camera_frame() -> np.ndarray:
    return CAMERA.camera_from_base.apply(ROBOT.base_points)


@pytest.mark.parametrize("name", READERS)
def test_base_points_in_millimetres_are_refused_with_the_factor(name: str) -> None:
    with pytest.raises(ContextError, match=r"base_points.*1000 times as far apart.*"
                                           r"millimetres\? SI units: metres"):
        _reset(name, _in_camera_frame() * 1000.0)


@pytest.mark.parametrize("name", READERS)
def test_base_points_in_the_base_frame_are_refused(name: str) -> None:
    with pytest.raises(ContextError, match=r"base_points.*in the base frame\? They are "
                                           r"within 0\.0 mm .* mm from those seen through"):
        _reset(name, ROBOT.base_points.copy())


@pytest.mark.parametrize("name", READERS)
def test_base_points_not_finite_or_of_another_shape_are_refused(name: str) -> None:
    A = _in_camera_frame()
    A[2, 1] = np.nan
    with pytest.raises(ContextError, match=r"shape \(6, 3\) with a value not finite"):
        _reset(name, A)
    with pytest.raises(ContextError, match=r"expected 6x3 finite values \[m\], got shape "
                                           r"\(3, 6\)"):
        _reset(name, _in_camera_frame().T)


@pytest.mark.parametrize("name", ["leg-edge", "leg-edge-ctc"])
def test_large_calibration_errors_are_accepted(name: str) -> None:
    """30 mm per coordinate on every point and a camera pose 3 deg and 30 mm off (the
    calibration-map study's largest errors are about these), drawn 50 times."""
    rng = np.random.default_rng(11)
    cam = CAMERA.camera_from_base
    for _ in range(50):
        off = Transform(exp_so3(rng.normal(size=3) * np.deg2rad(3.0) / np.sqrt(3)),
                        rng.normal(size=3) * 0.03)
        estimate = CAMERA.replace(camera_from_base=off.compose(cam))
        A = cam.apply(ROBOT.base_points + rng.normal(size=(6, 3)) * 0.03)
        _reset(name, A, estimate)


def test_without_a_camera_the_base_frame_is_the_camera_frame() -> None:
    """A context without a camera (the joint-space and model-based tests' kind) gives the
    base points in the base frame; millimetres are refused all the same."""
    _reset("leg-direction", ROBOT.base_points.copy(), None)
    with pytest.raises(ContextError, match="millimetres"):
        _reset("leg-direction", ROBOT.base_points * 1000.0, None)
