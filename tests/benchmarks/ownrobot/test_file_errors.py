"""Errors in the file's terms: the key as written, its unit, did-you-mean, the path tried."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from benchmarks.cli import main
from benchmarks.exceptions import ScenarioError
from benchmarks.study.scenario import check_controllers, load_scenario
from hexapod.exceptions import GeometryError
from hexapod.geometry import HexapodGeometry
from tests.benchmarks.ownrobot.robots import own_robot, write_study


def _run(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    code = main(args)
    return code, capsys.readouterr().err


def test_swapped_stroke_names_stroke_mm_in_mm(tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    table = own_robot().to_dict()
    table["stroke_mm"] = [540, 380]
    robot = tmp_path / "robot.toml"
    import tomli_w

    robot.write_text(tomli_w.dumps(table))
    with pytest.raises(GeometryError) as info:
        HexapodGeometry.from_toml(robot)
    text = str(info.value)
    assert info.value.field == "stroke_mm"
    assert "[540, 380] mm" in text and "swap" in text and str(robot) in text
    assert "q_min" not in text and " m)" not in text
    code, err = _run(["run", str(write_study(tmp_path)), "--out", str(tmp_path / "o")], capsys)
    assert code == 2
    assert "stroke_mm" in err and "[540, 380] mm" in err
    assert not (tmp_path / "o" / "results.jsonl").exists()


@pytest.mark.parametrize(("field", "value", "fragment"), [
    ("stroke_mm", [0, 380], "must be positive, got 0 mm"),
    ("leg_radius_mm", -2.0, "leg_radius_mm: must be positive, got -2 mm"),
    ("max_speed_mm_s", 0.0, "max_speed_mm_s: must be positive, got 0 mm/s"),
])
def test_geometry_values_in_millimetres(tmp_path: Path, field: str, value: object,
                                        fragment: str) -> None:
    table = own_robot().to_dict()
    table[field] = value
    with pytest.raises(GeometryError) as info:
        HexapodGeometry.from_dict(table, "robot.toml")
    assert info.value.field == field and fragment in str(info.value)


def test_coincident_points_name_the_file_key(tmp_path: Path) -> None:
    table = own_robot().to_dict()
    table["platform_points_mm"][1] = table["platform_points_mm"][0]
    with pytest.raises(GeometryError) as info:
        HexapodGeometry.from_dict(table, "robot.toml")
    assert str(info.value).startswith("robot.toml: platform_points_mm: points 0 and 1 coincide")
    assert "metres" not in str(info.value)
    metres = own_robot().to_dict()  # the points typed in metres: 0.35 for 350 mm
    metres["base_points_mm"] = (np.asarray(metres["base_points_mm"]) / 1000).tolist()
    with pytest.raises(GeometryError) as info:
        HexapodGeometry.from_dict(metres, "robot.toml")
    assert "metres where millimetres are meant" in str(info.value), str(info.value)


def test_misspelt_controller_option_gets_did_you_mean(tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]
                                                      ) -> None:
    own_robot().to_toml(tmp_path / "robot.toml")
    study = write_study(tmp_path, controllers='[{name = "leg-edge", adaptiv_gain = [5.0, 1.0, '
                                              '30.0]}]')
    with pytest.raises(ScenarioError) as info:
        check_controllers(load_scenario(study))
    assert info.value.key == "controllers[0].adaptiv_gain"
    assert info.value.suggestion == "adaptive_gain"
    assert "controller 'leg-edge' has no option 'adaptiv_gain'" in str(info.value)
    assert "unexpected keyword" not in str(info.value)
    code, err = _run(["run", str(study), "--out", str(tmp_path / "o")], capsys)
    assert code == 2
    assert f"{study}: key 'controllers[0].adaptiv_gain'" in err
    assert "(did you mean 'adaptive_gain'?)" in err


def test_misspelt_shared_option_names_controller_options(tmp_path: Path) -> None:
    own_robot().to_toml(tmp_path / "robot.toml")
    study = write_study(tmp_path, controllers='["leg-edge", "model-based"]',
                        extra="[controller_options]\ngian = 2.0")
    with pytest.raises(ScenarioError) as info:
        check_controllers(load_scenario(study))
    assert info.value.key == "controller_options.gian" and info.value.suggestion == "gain"


def test_unknown_controller_names_the_file_and_key(tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    own_robot().to_toml(tmp_path / "robot.toml")
    study = write_study(tmp_path, controllers='["leg-edge", "leg-edgee"]')
    code, err = _run(["run", str(study), "--out", str(tmp_path / "o")], capsys)
    assert code == 2
    assert f"{study}: key 'controllers[1]': unknown controller 'leg-edgee'" in err
    assert "(did you mean 'leg-edge'?)" in err
    code, err = _run(["run", str(study), "--out", str(tmp_path / "o"), "--controllers",
                      "modle-based"], capsys)
    assert code == 2 and err.startswith("hexapod-bench: error: --controllers: unknown "
                                        "controller 'modle-based'")


@pytest.mark.parametrize("section", ["robot.geometry", "camera.file"])
def test_missing_relative_file_gives_the_path_tried_and_the_rule(
        tmp_path: Path, section: str, capsys: pytest.CaptureFixture[str]) -> None:
    folder = tmp_path / "studies"
    folder.mkdir()
    if section == "robot.geometry":
        study = write_study(folder, geometry="my-hexapod.toml")
    else:
        study = write_study(folder, geometry=None, camera="cams/my-camera.toml")
    name = "my-hexapod.toml" if section == "robot.geometry" else "cams/my-camera.toml"
    code, err = _run(["run", str(study), "--out", str(tmp_path / "o")], capsys)
    assert code == 2
    assert f"key '{section}'" in err
    assert f"tried {(folder / name).resolve()}" in err
    assert f"relative to the folder of the scenario file, {folder.resolve()}" in err


def test_a_misspelt_robot_key_is_named_in_a_robot_file_checked_alone(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``check`` on a robot file whose ``base_points_mm`` is misspelt or missing: it was
    taken for a scenario (the scenario's keys listed, ``platform_points_mm`` blamed); it
    is a robot file with the close key named."""
    import tomli_w

    table = own_robot().to_dict()
    table["name"] = "mine"
    points = table.pop("base_points_mm")
    for name, key in (("typo", "base_point_mm"), ("api", "base_points"), ("none", None)):
        t = dict(table) if key is None else dict(table, **{key: points})
        robot = tmp_path / f"{name}.toml"
        robot.write_text(tomli_w.dumps(t))
        code, err = _run(["check", str(robot)], capsys)
        err = " ".join(err.split())
        assert code == 2, err
        if key is None:
            assert "key 'base_points_mm': missing required key" in err
        else:
            assert f"key '{key}': unknown key" in err
            assert "(did you mean 'base_points_mm'?)" in err and "controllers" not in err


def test_a_robot_file_named_as_the_camera_file_is_said_to_be_one(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The robot and camera files swapped in a scenario: each is told what it is and where
    it goes (it was an unknown-key error listing the other kind's keys)."""
    from tests.benchmarks.ownrobot.robots import BLIND_CAMERA

    own_robot().to_toml(tmp_path / "robot.toml")
    (tmp_path / "camera.toml").write_text(BLIND_CAMERA)
    code, err = _run(["check", str(write_study(tmp_path, "robot.toml", "robot.toml"))],
                     capsys)
    err = " ".join(err.split())
    assert code == 2 and "robot.toml: key 'base_points_mm': a robot file (it has " \
        "'base_points_mm'), not a camera file: a robot file goes to [robot] geometry" in err
    code, err = _run(["check", str(write_study(tmp_path, "camera.toml", None))], capsys)
    err = " ".join(err.split())
    assert code == 2 and "camera.toml: key 'fx_px': a camera file (it has 'fx_px'), not " \
        "a robot file: a camera file goes to [camera] file" in err


@pytest.mark.parametrize(("table", "key", "value", "fragment"), [
    ("drives", "encoder_resolution", 1.0,
     "drives.encoder_resolution: leg 0: 1 m, coarser than a hundredth of the stroke"),
    ("inertia", "platform_com", [0.0, 0.0, 20.0],
     "[0.0, 0.0, 20.0] m is 20 m from the platform's centre, more than ten times the "
     "robot's size"),
    ("inertia", "body_com", 171.0,
     "(millimetres? [inertia] is in SI units: 171 mm is 0.171 m)"),
])
def test_millimetres_in_the_si_tables_are_refused(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], table: str, key: str,
        value: object, fragment: str) -> None:
    """The SI tables' values a slip of units gives: check said 'The setup can run'
    (encoder, platform centre of mass) and every trial failed, or named no unit."""
    import tomli_w

    t = own_robot().to_dict(dynamics=True)
    t[table][key] = value
    robot = tmp_path / "robot.toml"
    robot.write_text(tomli_w.dumps(t))
    code, err = _run(["check", str(robot)], capsys)
    assert code == 2 and fragment in " ".join(err.split()), err


def test_platform_points_in_metres_are_an_error_of_check(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Platform joints a small fraction of a millimetre from their centre (as a small
    platform's points in metres give), far enough apart for the joint-separation rule:
    check said 'The setup can run' with hints at swapped rows and radians, and every
    trial failed; now an error naming the key and the unit."""
    import tomli_w

    t = own_robot().to_dict()
    t["platform_points_mm"] = (np.asarray(t["platform_points_mm"]) / 250).tolist()  # (apart)
    robot = tmp_path / "robot.toml"
    robot.write_text(tomli_w.dumps(t))
    code = main(["check", str(robot)])
    out = " ".join(capsys.readouterr().out.split())
    assert code == 1
    assert "error: the joints of platform_points_mm lie within" in out
    assert "given in metres? platform_points_mm is in millimetres" in out


@pytest.mark.parametrize("name", ["empty.toml", "empty.yml"])
def test_an_empty_file_is_said_to_be_empty(tmp_path: Path, name: str,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    """An empty TOML file was 'cannot tell what this file is' (implying keys it lacks),
    an empty OpenCV file OpenCV's own assertion '(-215:Assertion failed) buf'."""
    path = tmp_path / name
    path.write_text("")
    code, err = _run(["check", str(path)], capsys)
    assert code == 2 and f"{path}: the file is empty" in err and "-215" not in err


def test_a_robot_file_alone_says_its_drives_cannot_hold_its_platform(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A platform mass in grams (2000 for 2 kg): check of the robot file alone said 'No
    problem found' (a scenario's check in the dynamic world did warn)."""
    import tomli_w

    t = own_robot().to_dict(dynamics=True)
    t["inertia"]["platform_mass"] = 2000.0
    robot = tmp_path / "robot.toml"
    robot.write_text(tomli_w.dumps(t))
    assert main(["check", str(robot)]) == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "the robot's own weight needs" in out and "its drives' force limit is 200 N" in out
    own_robot().to_toml(robot)  # its own 2 kg: nothing said
    assert main(["check", str(robot)]) == 0
    assert "own weight" not in capsys.readouterr().out


def test_a_centre_of_mass_beyond_the_leg_in_metres_gets_no_millimetre_hint(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """0.4 m on a robot whose shortest leg is shorter: plainly metres, too long (the hint
    said '0.4 mm is 0.0004 m' of it)."""
    import tomli_w

    t = own_robot().to_dict(dynamics=True)
    t["inertia"]["rod_com"] = 0.4 + own_robot().stroke[0]
    robot = tmp_path / "robot.toml"
    robot.write_text(tomli_w.dumps(t))
    code, err = _run(["check", str(robot)], capsys)
    err = " ".join(err.split())
    assert code == 2 and "inertia.rod_com: centre of mass" in err and "outside the leg" in err
    assert "millimetres?" not in err
