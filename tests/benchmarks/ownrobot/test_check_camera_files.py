"""``hexapod-bench check`` of a camera calibration file: it says where it placed the
camera (a calibration file holds no pose), never asks to change a pose the file cannot
hold, and says where each end of each edge is: a pixel only for a point in the image or
near it, labelled; never a pixel of a point behind the camera or far outside the image
as if it were seen."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from benchmarks.cli import main
from vision.cameras.files.opencv import write_opencv_calibration
from vision.cameras.files.ros import write_ros_camera_info

W, H = 1024, 780
K_FRONT = np.array([[1032.26, 0.0, 511.5], [0.0, 1032.26, 389.5], [0.0, 0.0, 1.0]])
K_FISHEYE = np.array([[350.0, 0.0, 511.5], [0.0, 350.0, 389.5], [0.0, 0.0, 1.0]])
#: "<what> (x, y)": an end of an edge said with its pixel.
END = re.compile(r"(in the image|outside the image) \((-?[\d.]+), (-?[\d.]+)\)")


def _check(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    code = main(["check", *args])
    cap = capsys.readouterr()
    return code, cap.out + cap.err


def _ros(tmp_path: Path) -> Path:
    path = tmp_path / "ros.yaml"
    write_ros_camera_info(path, "perspective", K_FRONT,
                          np.array([-0.28, 0.09, 5e-4, -3e-4, -0.012]), W, H)
    return path


def _fisheye(tmp_path: Path) -> Path:
    path = tmp_path / "fisheye.yml"
    write_opencv_calibration(path, K_FISHEYE, np.array([0.05, -0.01, 0.002, -0.0005]), W, H,
                             fisheye=True)
    return path


def _pixels_are_labelled(out: str) -> list[tuple[str, float, float]]:
    """Every pixel printed is an end's, labelled by where it is, and is where its label
    says; none is a number of a point not in view (15227190174.9...)."""
    ends = [(what, float(x), float(y)) for what, x, y in END.findall(out)]
    for what, x, y in ends:
        inside = -0.5 <= x <= W - 0.5 and -0.5 <= y <= H - 0.5
        assert inside == (what == "in the image"), (what, x, y)
        assert -W <= x <= 2 * W and -H <= y <= 2 * H
    numbers = [float(v) for v in re.findall(r"-?\d+\.\d+", out)]
    assert max(abs(v) for v in numbers) < 1e5
    return ends


def test_a_ros_file_alone_is_placed_at_the_front_pose(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = _ros(tmp_path)
    code, out = _check([str(path)], capsys)
    assert code == 0, out
    assert ("camera pose: a calibration file holds none; placed where the 'front' preset "
            "sits for this robot (projection centre at (692.8, 400.0, 0.0) mm") in out
    assert f"[camera_from_base] in {path}" not in out  # a pose the file cannot hold
    ends = _pixels_are_labelled(out)
    assert len(ends) == 24 and all(what == "in the image" for what, _, _ in ends)
    assert "at home it sees 12 of 12 leg edges (12 with both ends in the image" in out


def test_a_camera_placed_among_the_legs_says_where_each_end_is(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The ROS file's camera at the identity pose (a camera file naming it, without
    [camera_from_base]): at the base centre, looking up through the platform; base ends
    lie on its image plane."""
    _ros(tmp_path)
    toml = tmp_path / "camera.toml"
    toml.write_text('opencv = "ros.yaml"\n')
    code, out = _check([str(toml)], capsys)
    assert code == 1, out
    _pixels_are_labelled(out)
    assert "base end behind the camera" in out and "far outside the image" in out
    assert "at home it sees 0 of 12 leg edges" in out
    assert re.search(r"error: the camera sees no leg edge at the home pose: .*\(of the 24 "
                     r"edge ends: \d+ behind the camera", out)
    assert f"change [camera_from_base] in {toml}" in out  # this file can hold one


def test_a_fisheye_seeing_legs_in_part_says_so(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    _fisheye(tmp_path)
    toml = tmp_path / "camera.toml"
    toml.write_text('opencv = "fisheye.yml"\n')  # at the identity pose: looking up
    code, out = _check([str(toml)], capsys)
    assert code == 0, out
    ends = _pixels_are_labelled(out)
    assert any(what == "outside the image" for what, _, _ in ends)
    assert "beyond the lens's field of view" in out
    # every edge is seen over part of its length only, and said so
    assert "at home it sees 12 of 12 leg edges (0 with both ends in the image, 12 with an " \
           "end out of it)" in out
    lines = [line for line in out.splitlines() if re.match(r"\s+leg \d edge \d: ", line)]
    assert len(lines) == 12
    assert all(re.search(r"seen, \d+ % in view; base end (outside the image|beyond)", line)
               for line in lines)
    # the fisheye file alone is placed at the fisheye preset's pose
    code, out = _check([str(tmp_path / "fisheye.yml")], capsys)
    assert code == 0, out
    assert "placed where the 'fisheye' preset sits" in out
    _pixels_are_labelled(out)


def test_a_ros_file_without_its_distortion_model_is_refused(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = _ros(tmp_path)
    path.write_text(path.read_text().replace("distortion_model: plumb_bob\n", ""))
    code, out = _check([str(path)], capsys)
    assert code == 2
    assert f"{path}: key 'distortion_model': a ROS camera_info file" in out


def test_a_scenario_naming_a_calibration_file_is_told_to_change_its_own_keys(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The camera's pose of a scenario that names a calibration file is the scenario's
    ([camera] pose or [camera.camera_from_base]), never the file's."""
    path = _ros(tmp_path)
    study = tmp_path / "study.toml"
    study.write_text('name = "blind"\ntrials = 2\ncontrollers = ["leg-edge"]\n[camera]\n'
                     'file = "ros.yaml"\n[camera.camera_from_base]\n'
                     "translation_mm = [0.0, 0.0, -3000.0]\n")  # the robot behind it
    code, out = _check([str(study)], capsys)
    assert code == 1, out
    assert (f"change [camera] pose or [camera.camera_from_base] in {study} (the calibration "
            f"file {path} holds no pose)") in out
    assert f"[camera_from_base] in {path}" not in out


def test_the_picture_of_a_camera_at_the_base_origin_draws_only_what_its_lens_images(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A scenario naming a calibration file without a pose puts the camera at the base
    origin, where a third of the limbs' points lie beyond the lens's fold: they were
    drawn too (pixels up to 1e13, 24 red lines through the image centre, and numpy's
    warning of the cast); only the runs of points the lens images are drawn now."""
    import warnings

    import cv2

    path = tmp_path / "cal.yml"
    write_opencv_calibration(path, K_FRONT, np.array([-0.28, 0.09, 5e-4, -3e-4, -0.012]),
                             W, H)
    study = tmp_path / "study.toml"
    study.write_text('name = "s"\ntrials = 2\ncontrollers = ["leg-edge"]\n[camera]\n'
                     'file = "cal.yml"\n')
    picture = tmp_path / "view.png"
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # (a RuntimeWarning of the cast fails the test)
        code, _ = _check([str(study), "--picture", str(picture)], capsys)
    assert code == 1  # the camera sees no edge: the setup cannot run, the picture is made
    img = cv2.imread(str(picture))
    centre = img[H // 2 - 60:H // 2 + 60, W // 2 - 60:W // 2 + 60].astype(int)
    red = (centre[..., 2] > 150) & (centre[..., 1] < 80) & (centre[..., 0] < 80)
    assert not red.any(), "an edge drawn through the image centre"


def test_a_calibration_with_width_and_height_swapped_is_warned_of(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A 1024x780 calibration written as 780x1024 was taken without a word (its principal
    point still inside the image): the principal point far from the centre is said, with
    the swap when it fits the other way round; a calibration of this size is not."""
    swapped = tmp_path / "swapped.yml"
    write_opencv_calibration(swapped, K_FRONT, np.zeros(5), H, W)
    _, out = _check([str(swapped)], capsys)
    said = " ".join(out.split())
    assert ("the principal point (511.5, 389.5) px is 16 % of the 780x1024 image's size "
            "from its centre: the width and height swapped?") in said, said
    right = tmp_path / "right.yml"
    write_opencv_calibration(right, K_FRONT, np.zeros(5), W, H)
    _, out = _check([str(right)], capsys)
    assert "principal point" not in out
