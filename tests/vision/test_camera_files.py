"""OpenCV calibration files: cameras round-tripped through files that ``cv2.FileStorage``
writes here (YAML 1.0 and 1.2, XML, JSON) with the keys of OpenCV's calibration samples,
the writer, TOML files that point to them, and the errors of bad files."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from hexapod import ConfigFileError, Transform
from hexapod.se3 import exp_so3
from vision import load_camera, load_opencv_camera, save_opencv_camera
from vision.cameras import Camera, PerspectiveCamera, UnifiedCamera
from vision.exceptions import CameraError, DistortionError

K_PER = np.array([[812.5, 0.0, 331.25], [0.0, 808.75, 243.5], [0.0, 0.0, 1.0]])
D_PER = np.array([-0.2813, 0.0712, 0.00081, -0.00047, -0.0079])
K_OMNI = np.array([[301.5, 0.75, 322.0], [0.0, 299.25, 238.5], [0.0, 0.0, 1.0]])
D_OMNI = np.array([-0.051, 0.012, 0.0011, -0.0006])
XI = 0.92
POSE = Transform(exp_so3(np.array([0.3, -0.2, 1.1])), np.array([0.12, -0.05, 0.8]))

#: OpenCV 5 writes YAML 1.2 by default and YAML 1.0 on request; OpenCV 4 writes YAML 1.0.
_YAML_1_0 = getattr(cv2, "FILE_STORAGE_FORMAT_YAML_1_0", None)
#: (extension, FileStorage flags, first line the file must start with).
FORMATS = {
    "yaml-1.2": (".yml", 0, "%YAML 1.2"),
    "yaml-1.0": (".yaml", _YAML_1_0 or 0, "%YAML:1.0"),
    "xml": (".xml", 0, "<?xml"),
    "json": (".json", 0, "{"),
}


def _write(path: Path, entries: dict[str, Any], flags: int = 0) -> Path:
    """A FileStorage file as OpenCV's samples write it (``fs << key << value``).

    An OpenCV 4 (which writes only YAML 1.0) gives the YAML 1.2 file the header OpenCV 5
    writes; the body is the same.
    """
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE | flags)
    assert fs.isOpened()
    for key, value in entries.items():
        fs.write(key, value)
    fs.release()
    text = path.read_text()
    if _YAML_1_0 is None and path.suffix == ".yml" and text.startswith("%YAML:1.0"):
        path.write_text("%YAML 1.2" + text[len("%YAML:1.0"):])
    return path


def _calibration_cpp(K: np.ndarray = K_PER, d: np.ndarray = D_PER, **extra: Any
                     ) -> dict[str, Any]:
    """The keys of samples/cpp/calibration.cpp's saveCameraParams (8x1 coefficients,
    k4..k6 zero, and the bookkeeping keys around them)."""
    d8 = np.zeros((8, 1))
    d8[: len(d), 0] = d
    entries: dict[str, Any] = {
        "calibration_time": "Sun Nov 22 10:00:00 2026", "nframes": 12, "image_width": 640,
        "image_height": 480, "board_width": 9, "board_height": 6, "square_size": 0.025,
        "flags": 0, "camera_matrix": K, "distortion_coefficients": d8,
        "avg_reprojection_error": 0.31, "per_view_reprojection_errors": np.ones((12, 1)),
        "extrinsic_parameters": np.zeros((12, 6)),
    }
    entries.update(extra)
    return entries


def _omni_calibration_cpp(K: np.ndarray = K_OMNI, d: np.ndarray = D_OMNI,
                          xi: float = XI) -> dict[str, Any]:
    """The keys of opencv_contrib's omni_calibration.cpp: no image size, 1x4 D, xi."""
    return {"calibration_time": "Sun Nov 22 10:00:00 2026", "nFrames": 9, "flags": 0,
            "camera_matrix": K, "distortion_coefficients": d.reshape(1, 4), "xi": xi,
            "extrinsic_parameters": np.zeros((9, 6)), "rms": 0.42}


def _perspective() -> PerspectiveCamera:
    return PerspectiveCamera(K_PER, 640, 480, POSE, name="cam", distortion=D_PER)


def _unified() -> UnifiedCamera:
    return UnifiedCamera(K_OMNI, XI, 640, 480, POSE, name="cam", distortion=D_OMNI)


# ---------------------------------------------------------------- reading
@pytest.mark.parametrize("fmt", list(FORMATS))
def test_perspective_file_of_calibration_cpp(tmp_path: Path, fmt: str) -> None:
    ext, flags, header = FORMATS[fmt]
    path = _write(tmp_path / f"cam{ext}", _calibration_cpp(), flags)
    assert path.read_text().startswith(header)
    cam = load_camera(path, camera_from_base=POSE)
    assert cam == _perspective()
    assert cam.name == "cam" and cam.source == str(path)
    # The same pixels as cv2.projectPoints with the file's matrices.
    X = np.array([[0.1, -0.05, 0.9], [-0.2, 0.1, 1.3]])
    rvec, _ = cv2.Rodrigues(POSE.rotation)
    ref, _ = cv2.projectPoints(X, rvec, POSE.translation, K_PER, D_PER)
    assert np.abs(cam.project_base(X)[0] - ref.reshape(-1, 2)).max() < 1e-6
    # The pose is an argument (identity by default).
    assert load_opencv_camera(path).camera_from_base.as_matrix().tolist() == np.eye(4).tolist()


@pytest.mark.parametrize("fmt", list(FORMATS))
def test_omni_file_of_omni_calibration_cpp(tmp_path: Path, fmt: str) -> None:
    ext, flags, header = FORMATS[fmt]
    path = _write(tmp_path / f"cam{ext}", _omni_calibration_cpp(), flags)
    assert path.read_text().startswith(header)
    # omni_calibration.cpp writes no image size: it must be given.
    with pytest.raises(ConfigFileError, match=r"image_width.*give width_px and height_px "
                       r"beside it.*image_size=") as info:
        load_camera(path)
    assert info.value.key == "image_width" and info.value.path == str(path)
    cam = load_camera(path, camera_from_base=POSE, image_size=(640, 480))
    assert isinstance(cam, UnifiedCamera) and cam == _unified()
    with pytest.raises(ConfigFileError, match=r"640x480.*width_px and height_px 800x600"):
        load_opencv_camera(_write(tmp_path / f"sized{ext}", {
            **_omni_calibration_cpp(), "image_width": 640, "image_height": 480}, flags),
            image_size=(800, 600))


def test_variants_written_by_opencv_tools(tmp_path: Path) -> None:
    # The camera-calibration tutorial: fisheye_model 0, 5x1 coefficients.
    tutorial = {"image_width": 640, "image_height": 480, "fisheye_model": 0,
                "camera_matrix": K_PER, "distortion_coefficients": D_PER.reshape(5, 1)}
    assert load_camera(_write(tmp_path / "t.yml", tutorial), camera_from_base=POSE) == \
        _perspective()
    # Its older versions capitalise the keys.
    old = {"image_Width": 640, "image_Height": 480, "Camera_Matrix": K_PER,
           "Distortion_Coefficients": D_PER.reshape(5, 1)}
    assert load_camera(_write(tmp_path / "old.xml", old), camera_from_base=POSE) == \
        _perspective()
    # D as the name of omnidir's coefficients, xi as a 1x1 matrix, float32 matrices.
    omni = {"image_width": 640, "image_height": 480, "K": K_OMNI.astype(np.float32),
            "D": D_OMNI.reshape(4, 1), "xi": np.array([[XI]])}
    cam = load_camera(_write(tmp_path / "omni.json", omni))
    assert isinstance(cam, UnifiedCamera) and cam.xi == XI
    assert np.allclose(cam.K, K_OMNI, rtol=1e-7) and np.array_equal(cam.distortion, D_OMNI)
    # Four coefficients (k3 = 0) and an empty vector (no distortion).
    four = load_camera(_write(tmp_path / "four.yml", _calibration_cpp(d=D_PER[:4])))
    assert four.distortion.tolist() == [*D_PER[:4], 0.0]
    none = {**_calibration_cpp(), "distortion_coefficients": np.zeros((0, 1))}
    assert not load_camera(_write(tmp_path / "none.yml", none)).is_distorted


def test_hand_written_yaml_1_2_in_ros_camera_info_style(tmp_path: Path) -> None:
    """YAML 1.2 that FileStorage reads but did not write: plain maps and sequences."""
    text = ("%YAML 1.2\n---\nimage_width: 640\nimage_height: 480\ncamera_name: cam\n"
            "camera_matrix:\n  rows: 3\n  cols: 3\n  data: [{}]\n"
            "distortion_model: {}\ndistortion_coefficients:\n  rows: 1\n  cols: 5\n"
            "  data: [{}]\n")
    k = ", ".join(repr(float(v)) for v in K_PER.ravel())
    d = ", ".join(repr(float(v)) for v in D_PER)
    path = tmp_path / "ros.yaml"
    path.write_text(text.format(k, "plumb_bob", d))
    assert load_camera(path, camera_from_base=POSE) == _perspective().replace(name="ros")
    path.write_text(text.format(k, "equidistant", d))  # a fisheye has 4 coefficients
    with pytest.raises(ConfigFileError, match="4 coefficients of cv::fisheye") as info:
        load_camera(path)
    assert info.value.key == "distortion_coefficients"
    path.write_text(text.format(k, "fov", d))
    with pytest.raises(ConfigFileError, match=r"'fov' is not supported.*equidistant") as info:
        load_camera(path)
    assert info.value.key == "distortion_model"
    path.write_text(text.format(k, "plumb_bob", d).replace("rows: 3", "rows: 2"))
    with pytest.raises(ConfigFileError, match="2x3 numbers") as info:
        load_camera(path)
    assert info.value.key == "camera_matrix"
    # a ROS file without distortion_model is refused (docs/robot-files.md), naming the
    # file and the key; an OpenCV file (no ROS key) needs none
    path.write_text(text.format(k, "plumb_bob", d).replace("distortion_model: plumb_bob\n",
                                                           ""))
    with pytest.raises(ConfigFileError, match=r"ROS camera_info file \(it has camera_name\) "
                                              r"must give distortion_model") as info:
        load_camera(path)
    assert info.value.key == "distortion_model" and info.value.path == str(path)
    path.write_text(text.format(k, "plumb_bob", d).replace("distortion_model: plumb_bob\n",
                                                           "").replace("camera_name: cam\n",
                                                                       ""))
    assert load_camera(path, camera_from_base=POSE).distortion.tolist() == list(D_PER)


# ---------------------------------------------------------------- writing
@pytest.mark.parametrize("ext", [".yml", ".yaml", ".xml", ".json"])
@pytest.mark.parametrize("factory", [_perspective, _unified], ids=["perspective", "unified"])
def test_save_opencv_camera_round_trip(tmp_path: Path, ext: str, factory) -> None:
    cam = factory()
    path = tmp_path / f"cam{ext}"
    save_opencv_camera(cam, path)
    # What OpenCV reads back: the sample's keys and values.
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    assert fs.getNode("image_width").real() == 640 and fs.getNode("image_height").real() == 480
    assert np.array_equal(fs.getNode("camera_matrix").mat(), cam.K)
    assert np.array_equal(fs.getNode("distortion_coefficients").mat().ravel(), cam.distortion)
    assert (fs.getNode("xi").real() == XI) if cam.kind == "unified" else fs.getNode("xi").empty()
    fs.release()
    assert load_camera(path, camera_from_base=POSE) == cam


def test_toml_that_points_to_an_opencv_file(tmp_path: Path) -> None:
    sub = tmp_path / "calib"
    sub.mkdir()
    _write(sub / "omni.yml", _omni_calibration_cpp())
    toml = tmp_path / "robot_camera.toml"
    body = ('opencv = "calib/omni.yml"\nwidth_px = 640\nheight_px = 480\n'
            "[camera_from_base]\ntranslation_mm = [120.0, -50.0, 800.0]\n"
            "rotation_vector_deg = [{}, {}, {}]\n")
    rv = np.rad2deg(np.array([0.3, -0.2, 1.1]))
    toml.write_text(body.format(*rv))
    cam = load_camera(toml)
    assert isinstance(cam, UnifiedCamera) and cam.name == "robot_camera"
    assert np.array_equal(cam.K, K_OMNI) and cam.xi == XI
    assert np.array_equal(cam.distortion, D_OMNI)
    assert np.allclose(cam.camera_from_base.as_matrix(), POSE.as_matrix(), atol=1e-12)
    assert UnifiedCamera.from_toml(toml) == cam
    bad = {
        'opencv = "calib/omni.yml"\nfx_px = 300.0\n': ("fx_px", "remove this key"),
        'opencv = "calib/omni.yml"\nkind = "perspective"\nwidth_px = 640\nheight_px = 480\n':
            ("kind", "unified calibration"),
        'opencv = "calib/omni.yml"\n': ("image_width", "width_px and height_px"),
        'opencv = "calib/missing.yml"\n': (
            "opencv", "file not found: tried .*calib/missing.yml \\(a relative path is "
                      "relative to the folder of the camera file"),
        "opencv = 3\n": ("opencv", "path of an OpenCV"),
        'opencv = "calib/omni.yml"\nwidth_px = 640\nheigth_px = 480\n':
            ("heigth_px", "did you mean 'height_px'"),
    }
    for text, (key, match) in bad.items():
        toml.write_text(text)
        with pytest.raises(ConfigFileError, match=match) as info:
            load_camera(toml)
        assert info.value.key == key, text
    toml.write_text('opencv = "calib/omni.yml"\nwidth_px = 640\nheight_px = 480\n')
    with pytest.raises(ConfigFileError, match="cannot be loaded as PerspectiveCamera"):
        PerspectiveCamera.from_toml(toml)


# ---------------------------------------------------------------- errors
def _bad_files() -> dict[str, tuple[dict[str, Any], str, str]]:
    """name: (entries, key the error must name, words of the message)."""
    good = _calibration_cpp()
    no_k = {k: v for k, v in good.items() if k != "camera_matrix"}
    no_d = {k: v for k, v in good.items() if k != "distortion_coefficients"}
    return {
        "missing camera_matrix": (no_k, "camera_matrix", "missing required key"),
        "missing distortion": (no_d, "distortion_coefficients", "missing required key"),
        # the names of cv2.calibrateCamera's Python outputs: the close key is named
        "cameraMatrix": ({**no_k, "cameraMatrix": good["camera_matrix"]}, "camera_matrix",
                         "the file has 'cameraMatrix': rename it 'camera_matrix'"),
        "distCoeffs": ({**no_d, "distCoeffs": good["distortion_coefficients"]},
                       "distortion_coefficients", "the file has 'distCoeffs': rename it"),
        "nothing close": ({**no_k, "intrinsics": good["camera_matrix"]}, "camera_matrix",
                          "the file's keys: .*intrinsics"),
        "K 2x3": ({**good, "camera_matrix": K_PER[:2]}, "camera_matrix", r"3x3.*\(2, 3\)"),
        "K not a matrix": ({**good, "camera_matrix": "K"}, "camera_matrix", "numbers"),
        "K bottom row": ({**good, "camera_matrix": K_PER * 2}, "camera_matrix", "fx, s, cx"),
        "D 2x3": ({**good, "distortion_coefficients": np.zeros((2, 3))},
                  "distortion_coefficients", r"1xN or Nx1.*\(2, 3\)"),
        "D 6 values": ({**good, "distortion_coefficients": np.zeros((6, 1))},
                       "distortion_coefficients", "got 6"),
        "D 9 values": ({**good, "distortion_coefficients": np.r_[D_PER, 0.01, 0, 0, 0]},
                       "distortion_coefficients", "got 9"),
        "D NaN": ({**good, "distortion_coefficients": np.r_[D_PER[:4], np.nan]},
                  "distortion_coefficients", "NaN"),
        "omni 5 values": ({**_omni_calibration_cpp(), "distortion_coefficients": D_PER},
                          "distortion_coefficients", r"omnidir.*got 5"),
        "negative xi": ({**_omni_calibration_cpp(), "xi": -0.5}, "xi", ">= 0"),
        "width 640.5": ({**good, "image_width": 640.5}, "image_width", "positive integer"),
        "width text": ({**good, "image_width": "640"}, "image_width", "numbers"),
        "fisheye 8 values": ({**good, "fisheye_model": 1}, "distortion_coefficients",
                             r"4 coefficients of cv::fisheye \(k1, k2, k3, k4\), got 8"),
        "fisheye with xi": ({**_omni_calibration_cpp(), "fisheye_model": 1}, "xi",
                            "fisheye"),
        "two names": ({**_omni_calibration_cpp(), "D": D_OMNI}, "distortion_coefficients",
                      "not both"),
    }


@pytest.mark.parametrize("case", list(_bad_files()))
def test_bad_opencv_files_name_the_file_and_the_key(tmp_path: Path, case: str) -> None:
    entries, key, match = _bad_files()[case]
    path = _write(tmp_path / "bad.yml", entries)
    with pytest.raises(ConfigFileError, match=match) as info:
        load_camera(path, image_size=(640, 480) if "xi" in entries else None)
    assert info.value.key == key and info.value.path == str(path)
    assert str(path) in str(info.value) and f"'{key}'" in str(info.value)


def test_other_bad_files(tmp_path: Path) -> None:
    # Folding coefficients: the camera refuses them, naming the file.
    fold = _write(tmp_path / "fold.xml", _calibration_cpp(d=np.array([-0.9, 0.0, 0, 0])))
    with pytest.raises(DistortionError, match="fold inside the image") as info:
        load_camera(fold)
    assert info.value.source == str(fold) and str(fold) in str(info.value)
    # A principal point outside the image (the intrinsics of a 1280 x 960 calibration
    # with the 640 x 480 size), from an OpenCV file as from a TOML one (it loaded: only
    # the TOML's keys were checked).
    big = _calibration_cpp(K=K_PER * [[2.0], [2.0], [1.0]])
    path = _write(tmp_path / "big.yml", big)
    with pytest.raises(CameraError, match=r"principal point's cx = 662\.5 px lies outside "
                       r"the image, \[-0\.5, 639\.5\] px for width 640") as info:
        load_camera(path)
    assert info.value.source == str(path)
    # Not a FileStorage file, unknown extensions, missing file.
    broken = tmp_path / "broken.yml"
    broken.write_text("%YAML:1.0\n---\ncamera_matrix: [1, 2\n")
    with pytest.raises(ConfigFileError, match="not a valid OpenCV FileStorage file"):
        load_camera(broken)
    (tmp_path / "cam.txt").write_text("camera_matrix: 1\n")
    with pytest.raises(ConfigFileError, match=r"unknown extension '\.txt'.*\.toml.*\.yml"):
        load_camera(tmp_path / "cam.txt")
    with pytest.raises(ConfigFileError, match=r"unknown extension '\.ini'.*\.xml, \.json"):
        load_opencv_camera(tmp_path / "cam.ini")
    with pytest.raises(ConfigFileError, match="not found"):
        load_camera(tmp_path / "absent.json")
    with pytest.raises(ConfigFileError, match=r"unknown extension '\.cfg'"):
        save_opencv_camera(_perspective(), tmp_path / "out.cfg")
    # A pose or an image size for a preset or a TOML file (which give them) is refused.
    with pytest.raises(CameraError, match=r"camera_from_base.*only for an OpenCV"):
        load_camera("front", camera_from_base=POSE)
    _perspective().to_toml(tmp_path / "cam.toml")
    with pytest.raises(CameraError, match="image_size"):
        load_camera(tmp_path / "cam.toml", image_size=(640, 480))
    assert load_camera(tmp_path / "cam.toml") == Camera.from_toml(tmp_path / "cam.toml")


def test_a_double_sphere_xi_given_apart_is_said_to_go_in_its_distortion() -> None:
    """(It said 'a perspective camera has xi = 0 ... use kind = unified'.)"""
    from hexapod.exceptions import ConfigFileError
    from vision.cameras.files.project import read_camera_table

    table = {"kind": "double_sphere", "width_px": 640, "height_px": 480, "fx_px": 300.0,
             "fy_px": 300.0, "cx_px": 320.0, "cy_px": 240.0, "xi": 0.5,
             "distortion": [-0.2, 0.6]}
    with pytest.raises(ConfigFileError, match=r"key 'xi': a double sphere camera's xi goes "
                                              r"in distortion = \[xi, alpha\], got xi = 0\.5"):
        read_camera_table(table, "ds.toml")
