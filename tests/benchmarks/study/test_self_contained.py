"""Self-contained runs (issue 28, item 5): the run directory keeps the scenario and every file
it names, the report lists the settings, fixed-duration trials say what ended outside the
tolerances, ``run --help`` says what ``--record`` keeps and ``viz`` points to it."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import pytest

from benchmarks.cli import main as cli_main
from benchmarks.sim.tolerance import unconverged_reason
from benchmarks.study.runner import read_results
from hexapod import deltalab
from vision.cameras import camera_preset


@pytest.fixture
def lab(tmp_path: Path) -> Path:
    """A scenario naming a robot file in a sub-folder, a camera file and a sweep."""
    folder = tmp_path / "lab"
    (folder / "robots").mkdir(parents=True)
    g = deltalab()
    g.to_toml(folder / "robots" / "robot.toml")
    camera_preset("front", g).to_toml(folder / "cam.toml")
    (folder / "study.toml").write_text(
        'name = "mine"\ntrials = 3\n'
        'controllers = ["leg-edge", {name = "joint-space", label = "joints", gain = 2.0}]\n'
        '[robot]\ngeometry = "robots/robot.toml"\n[camera]\nfile = "cam.toml"\n'
        '[noise]\nmodel = "rotation"\namplitude_deg = [0.01, 0.05]\n'
        '[calibration_error]\nbase_points_mm = 1.0\ncamera_pose_deg = 0.1\n'
        '[task]\nmax_steps = 60\nfixed_duration = true\norientation_tolerance_deg = 0.002\n')
    return folder / "study.toml"


def _outcomes(out: Path) -> list[tuple[str, int, int, float]]:
    return sorted((r["controller"], r["point"], r["trial"], r["final_position_error_mm"])
                  for r in read_results(out))


@pytest.mark.slow
def test_the_run_keeps_the_scenario_and_every_file_it_names(
        lab: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cal = tmp_path / "cal"
    assert cli_main(["calibrate", str(lab), "--out", str(cal)]) == 0
    out = tmp_path / "run"
    assert cli_main(["run", str(lab), "--out", str(out), "--no-progress", "--trials", "2",
                     "--calibration", str(cal / "calibrated.toml")]) == 0
    kept = out / "inputs" / "mine"
    assert sorted(p.name for p in kept.iterdir()) == [
        "calibrated.toml", "cam.toml", "robot.toml", "scenario.toml", "source.toml"]
    assert (kept / "source.toml").read_bytes() == lab.read_bytes()
    assert (kept / "robot.toml").read_bytes() == (lab.parent / "robots/robot.toml").read_bytes()
    assert (kept / "calibrated.toml").read_bytes() == (cal / "calibrated.toml").read_bytes()
    meta = json.loads((out / "run.json").read_text())["scenarios"]["mine"]
    assert meta["inputs"]["folder"] == "inputs/mine"
    assert set(meta["inputs"]["files"]) == {p.name for p in kept.iterdir()}
    # the copy runs on its own, with the overrides of the command line, and gives the same
    # trials (the lab folder is gone)
    for p in sorted(lab.parent.rglob("*"), reverse=True):
        p.rmdir() if p.is_dir() else p.unlink()
    again = tmp_path / "again"
    assert cli_main(["run", str(kept / "scenario.toml"), "--out", str(again),
                     "--no-progress"]) == 0
    assert _outcomes(again) == _outcomes(out)
    report = (out / "report.md").read_text()
    for line in ("- robot: robot.toml (leg radius 15 mm, strokes [345, 485] mm), dt 20 ms",
                 "- camera: cam.toml (perspective, 1024x780 px, fx 1032.3 px)",
                 "- noise: rotation: amplitude_deg 0.01",
                 "- calibration error: base_points_mm 1, camera_pose_deg 0.1",
                 "- calibration: file (calibrated.toml)",
                 "- task: random-pairs, 60 steps (fixed duration), tolerances 0.1 mm and "
                 "0.002 deg",
                 "- trials: 2 per sweep point and controller, seed 1",
                 "- swept noise.amplitude_deg: 0.01, 0.05",
                 f"- files: the scenario and every file it names are kept in `inputs/mine/` "
                 f"(rerun: `hexapod-bench run {out}/inputs/mine/scenario.toml --out NEW_DIR`)"):
        assert line in report, line


@pytest.mark.slow
def test_a_resumed_run_keeps_its_copy_and_warns_when_the_file_changed(
        lab: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run"
    assert cli_main(["run", str(lab), "--out", str(out), "--no-progress"]) == 0
    original = lab.read_text()
    lab.write_text(original.replace("trials = 3", "trials = 4"))
    capsys.readouterr()
    assert cli_main(["run", str(lab), "--out", str(out), "--no-progress", "--resume"]) == 0
    captured = capsys.readouterr()
    assert f"warning: {lab} differs from the copy this run started with " \
        f"({out}/inputs/mine/source.toml, kept); the study it describes was checked " \
        "against the directory's, setting by setting" in captured.err
    assert (out / "inputs" / "mine" / "source.toml").read_text() == original
    # more trials, everything else the same: the study grows, and the runnable copy says so
    assert "growing the study: grew mine from 3 to 4 trials" in " ".join(captured.out.split())
    assert "\ntrials = 4\n" in (out / "inputs" / "mine" / "scenario.toml").read_text()
    assert len(read_results(out)) == 2 * 2 * 4
    # another change in the file: refused, the copy and the rows untouched
    lab.write_text(original.replace("max_steps = 60", "max_steps = 70"))
    assert cli_main(["run", str(lab), "--out", str(out), "--no-progress", "--resume"]) == 2
    assert "--max-steps: 60 in the directory, 70 given" in capsys.readouterr().err
    assert len(read_results(out)) == 2 * 2 * 4


@pytest.mark.parametrize(("position", "rotation", "expected"), [
    (0.055, 0.0565, "not converged: rotation 0.0565 deg > 0.05 deg after 800 steps"),
    (0.3, 0.01, "not converged: position 0.3 mm > 0.1 mm after 800 steps"),
    (0.3, 0.2, "not converged: position 0.3 mm > 0.1 mm and rotation 0.2 deg > 0.05 deg "
               "after 800 steps"),
    (0.10004, 0.0, "not converged: position 0.10004 mm > 0.1 mm after 800 steps"),
    (0.1, 0.0, "not converged: position 0.1 mm not below 0.1 mm after 800 steps"),
    (float("nan"), 0.0, "not converged: position nan mm after 800 steps"),
    (0.01, 0.01, "not converged within 800 steps: within the tolerances at the end but not "
                 "for 5 consecutive periods"),
])
def test_the_unconverged_reason_names_what_ended_outside(
        position: float, rotation: float, expected: str) -> None:
    task = SimpleNamespace(position_tolerance_mm=0.1, orientation_tolerance_deg=0.05,
                           max_steps=800, settle_steps=5)
    assert unconverged_reason(task, position, rotation) == expected


@pytest.mark.slow
def test_fixed_duration_failures_in_the_results_are_in_the_users_terms(
        lab: Path, tmp_path: Path) -> None:
    out = tmp_path / "run"
    assert cli_main(["run", str(lab), "--out", str(out), "--no-progress"]) == 0
    failed = [r for r in read_results(out) if not r["converged"]]
    assert failed, "60 steps and 0.002 deg: some trials end outside"
    for r in failed:
        text = r["failure"]
        assert text.startswith("not converged: ") and text.endswith(" after 60 steps"), text
        assert ("rotation" in text) == (r["final_orientation_error_deg"] >= 0.002)
        assert ("position" in text) == (r["final_position_error_mm"] >= 0.1)
        if "rotation" in text:
            shown = float(text.split("rotation ")[1].split(" deg")[0])
            assert shown == pytest.approx(r["final_orientation_error_deg"], rel=5e-3)
    report = (out / "report.md").read_text()
    assert "## Trials that ended outside the tolerances" in report
    for label in ("leg-edge", "joints"):
        mine = [r["failure"] for r in failed if r["controller"] == label]
        both = sum("position" in t and "rotation" in t for t in mine)
        rot = sum("rotation" in t for t in mine) - both
        pos = sum("position" in t for t in mine) - both
        assert f"| {label} | {pos} | {rot} | {both} | 0 |" in report


def test_run_help_says_what_record_keeps(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:
        cli_main(["run", "--help"])
    assert info.value.code == 0
    text = " ".join(capsys.readouterr().out.split())
    assert ("--record K keep the time series of trials 0 to K-1 of each controller at each "
            "sweep point in DIR/trials/ (default 2: trials 0 and 1; the others keep only "
            "their row in results.jsonl)") in text


@pytest.mark.slow
def test_viz_points_to_record_for_a_trial_that_was_not_recorded(
        lab: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run"
    assert cli_main(["run", str(lab), "--out", str(out), "--no-progress"]) == 0
    capsys.readouterr()
    assert cli_main(["viz", str(out), "--trial", "2", "--controller", "joints",
                     "--point", "0", "--html", str(tmp_path / "t.html")]) == 2
    err = capsys.readouterr().err
    assert (f"{out}: no recorded trial 2 of 'joints'; the run kept the time series of trials "
            "0 to 1 only (--record 2): rerun into a new --out with --record 3 to keep trial 2"
            ) in err
    none = tmp_path / "none"
    assert cli_main(["run", str(lab), "--out", str(none), "--no-progress", "--record",
                     "0"]) == 0
    capsys.readouterr()
    assert cli_main(["viz", str(none), "--html", str(tmp_path / "t.html")]) == 2
    assert (f"{none}: no recorded trial (the run used --record 0); rerun into a new --out "
            "with --record K") in capsys.readouterr().err
    assert not (tmp_path / "t.html").exists()


def test_the_controllers_model_file_is_kept_and_the_copy_runs(tmp_path: Path) -> None:
    """``[robot] model`` (the controllers' robot file, e.g. an identified one) was not
    copied into ``inputs/``: the kept scenario named a file that was not there, and the
    command the report gives to run it again failed."""
    from benchmarks.study.scenario import load_scenario

    folder = tmp_path / "lab"
    folder.mkdir()
    g = deltalab()
    g.to_toml(folder / "identified.toml")
    (folder / "study.toml").write_text(
        'name = "mine"\ntrials = 1\ncontrollers = ["computed-torque"]\n'
        '[robot]\nworld = "dynamic"\nmodel = "identified.toml"\n[task]\nmax_steps = 5\n')
    out = tmp_path / "run"
    assert cli_main(["run", str(folder / "study.toml"), "--out", str(out),
                     "--no-progress"]) == 0
    kept = out / "inputs" / "mine"
    assert (kept / "identified.toml").read_bytes() == (folder / "identified.toml").read_bytes()
    again = load_scenario(kept / "scenario.toml")
    assert Path(again.robot_model).resolve() == (kept / "identified.toml").resolve()
    assert cli_main(["run", str(kept / "scenario.toml"), "--out", str(tmp_path / "again"),
                     "--no-progress"]) == 0
