"""``hexapod-bench tune`` end to end: on a noise-free kinematic task whose error after a
fixed time falls strictly with the gain, the search picks the largest gain; the tuning
trials are held out (their own seed, the study's refused); the tuned options go through
``run --options-file`` into ``run.json`` and the report; the criterion counts failures
as the worst."""

from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path

import pytest

from benchmarks.cli import main
from benchmarks.study.tune_command import SEED_OFFSET, Score, choose, criterion_value

SCENARIO = """
name = "gain-ladder"
seed = 7
trials = 3
controllers = ["leg-edge"]

[task]
kind = "random-pairs"
max_steps = 25
fixed_duration = true
max_translation_mm = 10.0
max_angle_deg = 2.0
"""
SPACE = '["leg-edge"]\ngain = { low = 0.5, high = 8.0, scale = "log" }\n'


@pytest.fixture
def files(tmp_path: Path) -> tuple[Path, Path]:
    sc, space = tmp_path / "ladder.toml", tmp_path / "space.toml"
    sc.write_text(SCENARIO)
    space.write_text(SPACE)
    return sc, space


def test_the_criterion_counts_failures_as_the_worst() -> None:
    rows = [{"final_position_error_mm": 0.1, "failure": None},
            {"final_position_error_mm": 0.3, "failure": "not converged: position 0.3 mm"},
            {"final_position_error_mm": 0.01, "failure": "leg 1 hit its end stop"},
            {"final_position_error_mm": None, "failure": "ValueError: boom"}]
    value, failed = criterion_value(rows, "median-final")
    assert failed == 2 and value == math.inf  # two of four worst: the median is inf
    value, failed = criterion_value(rows[:3], "median-final")
    assert (value, failed) == (0.3, 1)  # the end stop's small error does not count
    assert criterion_value(rows[:2], "mean-final") == (pytest.approx(0.2), 0)
    assert criterion_value([{"tracking_rms_position_mm": float(x)} for x in range(1, 11)],
                           "p90-tracking-rms") == (9.0, 0)



def _score(index: int, values: list[float], value: float | None = None) -> Score:
    per = {(0, k): v for k, v in enumerate(values)}
    return Score("a", index, {"gain": float(index)},
                 float(sorted(values)[len(values) // 2]) if value is None else value,
                 len(values), 0, per)


def test_the_best_candidate_is_kept_only_if_shown_better_than_the_options_as_given() -> None:
    """Lower on 8 of 8 paired trials: one-sided sign test p = 1/256, x 2 searched
    candidates = 0.0078: kept. Lower by 1e-5 on 5, higher on 3 (a score won on noise):
    p = 0.36: the options as given are kept, the test said."""
    from scipy.stats import binomtest

    given = _score(0, [1.0, 1.2, 0.9, 1.1, 1.3, 1.0, 0.8, 1.05])
    clear = _score(2, [v / 2 for v in given.per_trial.values()])
    noise = _score(1, [v - 1e-5 if k < 5 else v + 1e-5
                       for k, v in enumerate(given.per_trial.values())], given.value - 1e-5)
    c = choose([given, noise, clear])
    assert c.best is clear and c.chosen is clear and c.shown_better
    assert (c.better, c.worse) == (8, 0)
    assert c.p_value == pytest.approx(binomtest(8, 8, alternative="greater").pvalue)
    assert c.p_adjusted == pytest.approx(2 * c.p_value)
    c = choose([given, noise])
    assert c.best is noise and c.chosen is given and not c.shown_better
    assert (c.better, c.worse) == (5, 3)
    assert c.p_value == pytest.approx(binomtest(5, 8, alternative="greater").pvalue)
    assert choose([given, _score(1, list(given.per_trial.values()))]).chosen is given  # tie
    # a failed trial (+inf) is worse than any value; both failed: left out
    failing = _score(1, [math.inf] + [v / 2 for v in list(given.per_trial.values())[1:]])
    assert choose([given, failing]).worse == 1


@pytest.mark.slow
def test_tune_picks_the_known_best_and_the_run_records_it(files: tuple[Path, Path],
                                                          tmp_path: Path) -> None:
    sc, space = files
    out = tmp_path / "tune"
    assert main(["tune", str(sc), "--controllers", "leg-edge", "--trials", "8",
                 "--candidates", "4", "--space", str(space), "--out", str(out),
                 "--no-progress"]) == 0
    tuned = tomllib.loads((out / "tuned.toml").read_text())
    scores = json.loads((out / "tuning.json").read_text())["candidates"]["leg-edge"]
    gains = [c["options"].get("gain") for c in scores]
    assert gains == [None, 0.5, 2.0, 8.0]
    values = [c["criterion"] for c in scores]
    assert values[1] > values[0] > values[2] > values[3]  # 0.5 < 1 (given) < 2 < 8 1/s
    assert tuned["controllers"]["leg-edge"] == {"gain": 8.0}
    t = tuned["tuning"]
    assert t["chosen"] == {"leg-edge": 3} and t["criterion"] == "median-final"
    assert t["budget"] == "4 candidates x 8 trials x 1 sweep point(s)"
    # shown better on the 8 paired tuning trials: sign test 1/256, x 3 candidates
    shown = t["shown_better"]["leg-edge"]
    assert shown["kept"] == "best" and (shown["better_in"], shown["worse_in"]) == (8, 0)
    assert shown["p_bonferroni"] == pytest.approx(3 / 256)
    assert t["goal"] == "mixed" and t["held_out"] is True
    # held out: the tuning trials' seed is the study's plus the offset, recorded
    assert (t["study_seed"], t["tuning_seed"], t["seed_offset"]) == (7, 7 + SEED_OFFSET,
                                                                      SEED_OFFSET)
    meta = json.loads((out / "candidates" / "run.json").read_text())
    assert meta["scenarios"]["gain-ladder"]["study"]["seed"] == 7 + SEED_OFFSET
    # the tuned options into a run on the study's own seed, recorded in run.json
    run = tmp_path / "held-out"
    assert main(["run", str(sc), "--options-file", str(out / "tuned.toml"), "--out", str(run),
                 "--no-progress"]) == 0
    meta = json.loads((run / "run.json").read_text())
    assert meta["options_file"]["controllers"] == {"leg-edge": {"gain": 8.0}}
    assert meta["options_file"]["tuning"]["tuning_seed"] == 7 + SEED_OFFSET
    study = meta["scenarios"]["gain-ladder"]["study"]
    assert study["seed"] == 7 and study["controllers"] == ["leg-edge (gain=8.0)"]
    report = (run / "report.md").read_text()
    assert "**tuned**" in report and "median-final" in report
    given = tmp_path / "given"
    assert main(["run", str(sc), "--out", str(given), "--no-progress"]) == 0
    assert "**as given**" in (given / "report.md").read_text()
    assert "options_file" not in json.loads((given / "run.json").read_text())


def test_the_study_seed_is_refused(files: tuple[Path, Path], tmp_path: Path,
                                  capsys: pytest.CaptureFixture[str]) -> None:
    sc, _ = files
    assert main(["tune", str(sc), "--controllers", "leg-edge", "--seed", "7", "--out",
                 str(tmp_path / "t")]) == 2
    assert "7 is the study's own seed" in capsys.readouterr().err


def test_a_bad_space_option_is_refused_before_any_trial(files: tuple[Path, Path],
                                                       tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]
                                                       ) -> None:
    sc, space = files
    space.write_text('["leg-edge"]\ngian = { low = 0.5, high = 8.0 }\n')
    assert main(["tune", str(sc), "--controllers", "leg-edge", "--space", str(space),
                 "--out", str(tmp_path / "t")]) == 2
    err = capsys.readouterr().err
    assert "has no option 'gian'" in err and "did you mean 'gain'" in err
    assert not (tmp_path / "t" / "candidates").exists()


def test_a_run_under_another_goal_setting_than_tuned_is_warned(
        files: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from benchmarks.study.options_file import write_options_file

    sc, _ = files
    tuned = tmp_path / "tuned.toml"
    write_options_file(tuned, {"leg-edge": {"gain": 2.0}},
                       {"scenario": "gain-ladder", "goal": "mixed", "held_out": False,
                        "criterion": "median-final", "budget": "2 x 2 x 1",
                        "tuning_seed": 1000011, "study_seed": 8,
                        "shown_better": {"leg-edge": {"kept": "as given"}}}, "# tuned")
    run = tmp_path / "run"
    assert main(["run", str(sc), "--goal", "taught", "--options-file", str(tuned), "--trials",
                 "1", "--out", str(run), "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert "options tuned under the goal setting 'mixed', gain-ladder runs under 'taught'" in err
    report = (run / "report.md").read_text()
    assert "goal setting mixed" in report and "not held out" in report
    assert "kept as given, no candidate shown better: leg-edge" in report


def test_a_wrapper_is_searched_in_its_laws_space() -> None:
    """``latency-compensated`` hands its options on to the law it wraps: it is searched in
    that law's space (it ran its options as given alone: 1 candidate where the others
    had 6, under a budget printed as equal)."""
    from types import SimpleNamespace

    import controllers  # noqa: F401
    from benchmarks.study.options_file import controller_options
    from benchmarks.study.tuning_space import SEARCH_SPACE, candidates, controller_space
    from controllers.registry import registry

    spec = SimpleNamespace(name="latency-compensated", label="leg-edge+comp",
                           options={"law": "leg-edge", "adaptive_gain": [5.0, 1.0, 30.0]})
    table = controller_options(spec)
    assert {"law", "use_rates", "adaptive_gain", "gain"} <= set(table.names)
    wrapped = controller_space(spec.label, spec.name, table, SEARCH_SPACE)
    law = controller_space("leg-edge", "leg-edge", registry.options("leg-edge"), SEARCH_SPACE)
    assert wrapped.family == law.family is not None and wrapped.axes == law.axes
    assert len(candidates(spec.options, wrapped.axes, 6)) == 6
    assert all(c["law"] == "leg-edge" for c in candidates(spec.options, wrapped.axes, 6))


def test_an_axis_whose_values_the_controller_refuses_is_an_error_before_anything_runs(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A vector option's axis without its shape (``adaptive_gain = {low, high}``: a number
    where three are meant) is refused naming the space file and the axis, with nothing
    run and no --out made (it failed once the tune had started, naming the scenario, an
    empty --out left behind)."""
    space = tmp_path / "space.toml"
    space.write_text('["leg-edge"]\nadaptive_gain = { low = 1.0, high = 20.0 }\n')
    out = tmp_path / "tune"
    assert main(["tune", "quick", "--controllers", "leg-edge", "--trials", "2",
                 "--candidates", "2", "--space", str(space), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"{space}: key 'leg-edge.adaptive_gain': leg-edge: " in err, err
    assert "a vector option's axis needs a shape" in err
    assert not out.exists()


def test_a_space_table_is_its_controllers_and_its_options_someones(
        files: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A space file's table for leg-edge was searched by every controller that takes its
    option, a misspelt controller table was taken for a family, and a family table's
    misspelt option made a tune that searched nothing, exit 0: the first two are each
    controller's own, the others refused before any trial."""
    from benchmarks.study.tuning_space import controller_space, load_space
    from controllers import registry

    sc, space = files
    space.write_text('["leg-edge"]\ngain = { low = 2.0, high = 3.0 }\n')
    spec = load_space(space)
    tables = {n: registry.options(n) for n in ("leg-edge", "leg-direction")}
    own = frozenset(tables)
    assert controller_space("leg-edge", "leg-edge", tables["leg-edge"], spec, own).axes
    assert not controller_space("leg-direction", "leg-direction", tables["leg-direction"],
                                spec, own).axes  # (it was searched over leg-edge's range)
    for text, fragment in (
            ('["leg-egde"]\ngain = { low = 2.0, high = 3.0 }\n',
             "table [leg-egde] is no controller of this tuning"),
            ('[velocity]\nadaptive_gian = { low = 1.0, high = 8.0 }\n',
             "no controller of this tuning (leg-edge) has an option 'adaptive_gian'")):
        space.write_text(text)
        capsys.readouterr()
        assert main(["tune", str(sc), "--controllers", "leg-edge", "--space", str(space),
                     "--out", str(tmp_path / "t")]) == 2
        err = " ".join(capsys.readouterr().err.split())
        assert fragment in err and "did you mean" in err, err
        assert not (tmp_path / "t").exists()


def test_a_tracking_criterion_on_a_point_to_point_task_is_refused(
        files: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """It scored every trial as a failure (+inf), exit 0, and wrote a tuned.toml."""
    sc, _ = files
    assert main(["tune", str(sc), "--controllers", "leg-edge", "--criterion",
                 "median-tracking-rms", "--out", str(tmp_path / "t")]) == 2
    err = " ".join(capsys.readouterr().err.split())
    assert "--criterion median-tracking-rms:" in err and "no reference to track" in err
    assert not (tmp_path / "t").exists()


def test_workers_below_one_are_refused_before_anything_is_made(
        files: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """--workers 0 was refused after the tuning's header, its directory already made."""
    sc, _ = files
    assert main(["tune", str(sc), "--controllers", "leg-edge", "--workers", "0",
                 "--out", str(tmp_path / "t")]) == 2
    captured = capsys.readouterr()
    assert "--workers 0: at least 1" in captured.err and "tune " not in captured.out
    assert not (tmp_path / "t").exists()


def test_a_choice_at_the_deadbeat_gain_is_said_to_be_the_designs_limit(
        files: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A gain chosen at 1/dt (50 1/s at 20 ms) was told 'the best may lie beyond (widen
    the space)', which docs/tuning.md says it is not: the discrete loop's deadbeat gain."""
    sc, space = files
    space.write_text('["leg-edge"]\ngain = { low = 0.5, high = 50.0, scale = "log" }\n')
    assert main(["tune", str(sc), "--controllers", "leg-edge", "--space", str(space),
                 "--candidates", "3", "--trials", "8", "--out", str(tmp_path / "t")]) == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "the chosen gain = 50.0 is at an end of its range" in out, out
    assert "the discrete loop's deadbeat gain 1/dt" in out and "may lie beyond" not in out
    # the candidates' own report says what its options are (it said "as given")
    report = (tmp_path / "t" / "candidates" / "report.md").read_text()
    assert "Controller options: the **candidates** of `hexapod-bench tune`" in report


def test_the_shape_hint_is_for_a_vector_option_alone(
        files: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A scalar gain's bad range was told 'a vector option's axis needs a shape'."""
    sc, space = files
    for text, hinted in (('gain = { low = -1.0, high = 3.0, scale = "linear" }', False),
                         ("adaptive_gain = { low = 1.0, high = 3.0 }", True)):
        space.write_text(f'["leg-edge"]\n{text}\n')
        assert main(["tune", str(sc), "--controllers", "leg-edge", "--space", str(space),
                     "--out", str(tmp_path / "t")]) == 2
        err = " ".join(capsys.readouterr().err.split())
        assert ("a vector option's axis needs a shape" in err) is hinted, err


def test_a_tune_directory_of_other_settings_is_refused_in_tunes_words(
        files: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Another --candidates, another search space or another goal setting into a tune
    directory: the candidates' run refused it naming their internal labels
    (``leg-edge:c0 (...)``) under ``--controllers``, an option not changed; now what
    differs in tune's words and the command to finish it with, nothing run."""
    sc, space = files
    out = tmp_path / "t"
    first = ["tune", str(sc), "--controllers", "leg-edge", "--space", str(space),
             "--candidates", "3", "--trials", "2", "--out", str(out)]
    assert main(first) == 0
    rows = (out / "candidates" / "results.jsonl").read_text()
    capsys.readouterr()
    other_space = tmp_path / "other.toml"
    other_space.write_text(SPACE.replace("high = 8.0", "high = 4.0"))
    cases = [(["--candidates", "4"], "--candidates: leg-edge 3 in the directory, 4 given"),
             (["--space", str(other_space)], "the candidates' searched options"),
             (["--goal", "taught"], "--goal: mixed in the directory, taught given"),
             (["--controllers", "leg-edge,joint-space"],
              "--controllers: leg-edge in the directory, leg-edge, joint-space given")]
    for change, says in cases:
        args = list(first)
        for k in range(0, len(change), 2):
            if change[k] in args:
                args[args.index(change[k]) + 1] = change[k + 1]
            else:
                args += change[k:k + 2]
        assert main([*args, "--resume"]) == 2, change
        err = capsys.readouterr().err
        assert f"{out}: holds a tuning of other settings than those given" in err, err
        assert says in err and "leg-edge:c0" not in err, err
        assert ("finish it with its last command and --resume (hexapod-bench "
                + " ".join(first) + ")") in err, err
    assert (out / "candidates" / "results.jsonl").read_text() == rows  # nothing run
    # a record this cannot read (not this tuning's layout): the run's own refusal, no
    # traceback (a KeyError came out of a renamed scenario's directory)
    record = out / "candidates" / "run.json"
    record.write_text("[]")
    assert main([*first, "--resume"]) == 2
    assert "Traceback" not in capsys.readouterr().err
