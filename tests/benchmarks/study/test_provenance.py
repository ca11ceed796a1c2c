"""Calibration provenance (issue 28, item 4): calibrated.toml records the robot and camera it
was made with; another robot or camera is refused (or, asked explicitly, warned loudly);
points far from the nominal ones are flagged."""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import numpy as np
import pytest
import tomli_w

from benchmarks.cli import main as cli_main
from benchmarks.exceptions import ForeignCalibrationError
from benchmarks.robot import servo
from benchmarks.study.provenance import (
    FAR_FROM_NOMINAL_MM,
    camera_fingerprint,
    check_calibration,
    robot_fingerprint,
)
from hexapod import deltalab
from hexapod.geometry import HexapodGeometry
from vision.calibration import collect_observations
from vision.cameras import camera_preset, front_camera


def _own_robot(path: Path) -> Path:
    """The issue's robot: base radius 350 mm, platform radius 200 mm, strokes 380-540 mm."""
    table = deltalab().to_dict()
    table["name"] = "ours"
    table["base_points_mm"] = (np.array(table["base_points_mm"]) * 350 / 270).tolist()
    table["platform_points_mm"] = (np.array(table["platform_points_mm"]) * 200 / 195).tolist()
    table["stroke_mm"] = [380.0, 540.0]
    path.write_text(tomli_w.dumps(table))
    return path


def _scenario(folder: Path, name: str, robot: str = "", camera: str = "",
              calibration: str = "") -> Path:
    path = folder / f"{name}.toml"
    path.write_text(f'name = "{name}"\nseed = 3\ntrials = 2\ncontrollers = ["leg-edge"]\n'
                    f"{robot}{camera}{calibration}[task]\nmax_steps = 40\n")
    return path


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """calibrate on the reference robot and the front camera (as the quick study)."""
    folder = tmp_path_factory.mktemp("cal")
    assert cli_main(["calibrate", str(_scenario(folder, "ref")), "--out",
                     str(folder / "out")]) == 0
    return folder / "out" / "calibrated.toml"


def test_the_file_records_the_robot_and_camera_it_was_made_with(calibrated: Path) -> None:
    table = tomllib.loads(calibrated.read_text())
    g = deltalab()
    assert table["made_with"] == {
        "robot": "deltalab", "robot_fingerprint": robot_fingerprint(g),
        "camera": "front", "camera_fingerprint": camera_fingerprint(camera_preset("front", g))}
    doc = json.loads((calibrated.parent / "calibration.json").read_text())
    assert doc["made_with"] == table["made_with"]
    point = doc["points"][0]
    assert point["far_from_nominal_legs"] == []
    assert max(point["distance_from_nominal_mm"]) < 1.0, "noiseless: on the nominal points"


def test_fingerprints_follow_the_parameters_not_the_names(tmp_path: Path) -> None:
    g = deltalab()
    g.to_toml(tmp_path / "same.toml")
    assert robot_fingerprint(HexapodGeometry.from_toml(tmp_path / "same.toml")) == \
        robot_fingerprint(g)
    table = g.to_dict()
    table["base_points_mm"][2][1] += 0.01  # 10 micrometres
    (tmp_path / "moved.toml").write_text(tomli_w.dumps(table))
    assert robot_fingerprint(HexapodGeometry.from_toml(tmp_path / "moved.toml")) != \
        robot_fingerprint(g)
    cam = front_camera()
    assert camera_fingerprint(cam) == camera_fingerprint(front_camera())
    from hexapod.kinematics import Transform

    T = cam.camera_from_base
    shifted = T.translation + np.array([1e-3, 0.0, 0.0])  # 1 mm
    moved = cam.replace(camera_from_base=Transform(T.rotation, shifted))
    assert camera_fingerprint(moved) != camera_fingerprint(cam)


@pytest.mark.slow
def test_the_same_setup_uses_it_silently(calibrated: Path, tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run"
    assert cli_main(["run", str(_scenario(tmp_path, "ref")), "--out", str(out),
                     "--no-progress", "--calibration", str(calibrated)]) == 0
    assert "warning" not in capsys.readouterr().err.lower()
    assert json.loads((out / "run.json").read_text())["warnings"] == []


def test_another_robot_is_refused_naming_both(calibrated: Path, tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    _own_robot(tmp_path / "my-hexapod.toml")
    scen = _scenario(tmp_path, "mine", robot='[robot]\ngeometry = "my-hexapod.toml"\n',
                     camera='[camera]\npreset = "omni"\n')
    out = tmp_path / "run"
    assert cli_main(["run", str(scen), "--out", str(out), "--no-progress",
                     "--calibration", str(calibrated)]) == 2
    err = capsys.readouterr().err
    g = HexapodGeometry.from_toml(tmp_path / "my-hexapod.toml")
    assert (f"error: {calibrated}: key 'made_with': made with the robot 'deltalab' "
            f"(fingerprint {robot_fingerprint(deltalab())}), not this robot "
            f"'my-hexapod.toml' ({robot_fingerprint(g)}) and with the camera 'front'") in err
    assert "calibrate this one (hexapod-bench calibrate SCENARIO --out DIR), or pass " \
        "--allow-foreign-calibration" in err
    assert not out.exists(), "refused before anything runs"


def test_another_camera_alone_is_refused(calibrated: Path, tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    scen = _scenario(tmp_path, "omni", camera='[camera]\npreset = "omni"\n')
    assert cli_main(["run", str(scen), "--out", str(tmp_path / "r"), "--no-progress",
                     "--calibration", str(calibrated)]) == 2
    err = capsys.readouterr().err
    assert "made with the camera 'front'" in err and "not this camera 'omni'" in err
    assert "robot 'deltalab'" not in err, "the robot is the same"


@pytest.mark.slow
def test_insisting_warns_loudly_and_flags_the_far_points(
        calibrated: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    _own_robot(tmp_path / "my-hexapod.toml")
    scen = _scenario(tmp_path, "mine", robot='[robot]\ngeometry = "my-hexapod.toml"\n')
    out = tmp_path / "run"
    assert cli_main(["run", str(scen), "--out", str(out), "--no-progress",
                     "--calibration", str(calibrated), "--allow-foreign-calibration"]) == 0
    err = capsys.readouterr().err
    assert f"warning: {calibrated}: FOREIGN CALIBRATION used as asked: made with the robot " \
        "'deltalab'" in err
    assert "and with the camera 'front' with other parameters" in err  # scales with the robot
    assert f"farther than {FAR_FROM_NOMINAL_MM:g} mm from the nominal ones" in err
    meta = json.loads((out / "run.json").read_text())
    warnings = meta["warnings"]
    assert any("FOREIGN CALIBRATION" in w for w in warnings)
    assert any("base point(s) 0 (" in w for w in warnings)
    # the study recorded is the one run: the file allowed (it said false)
    assert meta["scenarios"]["mine"]["study"]["calibration.allow_foreign"] is True


@pytest.mark.slow
def test_the_scenario_key_refuses_or_allows_the_same_way(
        calibrated: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    _own_robot(tmp_path / "my-hexapod.toml")
    robot = '[robot]\ngeometry = "my-hexapod.toml"\n'
    cal = f'[calibration]\nmethod = "file"\nfile = "{calibrated}"\n'
    scen = _scenario(tmp_path, "strict", robot=robot, calibration=cal)
    assert cli_main(["run", str(scen), "--out", str(tmp_path / "a"), "--no-progress"]) == 2
    assert "key 'made_with': made with the robot 'deltalab'" in capsys.readouterr().err
    scen = _scenario(tmp_path, "lax", robot=robot, calibration=cal + "allow_foreign = true\n")
    assert cli_main(["run", str(scen), "--out", str(tmp_path / "b"), "--no-progress"]) == 0
    assert "FOREIGN CALIBRATION" in capsys.readouterr().err


@pytest.mark.slow
def test_a_file_without_provenance_is_used_with_a_warning(
        calibrated: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    table = tomllib.loads(calibrated.read_text())
    del table["made_with"]
    old = tmp_path / "old.toml"
    old.write_text(tomli_w.dumps(table))
    assert cli_main(["run", str(_scenario(tmp_path, "ref")), "--out", str(tmp_path / "r"),
                     "--no-progress", "--calibration", str(old)]) == 0
    assert f"{old}: records no robot or camera" in capsys.readouterr().err


def test_check_calibration_flags_points_beyond_the_threshold() -> None:
    g, cam = deltalab(), front_camera()
    points = cam.camera_from_base.apply(g.base_points)
    points[4] += [0.0, 0.0, 0.051]  # 51 mm
    points[1] += [0.030, 0.0, 0.0]  # 30 mm: within
    warnings = check_calibration("c.toml", points, None, "deltalab", g, "front", cam)
    assert warnings[-1].startswith(f"c.toml: base point(s) 4 (51.0 mm) farther than "
                                   f"{FAR_FROM_NOMINAL_MM:g} mm")
    with pytest.raises(ForeignCalibrationError) as info:
        check_calibration("c.toml", points, {"robot": "x", "robot_fingerprint": "0" * 16,
                                             "camera": "front",
                                             "camera_fingerprint": camera_fingerprint(cam)},
                          "deltalab", g, "front", cam)
    assert info.value.key == "made_with"


def test_calibrate_flags_estimates_far_from_the_nominal_points(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Observations of another robot calibrated against the reference robot's CAD."""
    own = HexapodGeometry.from_toml(_own_robot(tmp_path / "my-hexapod.toml"))
    data = collect_observations(own, camera_preset("front", deltalab()).camera_from_base)
    data.save(tmp_path / "obs.json")
    out = tmp_path / "cal"
    assert cli_main(["calibrate", str(_scenario(tmp_path, "ref")), "--out", str(out),
                     "--observations", str(tmp_path / "obs.json")]) == 0
    err = capsys.readouterr().err
    assert f"warning: {out / 'calibrated.toml'}: base point(s) 0 (" in err
    doc = json.loads((out / "calibration.json").read_text())
    assert doc["far_from_nominal_legs"] == [0, 1, 2, 3, 4, 5]
    assert min(doc["distance_from_nominal_mm"]) > FAR_FROM_NOMINAL_MM
    assert doc["normals_flipped"] == 0  # good normals are not turned by a far nominal
    np.testing.assert_allclose(doc["result"]["linear"]["residual_rms_mm"], 0.0, atol=1e-6)


def test_servo_refuses_a_foreign_calibration_before_the_robot_is_contacted(
        calibrated: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    _own_robot(tmp_path / "my-hexapod.toml")
    goal = tmp_path / "goal.toml"
    goal.write_text("lengths_mm = [450, 450, 450, 450, 450, 450]\n")
    code = servo.main(["--backend", "serial:/nonexistent/port", "--camera", "sim",
                       "--simulated-camera-on-real-robot", "--goal", str(goal),
                       "--geometry", str(tmp_path / "my-hexapod.toml"),
                       "--calibration", str(calibrated)])
    err = capsys.readouterr().err
    assert code == 2
    assert "made with the robot 'deltalab'" in err and "not this robot 'my-hexapod.toml'" in err
    assert "nonexistent" not in err


@pytest.mark.slow
def test_a_file_in_a_study_that_draws_calibration_errors_is_questioned(
        calibrated: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scen = _scenario(tmp_path, "drawn",
                     calibration="[calibration_error]\ncamera_pose_deg = [0.0, 0.2]\n")
    out = tmp_path / "run"
    assert cli_main(["run", str(scen), "--out", str(out), "--no-progress",
                     "--calibration", str(calibrated)]) == 0
    text = (f"warning: {calibrated}: scenario 'drawn' draws a calibration error per trial "
            "(camera_pose_deg): every trial is another robot")
    assert text in capsys.readouterr().err
    assert any("method = \"linear\"" in w
               for w in json.loads((out / "run.json").read_text())["warnings"])


@pytest.mark.parametrize(("key", "value", "says"), [
    ("leg_radius_mm", -15.0, "key 'leg_radius_mm': must be positive, got -15.0"),
    ("scale", 0.0, "key 'scale': must be positive, got 0.0"),
    ("scale", "one", "key 'scale': expected a finite number, got 'one'"),
])
def test_a_calibrated_file_s_recorded_values_are_checked(
        calibrated: Path, tmp_path: Path, key: str, value: object, says: str) -> None:
    """(A negative leg radius or a zero scale in a hand-edited file passed unseen.)"""
    from benchmarks.study.calibration import read_calibrated_file
    from hexapod.exceptions import ConfigFileError

    table = tomllib.loads(calibrated.read_text())
    table[key] = value
    bad = tmp_path / "bad.toml"
    bad.write_text(tomli_w.dumps(table))
    with pytest.raises(ConfigFileError) as exc:
        read_calibrated_file(bad)
    assert str(exc.value) == f"{bad}: {says}"
