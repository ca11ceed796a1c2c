"""``check`` and ``run`` share one pre-flight (:mod:`benchmarks.study.preflight`): over a
table of bad scenario files, both refuse with the same words; what only a plan shows
(options, actuation against the world, a trajectory's end stops and duration) is found
before any trial."""

from __future__ import annotations

from pathlib import Path

import pytest

from benchmarks.cli import main
from tests.benchmarks.ownrobot.robots import BLIND_CAMERA, own_robot

CRASH_FREE = "tests.benchmarks.plugins:ProportionalJoints"

#: name -> (scenario text, what the refusal says). Each is refused by both commands.
BAD = {
    "option typo in a controller table": (
        'controllers = [{name = "vision-ctc", natural_frequncy = 3.0}]\n'
        '[robot]\nworld = "dynamic"\n',
        "key 'controllers[0].natural_frequncy': controller 'vision-ctc' has no option "
        "'natural_frequncy'; its options: natural_frequency, damping, smooth_goal, "
        "integral_gain, saturation (hexapod-bench list --options vision-ctc) (did you mean "
        "'natural_frequency'?)"),
    "[controller_options] typo": (
        'controllers = ["leg-edge", "joint-space"]\n[controller_options]\n'
        "adaptve_gain = [5.0, 1.0, 30.0]\n",
        "key 'controller_options.adaptve_gain': no controller of the study takes this "
        "option (leg-edge: gain, adaptive_gain,"),
    "an option value refused": (
        'controllers = [{name = "leg-edge-qp", damping = 0.1}]\n',
        "key 'controllers[0].damping': leg-edge-qp: use 'regularization' with the QP law"),
    "unknown controller": (
        'controllers = ["leg-egde"]\n',
        "unknown controller 'leg-egde'"),
    "force controller in the kinematic world": (
        'controllers = ["leg-edge", "computed-torque"]\n',
        "key 'controllers[1]': controller 'computed-torque' commands leg forces [N], but "
        "the kinematic world applies only leg velocities [m/s]"),
    "physics step not dividing the period in the dynamic world": (
        'controllers = ["leg-edge"]\n[robot]\nworld = "dynamic"\ndt = 0.02\n'
        "physics_dt = 0.003\n",
        "key 'robot.physics_dt': the control period robot.dt (0.02 s) is not a whole number "
        "of physics steps of 0.003 s"),
    "every start of a trajectory hits an end stop": (
        'controllers = ["leg-edge"]\n[task]\nkind = "trajectory"\nshape = "circle"\n'
        "radius_mm = 60.0\nmax_translation_mm = 30.0\nmax_steps = 600\n",
        "the setup cannot run, every trial would fail: "),
    "blind camera": (
        'controllers = ["leg-edge"]\n[camera]\nfile = "camera.toml"\n',
        "the setup cannot run, every trial would fail: the camera sees no leg edge at the "
        "home pose"),
    "empty workspace (strokes too short for the robot)": (
        'controllers = ["leg-edge"]\n[robot]\ngeometry = "short.toml"\n',
        "the setup cannot run, every trial would fail: empty workspace, no home pose"),
    "unreachable fixed goal": (
        'controllers = ["leg-edge"]\n[robot]\ngeometry = "long.toml"\n[task]\n'
        'kind = "fixed"\nstart_mm = [460, 460, 460, 460, 460, 460]\n'
        "goal_mm = [990, 260, 600, 600, 600, 600]\n",
        "the setup cannot run, every trial would fail: task.goal_mm: no platform pose near "
        "the home pose has these six leg lengths"),
    "a value out of its range": (
        'controllers = ["leg-edge"]\n[noise]\nmodel = "rotation"\namplitude_deg = 1e9\n',
        "key 'noise.amplitude_deg': 1000000000.0 deg is out of the allowed range [0, 90] deg"),
}


def _write(folder: Path, body: str) -> Path:
    (folder / "camera.toml").write_text(BLIND_CAMERA)
    own_robot(stroke=(0.100, 0.150)).to_toml(folder / "short.toml")
    own_robot(stroke=(0.250, 1.000)).to_toml(folder / "long.toml")
    path = folder / "study.toml"
    path.write_text(f'name = "bad"\ntrials = 2\n{body}')
    return path


def _call(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = main(args)
    cap = capsys.readouterr()
    return code, cap.out, cap.err


def _refusal(stderr: str) -> list[str]:
    return [line for line in stderr.splitlines() if line.startswith("hexapod-bench: error:")]


@pytest.mark.parametrize("case", sorted(BAD))
def test_check_and_run_refuse_alike(case: str, tmp_path: Path,
                                    capsys: pytest.CaptureFixture[str]) -> None:
    body, expected = BAD[case]
    study = _write(tmp_path, body)
    out = tmp_path / "out"
    c_code, _, c_err = _call(["check", str(study)], capsys)
    r_code, r_out, r_err = _call(["run", str(study), "--out", str(out), "--no-progress"],
                                 capsys)
    assert r_code == 2, r_err  # run refuses before any trial
    assert not (out / "results.jsonl").exists() and r_out == ""
    assert c_code in (1, 2)  # check: 2 a file error, 1 a setup that cannot run
    assert _refusal(c_err) == _refusal(r_err) and len(_refusal(r_err)) == 1, (c_err, r_err)
    assert expected in _refusal(r_err)[0]
    # the other messages (the warnings) are the same too
    assert [x for x in c_err.splitlines() if "warning" in x] == [
        x for x in r_err.splitlines() if "warning" in x]


def test_the_kinematic_world_has_no_physics_step(tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    study = _write(tmp_path, f'controllers = ["{CRASH_FREE}"]\n[robot]\ndt = 0.02\n'
                             "physics_dt = 0.003\n")
    code, out, err = _call(["check", str(study)], capsys)
    assert code == 0, err
    assert "The setup can run." in out


def test_mixed_study_options_go_to_the_controllers_that_declare_them(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from benchmarks.study.preflight import preflight
    from benchmarks.study.scenario import load_scenario

    study = _write(tmp_path, 'controllers = ["leg-edge", "computed-torque"]\n'
                             "[controller_options]\nadaptive_gain = [5.0, 1.0, 30.0]\n"
                             "natural_frequency = 3.0\n"
                             '[robot]\nworld = "dynamic"\n')
    pre = preflight([load_scenario(study)], measure=False)
    leg_edge, ctc = pre.scenarios[0].controllers
    assert leg_edge.options == {"adaptive_gain": [5.0, 1.0, 30.0]}
    assert ctc.options == {"natural_frequency": 3.0}
    assert pre.warnings == []
    code, out, err = _call(["check", str(study)], capsys)
    assert code == 0 and "No problem found." in out, err


def test_trajectory_duration_and_end_stops_are_stated(tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]
                                                      ) -> None:
    study = _write(tmp_path, 'controllers = ["leg-edge"]\ntrials = 40\n[task]\n'
                             'kind = "trajectory"\nshape = "circle"\nradius_mm = 15.0\n'
                             "speed_mm_s = 20.0\nmax_steps = 300\n")
    study.write_text(study.read_text().replace("trials = 2\n", ""))
    code, out, err = _call(["check", str(study)], capsys)
    assert code == 0, err
    from benchmarks.study.scenario import load_scenario
    from benchmarks.study.trajectory_check import trajectory_facts

    facts = trajectory_facts(load_scenario(study))[0]
    lo, hi = facts.duration_s
    # a circle of 15 mm at 20 mm/s lasts 2 pi 15 / 20 = 4.7 s at full speed, more with
    # the quintic's acceleration: longer than 300 x 20 ms
    assert 2 * 3.14159 * 15 / 20 < lo <= hi and hi > 6.0 and facts.sampled == 40
    assert f"the reference lasts {lo:.2f}" in out and "max_steps x dt = 6.00 s" in out
    assert (f"warning: the reference lasts up to {hi:.2f} s, longer than max_steps x dt = "
            f"300 x 20 ms = 6.00 s: the trials stop before it ends; raise [task] max_steps "
            f"to at least {int(-(-(hi + 0.5) // 0.02))}") in out
    assert f"{facts.hits} of 40 sampled starts" in out
    if facts.hits:
        assert "would hit an end stop following the circle reference" in out
        assert f"set margin_mm >= {int(-(-facts.travel_mm // 1))}" in out


@pytest.mark.slow
def test_end_stop_estimate_is_the_runs_own(tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    """The estimate samples the run's own starts: in the kinematic world, the trials that
    push a leg against its stroke are those whose reference leaves it."""
    import json

    from benchmarks.study.scenario import load_scenario
    from benchmarks.study.trajectory_check import trajectory_facts

    study = _write(tmp_path, f'controllers = ["{CRASH_FREE}"]\n[task]\n'
                             'kind = "trajectory"\nshape = "circle"\nradius_mm = 15.0\n'
                             "max_steps = 300\n")
    study.write_text(study.read_text().replace("trials = 2", "trials = 40"))
    facts = trajectory_facts(load_scenario(study))[0]
    assert 0 < facts.hits < 40
    code, _, err = _call(["run", str(study), "--out", str(tmp_path / "o"), "--no-progress",
                          "--record", "0"], capsys)
    assert code == 0, err
    assert f"{facts.hits} of 40 sampled starts" in err
    rows = [json.loads(x) for x in (tmp_path / "o" / "results.jsonl").read_text().splitlines()]
    pushed = sum(1 for r in rows if r["stroke_violations"])
    assert pushed == facts.hits


def test_run_and_check_warn_alike_on_an_option_left_out(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``--controllers`` chooses a controller that does not take the file's
    ``[controller_options]``: the option is left out with a warning (not refused: the
    file's keys were written for its own controllers)."""
    from benchmarks.study.preflight import preflight
    from benchmarks.study.scenario import load_scenario

    sc = load_scenario("quick").with_overrides(controllers=[CRASH_FREE])
    pre = preflight([sc], measure=False)
    assert pre.scenarios[0].controllers[0].options == {}
    assert len(pre.warnings) == 1
    assert pre.warnings[0].startswith("[controller_options] adaptive_gain of ")
    assert "no controller chosen by --controllers" in pre.warnings[0]


def test_check_closes_with_the_warnings_it_printed(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """An unstable integral gain is warned of on stderr by check as by run; the last lines
    said 'No problem found.' under it (read as all clear): they count the warnings."""
    from benchmarks.cli import main

    study = tmp_path / "ki.toml"
    study.write_text('name = "ki"\ntrials = 1\ncontrollers = [{ name = "computed-torque", '
                     'integral_gain = 30.0 }]\n[robot]\nworld = "dynamic"\n')
    assert main(["check", str(study)]) == 0
    captured = capsys.readouterr()
    assert "integral_gain 30 1/s is not below 2 damping omega_n" in captured.err
    assert "No problem found in the setup; 1 warning(s) about the study above" in captured.out
    assert "No problem found." not in captured.out


def test_settings_without_effect_where_the_study_runs_are_warned_of() -> None:
    """Mass and drive errors in the kinematic world, a payload's mass error without a
    payload: accepted without a word, and nothing changed; the built-ins have none."""
    from benchmarks.study.preflight import dynamics_only
    from benchmarks.study.scenario import builtin_scenarios, load_scenario, parse_scenario

    sc = parse_scenario({"name": "k", "controllers": ["leg-edge"], "calibration_error": {
        "mass_percent": 10.0, "model_friction_error_percent": 20.0,
        "payload_mass_percent": 5.0}})
    said = dynamics_only(sc)
    assert len(said) == 2
    assert "mass_percent, model_friction_error_percent: errors of the robot's masses" in said[0]
    assert "payload_mass_percent: the error of a payload's mass" in said[1]
    dynamic = parse_scenario({"name": "d", "controllers": ["leg-edge"], "robot": {
        "world": "dynamic"}, "calibration_error": {"mass_percent": 10.0}})
    assert dynamics_only(dynamic) == []
    assert not any(dynamics_only(load_scenario(n)) for n in builtin_scenarios())


def test_settings_the_sensor_or_noise_model_does_not_read_are_warned_of() -> None:
    """A noise amplitude without its model (the default is none), rendering keys with the
    geometric sensor, a lens error the geometric features never meet: sweeps of identical
    points, accepted without a word; the built-ins have none."""
    from benchmarks.study.preflight import without_effect
    from benchmarks.study.scenario import builtin_scenarios, load_scenario, parse_scenario

    sc = parse_scenario({"name": "n", "controllers": ["leg-edge"],
                         "noise": {"amplitude_deg": [0.0, 0.1]},
                         "sensor": {"blur_px": 1.5},
                         "calibration_error": {"distortion_percent": [0.0, 100.0]}})
    said = without_effect(sc)
    assert len(said) == 3, said
    assert "[noise] amplitude_deg: read by model = \"rotation\" only, and the model is " \
           "'none' (the default): no effect" in said[0]
    assert "[sensor] blur_px: settings of rendered images, and the sensor is 'geometric'" \
        in said[1]
    assert "[calibration_error] distortion_percent: an error of the camera model's lens" \
        in said[2]
    pixel = parse_scenario({"name": "p", "controllers": ["leg-edge"], "noise": {
        "model": "rotation", "pixel_sigma_px": 0.5}})
    assert "[noise] pixel_sigma_px: read by model = \"pixel\" only" in without_effect(pixel)[0]
    read = parse_scenario({"name": "r", "controllers": ["leg-edge"], "noise": {
        "model": "pixel", "pixel_sigma_px": 0.5},
        "calibration_error": {"distortion_percent": 100.0}})
    assert without_effect(read) == []
    assert not any(without_effect(load_scenario(n)) for n in builtin_scenarios())
    # a jitter mostly clipped to 0.45 frame (100 ms at a 20 ms frame ran without a word)
    jitter = parse_scenario({"name": "j", "controllers": ["leg-edge"],
                             "clock": {"jitter_ms": [2.0, 100.0]}})
    said = without_effect(jitter)
    assert len(said) == 1 and "[clock] jitter_ms = 100: a capture time is clipped to +-9 ms " \
        "(0.45 of a 20 ms frame), and 93 % of them would be" in said[0], said


def test_a_problem_found_at_every_sweep_point_is_said_once() -> None:
    """A reference too fast for the legs was warned of six times, once per payload of
    the sweep, in the same words: once now, at every sweep point; a problem of one point
    keeps its point, and one of the study (no point) its text, whatever it ends with
    (the point was parsed back out of the text's end)."""
    from benchmarks.study.preflight import _merged
    from benchmarks.study.setup_check import Problem

    fast = "the circle reference moves a leg at up to 93.1 mm/s in s.toml"
    found = [Problem("warning", fast, "robot", point=f"payload.mass_kg = {m}")
             for m in (0, 20, 40)]
    found.append(Problem("warning", "85 kg cannot be held", "robot",
                         point="payload.mass_kg = 40"))
    found += [Problem("error", f"no start can be held in study.toml (sweep point {k})")
              for k in (1, 2)]  # (a study's own texts: the regex merged these two)
    merged = _merged(found, 3)
    assert [p.text for p in merged] == [
        f"{fast} (every sweep point)",
        "85 kg cannot be held (sweep point payload.mass_kg = 40)",
        "no start can be held in study.toml (sweep point 1)",
        "no start can be held in study.toml (sweep point 2)"]
    assert all(p.point == "" for p in merged)
    assert _merged(found[:2], 3)[0].text == (f"{fast} (sweep points payload.mass_kg = 0; "
                                             "payload.mass_kg = 20)")


def test_a_controller_named_twice_on_the_command_line_is_refused(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """--controllers leg-edge,leg-edge ran every trial twice under one label (tune: every
    candidate twice), and the rows were then duplicates; refused before anything runs."""
    for command in (["run", "quick", "--trials", "1"],
                    ["tune", "quick", "--trials", "2", "--candidates", "2"]):
        out = tmp_path / command[0]
        assert main([*command, "--controllers", "leg-edge,leg-edge", "--out", str(out)]) == 2
        assert "--controllers: leg-edge given twice" in capsys.readouterr().err
        assert not out.exists()


def test_a_calibration_that_fails_is_said_before_the_run() -> None:
    """Every trial failed at its calibration (legs under the file's own hard limit), and
    check had said "No problem found": the sampled trials' calibrations, run as the study
    runs them, say so; the built-in that calibrates has none."""
    from benchmarks.study.calibration_check import calibration_problems
    from benchmarks.study.scenario import load_scenario, parse_scenario

    sc = parse_scenario({"name": "c", "controllers": ["leg-edge"],
                         "calibration_error": {"base_points_mm": 3.0},
                         "calibration": {"method": "linear", "configurations": "random:20",
                                         "warn_singular_ratio": 0.9,
                                         "min_singular_ratio": 0.5}}, "c.toml")
    said = calibration_problems(sc)
    assert len(said) == 1 and said[0].severity == "warning"
    assert said[0].text.startswith("the calibration of 3 of 3 sampled trials fails "
                                   "(calibration: leg 0: ill-conditioned"), said[0].text
    assert "change [calibration] in c.toml" in said[0].text
    assert calibration_problems(load_scenario("andreff2005-noise")) == []
