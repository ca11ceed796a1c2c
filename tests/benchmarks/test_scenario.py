"""Scenario files: validation errors name the file, the key and the expectation."""

from __future__ import annotations

from pathlib import Path

import pytest

from benchmarks.exceptions import ScenarioError
from benchmarks.scenario import builtin_scenarios, load_scenario, parse_scenario

MINIMAL = {"name": "t", "controllers": ["leg-edge"]}


def test_every_builtin_scenario_validates() -> None:
    names = builtin_scenarios()
    for required in ("quick", "andreff2005-noise", "andreff2006-front-camera",
                     "tahri2009-convergence", "calibration-error-sweep"):
        assert required in names
    for name in names:
        sc = load_scenario(name)
        assert sc.name == name
        assert sc.controllers


def test_sweep_expands_to_cartesian_product() -> None:
    sc = parse_scenario({**MINIMAL, "noise": {"model": "rotation", "amplitude_deg": [0, 0.05]},
                         "calibration_error": {"base_points_mm": [0.0, 1.0, 2.0]}})
    points = sc.expand()
    assert len(points) == 6
    assert {(p.noise.amplitude_deg, p.calibration_error.base_points_mm) for p in points} == {
        (a, b) for a in (0.0, 0.05) for b in (0.0, 1.0, 2.0)}
    assert points[0].sweep == {"noise.amplitude_deg": 0.0,
                               "calibration_error.base_points_mm": 0.0}


@pytest.mark.parametrize(
    ("table", "key", "fragment"),
    [
        ({**MINIMAL, "noise": {"amplitud_deg": 0.1}}, "noise.amplitud_deg", "amplitude_deg"),
        ({**MINIMAL, "tasks": {}}, "tasks", "task"),
        ({**MINIMAL, "noise": {"model": "gaussian"}}, "noise.model", "rotation"),
        ({**MINIMAL, "robot": {"dt": -0.1}}, "robot.dt", "(0, 1]"),
        ({**MINIMAL, "robot": {"dt": "fast"}}, "robot.dt", "number"),
        ({**MINIMAL, "trials": 0}, "trials", ">= 1"),
        ({**MINIMAL, "task": {"kind": "fixed", "start_mm": [375.0] * 5,
                              "goal_mm": [375.0] * 6}}, "task.start_mm", "6 leg lengths"),
        ({**MINIMAL, "calibration_error": {"base_points_mm": -1.0}},
         "calibration_error.base_points_mm", ">= 0"),
        ({**MINIMAL, "task": {"max_steps": [1, 2]}}, "task.max_steps", "sweepable"),
        ({"name": "t"}, "controllers", "missing"),
        ({**MINIMAL, "camera": {"preset": "fisheye"}}, "camera.preset", "front"),
        ({**MINIMAL, "controllers": ["a", "a"]}, "controllers", "duplicate"),
        ({**MINIMAL, "sensor": {"teach_frames": 0}}, "sensor.teach_frames", ">= 1"),
        ({**MINIMAL, "sensor": {"kind": "image", "teach_frames": 2.5}}, "sensor.teach_frames",
         "integer"),
        ({**MINIMAL, "sensor": {"teach_frames": [1, 10]}}, "sensor.teach_frames", "integer"),
        ({**MINIMAL, "sensor": {"blur": 1.0}}, "sensor.blur", "blur_px"),
    ],
)
def test_invalid_scenarios_name_the_key(table: dict, key: str, fragment: str) -> None:
    with pytest.raises(ScenarioError) as info:
        parse_scenario(table, "study.toml")
    msg = str(info.value)
    assert msg.startswith("study.toml")
    assert info.value.key == key
    assert fragment in msg


def test_typo_suggests_the_close_key() -> None:
    with pytest.raises(ScenarioError) as info:
        parse_scenario({**MINIMAL, "task": {"max_step": 10}}, "s.toml")
    assert info.value.suggestion == "max_steps"
    assert "did you mean 'max_steps'" in str(info.value)


def test_teach_frames() -> None:
    assert parse_scenario(MINIMAL).teach_frames == 1
    sc = parse_scenario({**MINIMAL, "sensor": {"kind": "image", "teach_frames": 10}})
    assert sc.sensor == "image" and sc.teach_frames == 10
    with pytest.raises(ScenarioError) as info:
        parse_scenario({**MINIMAL, "sensor": {"teach_frame": 10}}, "s.toml")
    assert info.value.key == "sensor.teach_frame"
    assert "did you mean 'teach_frames'" in str(info.value)


def test_scenario_file_errors(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text("name = 'x'\ncontrollers = [\n")
    with pytest.raises(ScenarioError, match="not valid TOML"):
        load_scenario(bad)
    with pytest.raises(ScenarioError, match="did you mean 'quick'"):
        load_scenario("quik")


def test_overrides() -> None:
    sc = load_scenario("quick").with_overrides(trials=3, seed=9, controllers=["leg-edge"])
    assert sc.trials == 3 and sc.seed == 9
    assert [c.name for c in sc.controllers] == ["leg-edge"]
    with pytest.raises(ScenarioError):
        sc.with_overrides(trials=0)
