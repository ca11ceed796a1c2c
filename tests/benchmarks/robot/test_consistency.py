"""The camera check (benchmarks.robot.consistency): the camera pose from rendered images
(real rendering and edge detection) against the encoder pose, the blind timer on a test
clock."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchmarks.exceptions import BenchmarkError
from benchmarks.robot.consistency import (
    DEFAULT_CONSISTENCY_DEG,
    DEFAULT_CONSISTENCY_MM,
    CameraCheck,
    visual_pose,
)
from benchmarks.robot.exits import ServoExit, SessionStop
from hexapod.fk import forward_kinematics
from hexapod.geometry import deltalab
from hexapod.se3 import exp_so3
from vision.cameras import front_camera
from vision.feature_cameras import Features, SimCamera

G = deltalab()
CAM = front_camera(G)
BASE = CAM.camera_from_base.apply(G.base_points)
MID = np.full(6, np.mean(G.stroke))
SOL = forward_kinematics(G, MID)


class Clock:
    """A clock the test moves [s]."""

    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def _features(rotation: np.ndarray, translation: np.ndarray, seed: int = 0) -> Features:
    f = SimCamera(CAM, G, seed=seed).measure(rotation, translation)
    assert f is not None
    return f


def _check(clock: Clock | None = None, **kw: object) -> CameraCheck:
    return CameraCheck(G, BASE, camera="test",
                       clock=clock or Clock(), **kw)  # type: ignore[arg-type]


def test_the_camera_pose_of_a_consistent_image_is_near_the_encoder_pose() -> None:
    f = _features(SOL.rotation, SOL.translation)
    res = _check().compare(0, MID, SOL.rotation, SOL.translation, f.normals, f.edge_visible)
    assert res.legs == (0, 1, 2, 3, 4, 5)
    # the pixel noise and the detector: millimetres, well within the defaults
    assert res.distance < DEFAULT_CONSISTENCY_MM * 1e-3 / 2
    assert res.angle < math.radians(DEFAULT_CONSISTENCY_DEG) / 2


def test_the_summary_of_a_check_that_saw_no_period_says_so() -> None:
    """Before any period (a move refused at the start): "no period checked", not "0
    periods checked, largest disagreement 0.00 mm" (no check read as perfect agreement);
    after one, the count and the largest disagreement."""
    check = _check()
    assert check.summary() == "camera check: no period checked (limits 10 mm, 3 deg)"
    f = _features(SOL.rotation, SOL.translation)
    check.compare(0, MID, SOL.rotation, SOL.translation, f.normals, f.edge_visible)
    assert check.summary().startswith("camera check: 1 periods checked, largest "
                                      "disagreement ")


def test_an_image_of_another_pose_stops_with_both_poses() -> None:
    # the camera sees the platform 25 mm aside and turned 1 deg; the encoders say mid-stroke
    R2 = exp_so3(np.radians([0.0, 0.0, 1.0])) @ SOL.rotation
    f = _features(R2, SOL.translation + np.array([0.025, 0.0, 0.0]))
    check = _check()
    with pytest.raises(SessionStop) as info:
        check.compare(0, MID, SOL.rotation, SOL.translation, f.normals, f.edge_visible)
    stop = info.value
    assert stop.code == ServoExit.SAFETY
    assert "at start, before any motion" in stop.reason
    assert "camera pose (2" in stop.reason  # x about 20-25 mm
    assert f"encoder pose ({SOL.translation[0] * 1e3:.2f}," in stop.reason
    assert "limits 10 mm, 3 deg" in stop.reason
    assert check.worst_distance > 0.015
    # the same image at a later period says so
    with pytest.raises(SessionStop, match="at period 7"):
        check.compare(7, MID, SOL.rotation, SOL.translation, f.normals, f.edge_visible)


def test_as_a_period_check_the_encoder_pose_is_the_forward_kinematics_of_the_lengths(
        ) -> None:
    """The session's seam (check(step, lengths, features)): the encoder pose comes from
    the lengths, so an image of the mid-stroke pose agrees with the mid-stroke lengths,
    and the lengths of a pose 25 mm aside disagree with it, the message giving that
    pose's forward kinematics as the encoder pose."""
    from hexapod.kinematics import inverse_kinematics

    f = _features(SOL.rotation, SOL.translation)
    check = _check()
    check(0, MID, f)  # agrees: no stop
    assert check.checked == 1 and check.worst_distance < DEFAULT_CONSISTENCY_MM * 1e-3 / 2
    aside = SOL.translation + np.array([0.025, 0.0, 0.0])
    q_aside = inverse_kinematics(G, SOL.rotation, aside)
    with pytest.raises(SessionStop) as info:
        check(1, q_aside, f)
    assert info.value.code == ServoExit.SAFETY
    assert "at period 1" in info.value.reason
    assert f"encoder pose ({aside[0] * 1e3:.2f}, {aside[1] * 1e3:.2f}, " \
           f"{aside[2] * 1e3:.2f}) mm" in info.value.reason
    assert check.worst_distance > 0.015
    # a lost frame is blind, not a stop, before the timeout
    check(2, MID, None)
    assert check.checked == 2


def test_a_threshold_stops_on_rotation_alone() -> None:
    R2 = exp_so3(np.radians([0.0, 0.0, 6.0])) @ SOL.rotation
    f = _features(R2, SOL.translation)
    with pytest.raises(SessionStop, match=r"deg apart"):
        _check().compare(3, MID, SOL.rotation, SOL.translation, f.normals, f.edge_visible)
    # with a looser rotation limit it passes
    res = _check(max_angle=math.radians(10), max_distance=0.05).compare(
        3, MID, SOL.rotation, SOL.translation, f.normals, f.edge_visible)
    assert math.radians(3) < res.angle < math.radians(10)


def test_hidden_legs_use_the_visible_ones_and_too_few_is_blind() -> None:
    f = _features(SOL.rotation, SOL.translation)
    vis = f.edge_visible.copy()
    vis[[0, 3]] = False  # legs 0 and 3 hidden
    res = _check().compare(0, MID, SOL.rotation, SOL.translation, f.normals, vis)
    assert res.legs == (1, 2, 4, 5) and res.why_blind is None
    # a hidden leg with another pose: still caught with the four seen
    f2 = _features(SOL.rotation, SOL.translation + np.array([0.0, 0.03, 0.0]))
    with pytest.raises(SessionStop, match=r"legs 1, 2, 4, 5\)"):
        _check().compare(1, MID, SOL.rotation, SOL.translation, f2.normals, vis)
    vis[[1, 2, 4]] = False  # one leg left
    res = _check().compare(1, MID, SOL.rotation, SOL.translation, f.normals, vis)
    assert res.legs == () and "only 1 legs seen" in str(res.why_blind)
    assert math.isnan(res.distance)


def test_the_blind_camera_stops_after_its_timeout() -> None:
    clock = Clock()
    check = _check(clock, blind_timeout=2.0)
    f = _features(SOL.rotation, SOL.translation)
    check.compare(0, MID, SOL.rotation, SOL.translation, f.normals, f.edge_visible)
    for k in range(1, 20):  # lost frames for 1.9 s: not yet
        clock.now = 0.1 * k
        assert check.compare(k, MID, SOL.rotation, SOL.translation, None, None).why_blind == \
            "no image (lost frame)"
    clock.now = 2.05
    with pytest.raises(SessionStop) as info:
        check.compare(20, MID, SOL.rotation, SOL.translation, None, None)
    assert info.value.code == ServoExit.SAFETY
    assert "no platform pose for 2.05 s (--blind-timeout-s 2" in info.value.reason
    # a pose in between restarts the timer
    clock.now = 0.0
    check = _check(clock, blind_timeout=2.0)
    for k, now in enumerate([0.0, 1.5, 3.0, 4.4]):
        clock.now = now
        if k == 2:
            check.compare(k, MID, SOL.rotation, SOL.translation, f.normals, f.edge_visible)
        else:
            check.compare(k, MID, SOL.rotation, SOL.translation, None, None)


def test_a_recording_blind_at_start_is_refused() -> None:
    check = _check(must_agree_at_start=True)
    with pytest.raises(SessionStop) as info:
        check.compare(0, MID, SOL.rotation, SOL.translation, np.full((6, 2, 3), np.nan),
              np.zeros((6, 2), bool))
    assert info.value.code == ServoExit.REFUSED
    assert "only 0 legs seen" in info.value.reason
    # a live camera blind at start waits (the blind timer)
    assert _check().compare(0, MID, SOL.rotation, SOL.translation, None, None).legs == ()


@pytest.mark.parametrize(("kw", "fragment"), [
    ({"max_distance": 0.0}, "--consistency-mm must be a positive number of mm, got 0"),
    ({"max_angle": math.nan}, "--consistency-deg must be a positive number of deg, got nan"),
    ({"blind_timeout": -1.0}, "--blind-timeout-s must be a positive number of s, got -1"),
])
def test_bad_thresholds_are_refused(kw: dict[str, float], fragment: str) -> None:
    with pytest.raises(BenchmarkError, match=fragment):
        _check(**kw)


def test_visual_pose_refuses_collinear_legs() -> None:
    f = _features(SOL.rotation, SOL.translation)
    assert isinstance(visual_pose(f.normals, f.edge_visible, MID, BASE, G.platform_points,
                                  CAM.camera_from_base.inverse()), tuple)
    # three platform points on one line: no pose
    pts = np.array(G.platform_points, float)
    pts[:3] = [[0.0, 0.0, 0.0], [0.01, 0.0, 0.0], [0.02, 0.0, 0.0]]
    vis = f.edge_visible.copy()
    vis[3:] = False
    why = visual_pose(f.normals, vis, MID, BASE, pts, CAM.camera_from_base.inverse())
    assert isinstance(why, str) and "collinear" in why


def test_the_calibrated_base_points_place_the_camera() -> None:
    """A camera whose file pose is 2 deg off: the calibrated base points (seen from where
    it really is) place it, and the consistent image agrees; the file's pose would have
    put the camera pose centimetres away."""
    from hexapod.kinematics import Transform

    tilt = Transform(exp_so3(np.radians([2.0, 0.0, 0.0])), np.zeros(3))
    true_pose = Transform(tilt.rotation @ CAM.camera_from_base.rotation,
                          tilt.rotation @ CAM.camera_from_base.translation)
    f = SimCamera(CAM.replace(camera_from_base=true_pose), G).measure(SOL.rotation, SOL.translation)
    assert f is not None
    calibrated = true_pose.apply(G.base_points)
    res = CameraCheck(G, calibrated, camera="test", clock=Clock()).compare(
        0, MID, SOL.rotation, SOL.translation, f.normals, f.edge_visible)
    assert res.distance < 0.005 and res.angle < math.radians(1)
    # the nominal base points (the file's pose, 2 deg off) see a disagreement
    with pytest.raises(SessionStop, match="disagrees"):
        _check().compare(0, MID, SOL.rotation, SOL.translation, f.normals, f.edge_visible)
