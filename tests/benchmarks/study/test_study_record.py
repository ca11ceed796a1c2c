"""A run directory holds one study (issue 35): ``--resume`` refuses another world, seed,
controllers, scenario content or trial plan before any trial runs, naming each difference;
a study may grow; ``run.json`` and the report keep every command that wrote the
directory."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace
from pathlib import Path

import pytest

from benchmarks.cli import main as cli_main
from benchmarks.exceptions import StudyMismatchError
from benchmarks.study.runner import read_results
from benchmarks.study.scenario import load_scenario
from benchmarks.study.study_record import check_same_study, differences, study_of
from hexapod import deltalab

STUDY = ('name = "mine"\ntrials = 2\nseed = 1\ncontrollers = ["leg-edge"]\n'
         '[robot]\ngeometry = "robot.toml"\n'
         '[noise]\nmodel = "rotation"\namplitude_deg = 0.01\n[task]\nmax_steps = 20\n')


def _tree(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*"))
            if p.is_file()}


@pytest.fixture(scope="module")
def base(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A scenario file (with a robot file) and a finished run of it (2 trials)."""
    folder = tmp_path_factory.mktemp("study")
    deltalab().to_toml(folder / "robot.toml")
    (folder / "study.toml").write_text(STUDY)
    out = folder / "run"
    assert cli_main(["run", str(folder / "study.toml"), "--out", str(out),
                     "--no-progress"]) == 0
    return folder / "study.toml", out


@pytest.fixture
def study(base: tuple[Path, Path], tmp_path: Path) -> tuple[Path, Path]:
    """A copy of the scenario folder and of its run, for one test to change."""
    scen, _ = base
    folder = tmp_path / "study"
    shutil.copytree(scen.parent, folder)
    return folder / "study.toml", folder / "run"


# ----------------------------------------------------------- the two cases of the issue
@pytest.mark.slow
def test_a_dynamic_resume_of_a_kinematic_study_is_refused(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "D"
    # the issue's first command: computed-torque commands forces, which the kinematic
    # world does not apply; the pre-flight refuses it before anything is written
    issue = ["run", "quick", "--controllers", "computed-torque", "--out", str(out),
             "--trials", "2", "--no-progress"]
    assert cli_main(issue) == 2 and not out.exists()
    first = ["run", "quick", "--controllers", "leg-edge", "--out", str(out), "--trials", "2",
             "--max-steps", "20", "--no-progress"]
    assert cli_main(first) == 0
    assert len(read_results(out)) == 2
    before = _tree(out)
    capsys.readouterr()
    assert cli_main([*first, "--world", "dynamic", "--resume"]) == 2
    captured = capsys.readouterr()
    assert f"hexapod-bench: error: {out}: holds another study than the one given" \
        in captured.err
    assert "\n  --world: kinematic in the directory, dynamic given\n" in captured.err
    assert "resuming" not in captured.out
    assert _tree(out) == before, "nothing written: no row, no run.json, no report"


@pytest.mark.slow
def test_a_resume_with_another_seed_is_refused_and_the_record_does_not_lie(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "D"
    first = ["run", "quick", "--controllers", "leg-edge", "--max-steps", "20", "--out",
             str(out), "--no-progress"]
    assert cli_main([*first, "--trials", "2"]) == 0
    before = _tree(out)
    capsys.readouterr()
    assert cli_main([*first, "--trials", "3", "--seed", "99", "--resume"]) == 2
    err = capsys.readouterr().err
    assert "\n  --seed: 1 in the directory, 99 given\n" in err
    assert "--trials" not in err, "more trials alone would be allowed"
    assert _tree(out) == before
    # the same study grown: allowed, and said
    assert cli_main([*first, "--trials", "3", "--resume"]) == 0
    said = " ".join(capsys.readouterr().out.split())
    assert "growing the study: grew quick from 2 to 3 trials per sweep point and " \
        "controller (everything else as in the directory)" in said
    assert "resuming: 2 trials already done, 1 to go" in said
    assert sorted(r["trial"] for r in read_results(out)) == [0, 1, 2]
    kept = (out / "inputs" / "quick" / "scenario.toml").read_text()
    assert "\ntrials = 3\n" in kept and "\nseed = 1\n" in kept
    report = (out / "report.md").read_text()
    assert "- trials: 3 per sweep point and controller, seed 1" in report
    commands = json.loads((out / "run.json").read_text())["commands"]
    assert [c["command"] for c in commands] == [
        "hexapod-bench " + " ".join([*first, "--trials", "2"]),
        "hexapod-bench " + " ".join([*first, "--trials", "3", "--resume"])]
    assert commands[1]["did"] == ("grew quick from 2 to 3 trials per sweep point and "
                                  "controller; 2 trials already done, 1 to run")
    for k, c in enumerate(commands, 1):
        assert c["version"].startswith("hexapod-vs ") and c["time"].endswith("Z")
        assert f"{k}. `{c['command']}` ({c['time']}, {c['version']}): {c['did']}" in report


# ------------------------------------------------- every kind of difference, named
def _edit(scen: Path, old: str, new: str) -> None:
    text = scen.read_text()
    assert old in text
    scen.write_text(text.replace(old, new))


@pytest.mark.slow
@pytest.mark.parametrize(("change", "extra", "named"), [
    (None, ["--world", "dynamic"], "--world: kinematic in the directory, dynamic given"),
    (None, ["--seed", "7"], "--seed: 1 in the directory, 7 given"),
    (("seed = 1", "seed = 7"), [], "--seed: 1 in the directory, 7 given"),
    (None, ["--controllers", "leg-edge,joint-space"],
     "--controllers: leg-edge in the directory, leg-edge, joint-space given"),
    (('controllers = ["leg-edge"]', 'controllers = [{name = "leg-edge", gain = 2.0}]'), [],
     "--controllers: leg-edge in the directory, leg-edge (gain=2.0) given"),
    (("amplitude_deg = 0.01", "amplitude_deg = 0.02"), [],
     "scenario key noise.amplitude_deg: 0.01 in the directory, 0.02 given"),
    (("amplitude_deg = 0.01", "amplitude_deg = [0.01, 0.02]"), [],
     "scenario key sweep.noise.amplitude_deg: absent in the directory, [0.01, 0.02] given"),
    (None, ["--max-steps", "30"], "--max-steps: 20 in the directory, 30 given"),
    (None, ["--trials", "1"], "--trials: 2 in the directory, 1 given (a study grows, it "
                              "does not shrink: give --trials 2 or more)"),
])
def test_resume_refuses_each_kind_of_difference_naming_it(
        study: tuple[Path, Path], capsys: pytest.CaptureFixture[str],
        change: tuple[str, str] | None, extra: list[str], named: str) -> None:
    scen, out = study
    if change:
        _edit(scen, *change)
    before = _tree(out)
    assert cli_main(["run", str(scen), "--out", str(out), "--no-progress", "--resume",
                     *extra]) == 2
    err = capsys.readouterr().err
    assert f"\n  {named}\n" in err, err
    assert _tree(out) == before


def test_a_changed_robot_file_is_another_study(
        study: tuple[Path, Path], capsys: pytest.CaptureFixture[str]) -> None:
    scen, out = study
    robot = scen.parent / "robot.toml"
    kept = study_of(load_scenario(str(scen)))["robot.geometry"]
    g = deltalab()
    replace(g, leg_radius=1.1 * g.leg_radius).to_toml(robot)
    before = _tree(out)
    assert cli_main(["run", str(scen), "--out", str(out), "--no-progress", "--resume"]) == 2
    now = study_of(load_scenario(str(scen)))["robot.geometry"]
    assert now != kept
    assert (f"\n  robot.geometry: content {kept[7:19]} in the directory, content "
            f"{now[7:19]} given\n") in capsys.readouterr().err
    assert _tree(out) == before


def test_another_scenario_is_another_study(
        study: tuple[Path, Path], capsys: pytest.CaptureFixture[str]) -> None:
    scen, out = study
    other = scen.parent / "other.toml"
    other.write_text(STUDY.replace('name = "mine"', 'name = "other"'))
    assert cli_main(["run", str(scen), str(other), "--out", str(out), "--no-progress",
                     "--resume"]) == 2
    assert "\n  scenarios: mine in the directory, mine, other given\n" in \
        capsys.readouterr().err


def test_several_differences_are_all_named(
        study: tuple[Path, Path], capsys: pytest.CaptureFixture[str]) -> None:
    scen, out = study
    assert cli_main(["run", str(scen), "--out", str(out), "--no-progress", "--resume",
                     "--seed", "3", "--world", "dynamic", "--trials", "5"]) == 2
    err = capsys.readouterr().err
    assert "\n  --seed: 1 in the directory, 3 given\n" in err
    assert "\n  --world: kinematic in the directory, dynamic given\n" in err
    assert "--trials" not in err


@pytest.mark.slow
def test_the_runs_own_scenario_copy_resumes_and_grows_the_study(
        study: tuple[Path, Path], capsys: pytest.CaptureFixture[str]) -> None:
    scen, out = study
    copy = out / "inputs" / "mine" / "scenario.toml"
    assert cli_main(["run", str(copy), "--out", str(out), "--no-progress", "--resume",
                     "--trials", "3"]) == 0
    assert "grew mine from 2 to 3 trials" in capsys.readouterr().out
    assert sorted(r["trial"] for r in read_results(out)) == [0, 1, 2]
    assert "\ntrials = 3\n" in copy.read_text()
    meta = json.loads((out / "run.json").read_text())
    assert meta["scenarios"]["mine"]["study"]["trials"] == 3
    assert len(meta["commands"]) == 2
    # the grown study is the directory's study now: its own file (2 trials) is fewer
    assert cli_main(["run", str(scen), "--out", str(out), "--no-progress", "--resume"]) == 2
    assert "--trials: 3 in the directory, 2 given" in capsys.readouterr().err


def test_a_directory_that_recorded_no_study_cannot_be_resumed(
        study: tuple[Path, Path], capsys: pytest.CaptureFixture[str]) -> None:
    scen, out = study
    meta = json.loads((out / "run.json").read_text())
    del meta["scenarios"]["mine"]["study"]
    (out / "run.json").write_text(json.dumps(meta))
    assert cli_main(["run", str(scen), "--out", str(out), "--no-progress", "--resume"]) == 2
    assert "mine: the directory was written by an earlier hexapod-bench that did not " \
        "record the study" in capsys.readouterr().err


def test_differences_compare_key_by_key() -> None:
    a = {"version": 1, "seed": 1, "trials": 2, "world": "kinematic"}
    assert differences(a, dict(a)) == ([], None)
    assert differences(a, {**a, "trials": 5}) == ([], 5)
    assert differences(a, {**a, "seed": 2, "trials": 5}) == (
        ["--seed: 1 in the directory, 2 given"], 5)
    assert differences(a, {**a, "dt": 0.01}) == (
        ["scenario key dt: absent in the directory, 0.01 given"], None)
    # a study recorded before the goal setting existed ran the legacy one
    assert differences(a, {**a, "task.goal": "mixed"}) == ([], None)
    assert differences(a, {**a, "task.goal": "taught"}) == (
        ["--goal: mixed in the directory, taught given"], None)
    assert study_of(load_scenario("quick").with_goal("cartesian"))["task.goal"] == "cartesian"
    assert check_same_study(Path("x"), {}, []) == {}, "a new directory: nothing to check"
    with pytest.raises(StudyMismatchError) as info:
        check_same_study(Path("x"), {"scenarios": {"a": {"study": a}}}, [])
    assert info.value.differences == ["scenarios: a in the directory, none given"]


@pytest.mark.slow
def test_report_is_one_of_the_commands_that_wrote_the_directory(
        study: tuple[Path, Path]) -> None:
    _, out = study
    assert cli_main(["report", str(out)]) == 0
    commands = json.loads((out / "run.json").read_text())["commands"]
    assert [c["did"] for c in commands] == ["2 trials to run",
                                            "rebuilt report.md and its figures"]
    assert commands[1]["command"] == f"hexapod-bench report {out}"
    assert f"2. `hexapod-bench report {out}` (" in (out / "report.md").read_text()
    (out / "report.md").write_text("my analysis\n")
    before = (out / "run.json").read_bytes()
    assert cli_main(["report", str(out)]) == 2, "a user's report.md is refused"
    assert (out / "run.json").read_bytes() == before, "and nothing recorded"


@pytest.mark.slow
def test_a_study_with_controller_options_resumes_from_its_copy(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The runnable copy folds ``[controller_options]`` into each controller: it resumes
    the study (it was refused, 'controller_options: {...} in the directory, {} given'),
    and other options are still another study (named by the controllers)."""
    deltalab().to_toml(tmp_path / "robot.toml")
    scen = tmp_path / "study.toml"
    scen.write_text(STUDY + "[controller_options]\nadaptive_gain = [5.0, 1.0, 30.0]\n")
    out = tmp_path / "run"
    assert cli_main(["run", str(scen), "--out", str(out), "--no-progress"]) == 0
    copy = out / "inputs" / "mine" / "scenario.toml"
    assert "controller_options" not in copy.read_text()
    assert cli_main(["run", str(copy), "--out", str(out), "--no-progress", "--resume",
                     "--trials", "3"]) == 0
    assert "grew mine from 2 to 3 trials" in capsys.readouterr().out
    scen.write_text(STUDY + "[controller_options]\nadaptive_gain = [6.0, 1.0, 30.0]\n")
    assert cli_main(["run", str(scen), "--out", str(out), "--no-progress", "--resume",
                     "--trials", "3"]) == 2
    err = " ".join(capsys.readouterr().err.split())
    assert "controllers: leg-edge (adaptive_gain=[5.0, 1.0, 30.0]) in the directory, " \
           "leg-edge (adaptive_gain=[6.0, 1.0, 30.0]) given" in err
    # a directory of an earlier version recorded the table itself: ignored on both sides
    a = {"version": 1, "seed": 1, "controller_options": {"adaptive_gain": [5.0, 1.0, 30.0]}}
    assert differences(a, {"version": 1, "seed": 1}) == ([], None)
