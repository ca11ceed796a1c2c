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
    given = Score("a", 0, {}, 0.5, 3, 0)
    assert choose([given, Score("a", 1, {"gain": 2.0}, 0.5, 3, 0)]) is given  # ties: as given
    assert choose([given, Score("a", 2, {"gain": 4.0}, 0.4, 3, 0)]).index == 2


@pytest.mark.slow
def test_tune_picks_the_known_best_and_the_run_records_it(files: tuple[Path, Path],
                                                          tmp_path: Path) -> None:
    sc, space = files
    out = tmp_path / "tune"
    assert main(["tune", str(sc), "--controllers", "leg-edge", "--trials", "3",
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
    assert t["budget"] == "4 candidates x 3 trials x 1 sweep point(s)"
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
