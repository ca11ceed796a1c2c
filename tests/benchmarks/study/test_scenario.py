"""Scenario files: validation errors name the file, the key and the expectation."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from benchmarks.exceptions import ScenarioError
from benchmarks.study.scenario import builtin_scenarios, load_scenario, parse_scenario

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
        ({**MINIMAL, "robot": {"dt": 20}}, "robot.dt",
         "20.0 s is out of the allowed range (0, 1] s (a slip of units? robot.dt is in s; "
         "0.02 s would be in range)"),
        ({**MINIMAL, "robot": {"dt": "fast"}}, "robot.dt", "number"),
        ({**MINIMAL, "trials": 0}, "trials", "out of the allowed range [1, 1e+07]"),
        ({**MINIMAL, "task": {"kind": "fixed", "start_mm": [375.0] * 5,
                              "goal_mm": [375.0] * 6}}, "task.start_mm",
         "6 leg lengths [mm], got 5"),
        ({**MINIMAL, "calibration_error": {"base_points_mm": -1.0}},
         "calibration_error.base_points_mm", "out of the allowed range [0, 100]"),
        ({**MINIMAL, "task": {"max_steps": [1, 2]}}, "task.max_steps", "sweepable"),
        ({"name": "t"}, "controllers", "missing"),
        ({**MINIMAL, "camera": {"preset": "wide-angle"}}, "camera.preset", "front"),
        ({**MINIMAL, "controllers": ["a", "a"]}, "controllers", "duplicate"),
        ({**MINIMAL, "sensor": {"teach_frames": 0}}, "sensor.teach_frames", "[1, 1000]"),
        # values that parse but cannot run (found by mutating the built-in scenarios)
        ({**MINIMAL, "seed": -1}, "seed", "-1 is out of the allowed range [0,"),
        ({**MINIMAL, "calibration_error": {"platform_points_mm": 1e308}},
         "calibration_error.platform_points_mm", "1e+308 mm is out of the allowed range"),
        ({**MINIMAL, "calibration_error": {"scale": [1.0, 50.0], "base_points_mm": 3.0}},
         "calibration_error.base_points_mm",
         "times scale 50 gives a standard deviation of 150 mm, beyond the allowed 100 mm"),
        ({**MINIMAL, "noise": {"model": "rotation", "amplitude_deg": 1e9}},
         "noise.amplitude_deg", "1000000000.0 deg is out of the allowed range [0, 90] deg"),
        ({**MINIMAL, "noise": {"model": "rotation", "amplitude_deg": [0.0, 100.0]}},
         "noise.amplitude_deg", "100.0 deg is out of the allowed range [0, 90] deg"),
        ({**MINIMAL, "noise": {"dropout_probability": 1.5}}, "noise.dropout_probability",
         "[0, 1]"),
        # strings in a list of numbers were converted without a word
        ({**MINIMAL, "robot": {"world": "dynamic"}, "payload": {
            "mass_kg": 1.0, "com_mm": ["0", "0", "-50"]}}, "payload.com_mm",
         "expected a list of numbers, got ['0', '0', '-50']"),
        ({**MINIMAL, "task": {"max_steps": 10, "settle_steps": 20}}, "task.settle_steps",
         "exceeds task.max_steps"),
        ({**MINIMAL, "task": {"kind": "fixed", "start_mm": [375.0] * 6,
                              "goal_mm": [375.0] * 5 + [9000.0]}}, "task.goal_mm",
         "leg 5: 9000 mm is outside the stroke"),
        ({**MINIMAL, "calibration": {"configurations": "random:1"}},
         "calibration.configurations", "integer N in [2, 100000]"),
        ({**MINIMAL, "calibration": {"min_singular_ratio": 0.1}},
         "calibration.min_singular_ratio", "must be below the warning"),
        ({**MINIMAL, "sensor": {"kind": "image", "teach_frames": 2.5}}, "sensor.teach_frames",
         "integer"),
        # (it said "expected an integer", not that a list is a sweep axis this key is not)
        ({**MINIMAL, "sensor": {"teach_frames": [1, 10]}}, "sensor.teach_frames",
         "expected one value, got the list [1, 10]: this key cannot be swept"),
        ({**MINIMAL, "robot": {"dt": [0.01, 0.02]}}, "robot.dt", "this key cannot be swept"),
        ({**MINIMAL, "sensor": {"blur": 1.0}}, "sensor.blur", "blur_px"),
        # a trajectory's keys in a point-to-point task (ran that task without a word)
        ({**MINIMAL, "task": {"shape": "circle", "radius_mm": 15.0}}, "task.shape",
         "only a trajectory task reads it (kind = \"trajectory\"); this task is "
         "'random-pairs'"),
        ({**MINIMAL, "task": {"kind": "fixed", "start_mm": [375.0] * 6, "goal_mm": [380.0] * 6,
                              "speed_mm_s": 20.0}}, "task.speed_mm_s", "this task is 'fixed'"),
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


def test_controller_options_are_checked_when_the_study_is_loaded(tmp_path: Path) -> None:
    from benchmarks.cli import main
    from benchmarks.study.scenario import check_controllers

    table = {**MINIMAL, "controllers": ["leg-direction",
                                        {"name": "leg-edge", "adaptive_gain": [float("nan"),
                                                                              1.0, 1.0]}]}
    with pytest.raises(ScenarioError) as info:
        check_controllers(parse_scenario(table, "study.toml"))
    assert info.value.key == "controllers[1].adaptive_gain"
    assert "finite" in str(info.value)
    with pytest.raises(ScenarioError) as info:
        check_controllers(parse_scenario({**MINIMAL, "controllers": [
            {"name": "leg-edge", "gian": 2.0}]}, "study.toml"))
    assert info.value.key == "controllers[0].gian" and "gain" in str(info.value)
    study = tmp_path / "nan.toml"
    study.write_text('name = "t"\ncontrollers = [{name = "leg-edge", gain = nan}]\n')
    out = tmp_path / "out"
    assert main(["run", str(study), "--out", str(out), "--no-progress"]) == 2
    assert not (out / "results.jsonl").exists(), "nothing ran"


def test_a_controller_s_own_gain_is_not_replaced_by_a_file_wide_adaptive_gain(
        caplog: pytest.LogCaptureFixture) -> None:
    """[controller_options] adaptive_gain replaces gain: a controller whose own table sets
    gain keeps it (its rows were those of the file-wide adaptive gain, its own gain, even
    a negative one, unread); a table giving both is warned of; a bad gain is refused even
    beside an adaptive one."""
    from benchmarks.study.scenario import check_controllers

    table = {**MINIMAL, "controller_options": {"adaptive_gain": [5.0, 1.0, 30.0]},
             "controllers": ["leg-edge", {"name": "leg-edge", "label": "own", "gain": 3.0},
                             {"name": "leg-direction", "adaptive_gain": [2.0, 1.0, 5.0]}]}
    specs = {s.label: s for s in parse_scenario(table, "study.toml").controllers}
    assert specs["leg-edge"].options == {"adaptive_gain": [5.0, 1.0, 30.0]}
    assert specs["own"].options == {"gain": 3.0}
    assert specs["leg-direction"].options == {"adaptive_gain": [2.0, 1.0, 5.0]}
    both = {**MINIMAL, "controllers": [{"name": "leg-edge", "gain": 3.0,
                                        "adaptive_gain": [5.0, 1.0, 30.0]}]}
    with caplog.at_level(logging.WARNING):  # (a run's kept scenario of before holds both)
        (spec,) = parse_scenario(both, "study.toml").controllers
    assert spec.options == {"gain": 3.0, "adaptive_gain": [5.0, 1.0, 30.0]}
    assert "key 'controllers[0]': adaptive_gain and gain both given" in caplog.text
    negative = {**MINIMAL, "controllers": [{"name": "leg-edge", "gain": -1.0}],
                "controller_options": {"adaptive_gain": [5.0, 1.0, 30.0]}}
    with pytest.raises(ScenarioError) as info:
        check_controllers(parse_scenario(negative, "study.toml"))
    assert info.value.key == "controllers[0].gain" and "-1.0" in str(info.value)
    from controllers.exceptions import OptionError
    from controllers.law_tools import Gain

    with pytest.raises(OptionError, match="gain"):  # beside an adaptive gain too
        Gain.from_options("leg-edge", -1.0, [5.0, 1.0, 30.0])


def test_camera_from_an_opencv_calibration_file(tmp_path: Path) -> None:
    """[camera] opencv = "cal.yml" with the pose of the front preset (or a pose table):
    the intrinsics and the lens come from the file, read when the scenario is loaded."""
    import numpy as np

    from benchmarks.sim import load_camera as scenario_camera
    from benchmarks.sim import run_trials
    from hexapod import deltalab
    from vision.cameras import front_camera, save_opencv_camera

    lens = front_camera(deltalab()).replace(distortion=(-0.28, 0.09, 0.0, 0.0, -0.012))
    save_opencv_camera(lens, tmp_path / "cal.yml")
    study = tmp_path / "s.toml"
    study.write_text('name = "lens"\ntrials = 1\ncontrollers = [{name = "leg-edge", gain = 4.0}]'
                     '\n[camera]\nopencv = "cal.yml"\npose = "front"\n'
                     '[task]\nmax_steps = 150\nposition_tolerance_mm = 0.5\n'
                     'orientation_tolerance_deg = 0.05\n')
    sc = load_scenario(study)
    cam = scenario_camera(sc, deltalab())
    np.testing.assert_allclose(cam.distortion, lens.distortion)
    np.testing.assert_allclose(cam.K, lens.K)
    np.testing.assert_allclose(cam.camera_from_base.as_matrix(),
                               lens.camera_from_base.as_matrix(), atol=1e-12)
    row = run_trials(sc, 0, [0])[0].row
    assert row["converged"], row
    # a pose table instead of the preset, and the errors
    study.write_text('name = "lens"\ncontrollers = ["leg-edge"]\n[camera]\nopencv = "cal.yml"\n'
                     '[camera.camera_from_base]\ntranslation_mm = [0, 0, 800]\n')
    assert load_scenario(study).camera_data.camera_from_base.translation[2] == 0.8
    for body, key, fragment in (
            ('opencv = "cal.yml"\npreset = "front"', "camera", "not preset and opencv"),
            ('preset = "front"\npose = "front"', "camera.pose", "only with 'opencv'"),
            ('opencv = "missing.yml"', None, "missing.yml"),
            ('opencv = "cal.yml"\npose = "side"', "camera.pose", "front, omni"),
            # (it said "key 'camera.height_px': expected an integer, got None")
            ('opencv = "cal.yml"\npose = "front"\nwidth_px = 1024', "camera.height_px",
             "width_px needs height_px")):
        study.write_text(f'name = "x"\ncontrollers = ["leg-edge"]\n[camera]\n{body}\n')
        with pytest.raises(ScenarioError) as info:
            load_scenario(study)
        if key is not None:
            assert info.value.key == key, str(info.value)
        assert fragment in str(info.value).replace("'preset' and 'opencv'", "preset and opencv")


def test_a_camera_model_that_misses_the_distortion(tmp_path: Path) -> None:
    """calibration_error.distortion_percent: the model's coefficients are the true ones
    times 1 - p/100 (100: a model without distortion); the true camera keeps its lens."""
    import numpy as np

    from benchmarks.sim import load_camera as scenario_camera
    from benchmarks.sim import load_geometry, make_trial
    from hexapod import deltalab
    from vision.cameras import front_camera

    lens = front_camera(deltalab()).replace(distortion=(-0.28, 0.09, 0.0, 0.0, -0.012))
    lens.to_toml(tmp_path / "lens.toml")
    study = tmp_path / "s.toml"
    study.write_text('name = "lens"\ncontrollers = ["leg-edge"]\n[camera]\nfile = "lens.toml"\n'
                     '[calibration_error]\ndistortion_percent = [0.0, 50.0, 100.0]\n')
    points = load_scenario(study).expand()
    assert [p.sweep["calibration_error.distortion_percent"] for p in points] == [0, 50, 100]
    for p, factor in zip(points, (1.0, 0.5, 0.0), strict=True):
        nominal = load_geometry(p)
        setup = make_trial(p, 0, nominal, scenario_camera(p, nominal))
        np.testing.assert_allclose(setup.world.camera.distortion, lens.distortion)
        np.testing.assert_allclose(setup.estimated_camera.distortion,
                                   np.asarray(lens.distortion) * factor)
        assert setup.shared, "a lens-model error alone keeps the true world nominal"
    with pytest.raises(ScenarioError, match="out of the allowed range"):
        parse_scenario({**MINIMAL, "calibration_error": {"distortion_percent": 150.0}})


def test_gains_beyond_the_documented_bounds_are_warned_of() -> None:
    """A first-order gain at 2/dt (the discrete loop unstable) and a computed-torque
    integral gain at 2 damping omega_n (unstable with an exact model) are warned of before
    any trial, naming the controller, the value and the bound (a natural frequency in
    rad/s, an integral gain of 500: every trial hit an end stop without a word); the
    built-in scenarios' gains are within them."""
    from benchmarks.study.scenario import builtin_scenarios
    from benchmarks.study.scenario_checks import check_controllers

    sc = parse_scenario({**MINIMAL, "robot": {"world": "dynamic"}, "controllers": [
        {"name": "leg-edge", "gain": 100.0},
        {"name": "computed-torque", "natural_frequency": 2.0, "integral_gain": 500.0},
        {"name": "vision-ctc", "natural_frequency": 2.0, "integral_gain": 20.0}]})
    warnings = check_controllers(sc)[1]
    assert any(w.startswith("leg-edge: gain 100 1/s is at least 2/dt = 100 1/s (robot.dt "
                            "20 ms)") for w in warnings), warnings
    assert any(w.startswith("computed-torque: integral_gain 500 1/s is not below 2 damping "
                            "omega_n = 25.1 1/s") for w in warnings), warnings
    assert not any(w.startswith("vision-ctc") for w in warnings)  # 20 < 25.1
    for name in builtin_scenarios():
        said = check_controllers(load_scenario(name))[1]
        assert not any("2/dt" in w or "omega_n" in w for w in said), (name, said)


def test_first_order_laws_under_different_gain_schedules_are_warned_of(tmp_path: Path
                                                                        ) -> None:
    """A study whose first-order laws run under different gain schedules (one given
    quick's adaptive gain, the others left at their constant default: payload-saturation
    compared them so) is warned of, naming each law's schedule; one schedule for all
    ([controller_options]) or gains from an options file (tuned) is not; of the
    built-in scenarios none is."""
    from benchmarks.study.options_file import apply_options_file, load_options_file
    from benchmarks.study.scenario import builtin_scenarios
    from benchmarks.study.scenario_checks import check_controllers

    laws = [{"name": "leg-edge", "adaptive_gain": [5.0, 1.0, 30.0]}, "joint-space",
            {"name": "leg-edge-mpc", "label": "mpc", "gain": 2.0}, "computed-torque"]
    study = {**MINIMAL, "robot": {"world": "dynamic"}, "controllers": laws}
    (said,) = [w for w in check_controllers(parse_scenario(study))[1] if "gain sched" in w]
    assert ("the first-order laws run under different gain schedules (leg-edge: "
            "adaptive_gain [5.0, 1.0, 30.0]; joint-space: constant gain 1 1/s; mpc: constant "
            "gain 2 1/s): their comparison measures the gains") in said
    assert "computed-torque" not in said  # (no first-order gain)
    same = {**study, "controllers": ["leg-edge", "joint-space", "computed-torque"],
            "controller_options": {"adaptive_gain": [5.0, 1.0, 30.0]}}
    assert not [w for w in check_controllers(parse_scenario(same))[1] if "gain sched" in w]
    tuned = tmp_path / "tuned.toml"
    tuned.write_text('[controllers."joint-space"]\ngain = 3.0\n[controllers.mpc]\n'
                     'adaptive_gain = [4.0, 1.0, 20.0]\n')
    (sc,) = apply_options_file([parse_scenario(study)], load_options_file(tuned))
    assert not [w for w in check_controllers(sc)[1] if "gain sched" in w]
    for name in builtin_scenarios():
        assert not [w for w in check_controllers(load_scenario(name))[1]
                    if "gain sched" in w], name


@pytest.mark.parametrize(("reference", "key", "says"), [
    # a flat rows: every trial ran, then the report crashed ('float' object is not iterable)
    ({"header": ["a", "b"], "rows": [0.01, 0.1]}, "reference.rows[0]",
     "expected a list of rows of 2 values (one per header column), got 0.01"),
    ({"header": ["a", "b"], "rows": 3}, "reference.rows", "(not a list)"),
    ({"header": ["a", "b"], "rows": [[1, 2, 3]]}, "reference.rows[0]", "rows of 2 values"),
    # a misspelt key: the table was left out without a word
    ({"header": ["a"], "row": [[1]]}, "reference.row", "did you mean 'rows'?"),
    ({"header": ["a"]}, "reference.rows", "a table needs both header and rows: rows missing"),
    ({"text": 3}, "reference.text", "expected a string, got 3"),
])
def test_a_bad_reference_table_is_refused_naming_the_key(
        reference: dict, key: str, says: str) -> None:
    with pytest.raises(ScenarioError) as info:
        parse_scenario({"name": "x", "controllers": ["leg-edge"], "reference": reference})
    assert info.value.key == key and says in str(info.value), str(info.value)


@pytest.mark.parametrize("method", ["linear", "none"])
def test_a_calibration_file_without_method_file_is_refused(method: str) -> None:
    """It was ignored (a missing file too) and a calibration of the study's own ran."""
    with pytest.raises(ScenarioError) as info:
        parse_scenario({"name": "x", "controllers": ["leg-edge"], "calibration": {
            "method": method, "file": "nothere.toml"}})
    assert info.value.key == "calibration.file"
    assert f"read by method = \"file\" only, and the method is '{method}'" in str(info.value)
