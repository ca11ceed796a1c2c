"""Calibration files of every kind: OpenCV FileStorage (full model, fisheye), ROS
camera_info (plumb_bob, rational_polynomial, equidistant) and Kalibr camchain.yaml
(pinhole-radtan, pinhole-equi, pinhole-none, omni-radtan, ds, eucm): round trips, what
OpenCV reads back, and refusals that name the key."""

from __future__ import annotations

import logging
from pathlib import Path

import cv2
import numpy as np
import pytest

from hexapod import Transform
from hexapod.exceptions import ConfigFileError
from hexapod.se3 import exp_so3
from vision import load_camera
from vision.cameras import (
    Camera,
    DoubleSphereCamera,
    ExtendedUnifiedCamera,
    FisheyeCamera,
    PerspectiveCamera,
    UnifiedCamera,
    read_calibration,
    save_kalibr_camera,
    save_opencv_camera,
    save_ros_camera_info,
)
from vision.exceptions import CameraError

W, H = 1280, 800
K = np.array([[420.0, 0.0, 645.3], [0.0, 424.0, 396.8], [0.0, 0.0, 1.0]])
POSE = Transform(exp_so3(np.array([0.3, -0.2, 1.1])), np.array([0.12, -0.05, 0.8]))
FULL14 = np.array([0.12, -0.03, 4e-4, -2e-4, 0.004, 0.05, -0.01, 0.002, 1e-3, -5e-4,
                   2e-4, 1e-4, 0.01, -0.008])
RATIONAL = np.array([0.3, 0.05, 4e-4, -2e-4, 0.004, 0.6, 0.12, 0.01])
KB = np.array([0.032, -0.011, 0.0024, -0.0004])


def _cameras() -> dict[str, Camera]:
    Ks = K.copy()
    Ks[0, 1] = 0.8
    return {
        "plumb_bob": PerspectiveCamera(K, W, H, POSE, distortion=(-0.2, 0.05, 4e-4, -2e-4,
                                                                  -0.004)),
        "rational": PerspectiveCamera(K, W, H, POSE, distortion=RATIONAL),
        "full14": PerspectiveCamera(K, W, H, POSE, distortion=FULL14),
        "fisheye": FisheyeCamera(K, W, H, POSE, distortion=KB),
        "fisheye-skew": FisheyeCamera(Ks, W, H, POSE, distortion=KB),
        "unified": UnifiedCamera(K, 0.9, W, H, POSE, distortion=(-0.05, 0.01, 1e-4, 2e-4)),
        "ideal": PerspectiveCamera(K, W, H, POSE),
        "ds": DoubleSphereCamera(K, W, H, POSE, distortion=(-0.18, 0.59)),
        "eucm": ExtendedUnifiedCamera(K, W, H, POSE, distortion=(0.63, 1.07)),
    }


def _same(a: Camera, b: Camera) -> None:
    assert type(a) is type(b)
    assert np.array_equal(a.K, b.K) and np.array_equal(a.distortion, b.distortion)
    assert (a.width, a.height, a.xi) == (b.width, b.height, b.xi)
    assert np.array_equal(a.camera_from_base.rotation, b.camera_from_base.rotation)


# ---------------------------------------------------------------- OpenCV FileStorage
@pytest.mark.parametrize("ext", [".yml", ".xml", ".json"])
@pytest.mark.parametrize("name", ["plumb_bob", "rational", "full14", "fisheye",
                                  "fisheye-skew", "unified", "ideal"])
def test_opencv_files_round_trip(tmp_path: Path, name: str, ext: str) -> None:
    cam = _cameras()[name]
    path = tmp_path / f"{name}{ext}"
    save_opencv_camera(cam, path)
    back = load_camera(path, camera_from_base=POSE)
    _same(back, cam)
    # What OpenCV reads back projects as our camera.
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    Kf, Df = fs.getNode("camera_matrix").mat(), fs.getNode("distortion_coefficients").mat()
    fisheye = fs.getNode("fisheye_model")
    flag = None if fisheye.empty() else fisheye.real()
    fs.release()
    X = np.random.default_rng(0).normal(size=(200, 3)) * [0.3, 0.3, 0.1] + [0.0, 0.0, 1.0]
    ours = back.project(X)[0]
    if name.startswith("fisheye"):
        assert flag == 1
        ref = cv2.fisheye.projectPoints(X.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), Kf,
                                        Df.ravel(), alpha=Kf[0, 1] / Kf[0, 0])[0]
    elif name == "unified":
        return
    else:
        assert flag is None
        ref = cv2.projectPoints(X.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), Kf, Df)[0]
    assert np.abs(ours - ref.reshape(-1, 2)).max() < 1e-9


def test_models_opencv_does_not_have_are_refused(tmp_path: Path) -> None:
    for name in ("ds", "eucm"):
        with pytest.raises(CameraError, match="Kalibr") as info:
            save_opencv_camera(_cameras()[name], tmp_path / "x.yml")
        assert info.value.field == "kind"


# ---------------------------------------------------------------- ROS camera_info
@pytest.mark.parametrize("name,model", [("plumb_bob", "plumb_bob"),
                                        ("rational", "rational_polynomial"),
                                        ("fisheye", "equidistant"), ("ideal", "plumb_bob")])
def test_ros_camera_info_round_trip(tmp_path: Path, name: str, model: str) -> None:
    cam = _cameras()[name]
    path = tmp_path / "camera_info.yaml"
    save_ros_camera_info(cam, path)
    text = path.read_text()
    assert f"distortion_model: {model}\n" in text and "projection_matrix:" in text
    assert not text.startswith("%")  # as ROS writes it: no OpenCV header
    _same(load_camera(path, camera_from_base=POSE), cam)


@pytest.mark.parametrize("name", ["full14", "unified", "ds", "eucm"])
def test_ros_refuses_models_it_has_no_name_for(tmp_path: Path, name: str) -> None:
    with pytest.raises(ConfigFileError, match="no ROS distortion_model") as info:
        save_ros_camera_info(_cameras()[name], tmp_path / "c.yaml")
    assert info.value.key == "distortion_model"


# ---------------------------------------------------------------- Kalibr
@pytest.mark.parametrize("name,models", [
    ("plumb_bob4", ("pinhole", "radtan")), ("fisheye", ("pinhole", "equidistant")),
    ("ideal", ("pinhole", "none")), ("unified", ("omni", "radtan")), ("ds", ("ds", "none")),
    ("eucm", ("eucm", "none"))])
def test_kalibr_camchain_round_trip(tmp_path: Path, name: str, models: tuple[str, str]
                                    ) -> None:
    import yaml

    cams = _cameras()
    cams["plumb_bob4"] = PerspectiveCamera(K, W, H, POSE, distortion=(-0.2, 0.05, 4e-4, -2e-4))
    cam = cams[name]
    path = tmp_path / "camchain.yaml"
    save_kalibr_camera(cam, path)
    block = yaml.safe_load(path.read_text())["cam0"]
    assert (block["camera_model"], block["distortion_model"]) == models
    assert block["resolution"] == [W, H]
    _same(load_camera(path, camera_from_base=POSE), cam)


CHAIN = """\
cam0:
  camera_model: ds
  intrinsics: [-0.18, 0.59, 420.0, 424.0, 645.3, 396.8]
  distortion_model: none
  distortion_coeffs: []
  resolution: [1280, 800]
  rostopic: /cam0/image_raw
  cam_overlaps: [1]
  T_cam_imu:
  - [0.0, -1.0, 0.0, 0.01]
  - [1.0, 0.0, 0.0, 0.02]
  - [0.0, 0.0, 1.0, -0.03]
  - [0.0, 0.0, 0.0, 1.0]
cam1:
  camera_model: pinhole
  intrinsics: [460.1, 459.3, 367.2, 248.4]
  distortion_model: equidistant
  distortion_coeffs: [0.0034, 0.0067, -0.0071, 0.0019]
  resolution: [752, 480]
  T_cn_cnm1:
  - [1.0, 0.0, 0.0, -0.11]
  - [0.0, 1.0, 0.0, 0.0]
  - [0.0, 0.0, 1.0, 0.0]
  - [0.0, 0.0, 0.0, 1.0]
  T_cam_imu:
  - [1.0, 0.0, 0.0, 0.0]
  - [0.0, 1.0, 0.0, 0.0]
  - [0.0, 0.0, 1.0, 0.0]
  - [0.0, 0.0, 0.0, 1.0]
"""


def test_kalibr_chain_says_what_it_reads(tmp_path: Path, caplog: pytest.LogCaptureFixture
                                         ) -> None:
    path = tmp_path / "camchain-imucam.yaml"
    path.write_text(CHAIN)
    with caplog.at_level(logging.INFO, logger="vision.cameras.files.kalibr"):
        cam = load_camera(path, camera_from_base=POSE)
    assert isinstance(cam, DoubleSphereCamera)
    assert cam.distortion.tolist() == [-0.18, 0.59] and (cam.width, cam.height) == (1280, 800)
    # The IMU pose is not taken for the robot pose: the given one is kept.
    assert np.allclose(cam.camera_from_base.as_matrix(), POSE.as_matrix())
    assert "cam0.T_cam_imu" in caplog.text and "not a pose in the robot's frame" in caplog.text
    cal = read_calibration(path, camera="cam1")
    assert cal.kind == "fisheye" and cal.distortion.tolist() == [0.0034, 0.0067, -0.0071,
                                                                 0.0019]
    assert any("T_cn_cnm1" in n for n in cal.notes) and any("T_cam_imu" in n
                                                            for n in cal.notes)
    # A camera TOML file may take its intrinsics from the chain.
    toml = tmp_path / "robot_camera.toml"
    toml.write_text('opencv = "camchain-imucam.yaml"\n[camera_from_base]\n'
                    "translation_mm = [0.0, 0.0, 500.0]\n")
    from_toml = Camera.from_toml(toml)
    assert isinstance(from_toml, DoubleSphereCamera) and from_toml.width == 1280


@pytest.mark.parametrize("edit,key,match", [
    (("camera_model: ds", "camera_model: fisheye"), "cam0.camera_model", "not supported"),
    (("distortion_model: none", "distortion_model: fov"), "cam0.distortion_model",
     "ds-fov is not supported"),
    (("[-0.18, 0.59, 420.0", "[0.59, 420.0"), "cam0.intrinsics", "expected 6 numbers"),
    (("resolution: [1280, 800]", "resolution: [1280.5, 800]"), "cam0.resolution",
     "width, height"),
    (("  resolution: [1280, 800]\n", ""), "cam0.resolution", "missing"),
    (("[-0.18, 0.59,", "[1.5, 0.59,"), None, "xi"),
])
def test_kalibr_refusals_name_the_key(tmp_path: Path, edit: tuple[str, str],
                                      key: str | None, match: str) -> None:
    path = tmp_path / "camchain.yaml"
    path.write_text(CHAIN.replace(*edit, 1))
    error = ConfigFileError if key else CameraError
    with pytest.raises(error, match=match) as info:
        load_camera(path)
    if key:
        assert info.value.key == key  # type: ignore[union-attr]
    with pytest.raises(ConfigFileError, match="no camera 'cam7'") as info2:
        read_calibration(tmp_path / "camchain.yaml", camera="cam7")
    assert info2.value.key == "cam7"
