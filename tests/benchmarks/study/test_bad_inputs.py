"""Inputs a user can get wrong, each refused with the file and what is wrong, exit 2 and
no traceback: a results file whose rows are not trial rows, a run directory whose record
was deleted, a binary file where TOML is read, a folder the system refuses."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from benchmarks.cli import main as cli_main
from benchmarks.exceptions import ResultsError
from benchmarks.study.results import read_results
from hexapod.config import load_toml
from hexapod.exceptions import ConfigFileError
from tests.benchmarks.study.helpers_rows import make_rows, write_run


def _run(tmp_path: Path) -> Path:
    return write_run(tmp_path / "run", make_rows("leg-edge", np.full(3, 0.1),
                                                 np.ones(3, bool), np.full(3, 50)))


@pytest.mark.parametrize(("line", "says"), [
    ("[1, 2, 3]", "a row is a JSON object ({...}), not a list"),
    ('{"scenario": "s", "controller": "c", "point": 0}', "key 'trial': missing"),
    ('{"scenario": "s", "controller": "c", "trial": "3"}', "key 'trial': '3'"),
    ('{"scenario": "s", "controller": "c", "trial": 3, "final_position_error_mm": "big"}',
     "key 'final_position_error_mm': 'big' is not a number"),
    ('{"scenario": "s", "controller": "c", "trial": 3, "steps": true}',
     "key 'steps': True is not a number"),
])
def test_a_row_that_is_not_a_trial_row_is_refused_by_line(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], line: str, says: str) -> None:
    out = _run(tmp_path)
    with (out / "results.jsonl").open("a") as f:
        f.write(line + "\n")
    with pytest.raises(ResultsError) as info:
        read_results(out)
    assert f"results.jsonl:4: {says}" in str(info.value)
    before = (out / "results.jsonl").read_bytes()
    for command in (["report", str(out)], ["compare", str(out)],
                    ["export", str(out), "--parquet", str(tmp_path / "t.parquet")]):
        assert cli_main(command) == 2
        assert f"results.jsonl:4: {says}" in capsys.readouterr().err
    assert (out / "results.jsonl").read_bytes() == before


def test_good_rows_with_lists_and_nulls_are_read(tmp_path: Path) -> None:
    out = _run(tmp_path)
    with (out / "results.jsonl").open("a") as f:
        f.write(json.dumps({"scenario": "s", "controller": "c", "trial": 9, "point": 1,
                            "saturation_legs_s": [0.0, 1.5, None, 0, 0, 0],
                            "final_position_error_mm": None, "goal": "taught"}) + "\n")
    assert len(read_results(out)) == 4


@pytest.mark.slow
def test_a_resume_without_the_run_s_record_is_refused(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """run.json deleted (or not JSON): the study cannot be checked, so a resume that
    could mix another study's trials into the rows is refused, the rows kept."""
    out = tmp_path / "run"
    assert cli_main(["run", "quick", "--out", str(out), "--trials", "2", "--max-steps", "20",
                     "--no-progress"]) == 0
    rows = (out / "results.jsonl").read_bytes()
    (out / "run.json").unlink()
    args = ["run", "quick", "--out", str(out), "--trials", "3", "--max-steps", "40",
            "--resume", "--no-progress"]
    assert cli_main(args) == 2
    assert "holds results.jsonl but no run.json" in capsys.readouterr().err
    (out / "run.json").write_text("{not json")
    assert cli_main(args) == 2
    assert "run.json: not the run's record (not JSON" in capsys.readouterr().err
    assert (out / "results.jsonl").read_bytes() == rows


def test_a_binary_file_where_toml_is_read_is_named(tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    png = tmp_path / "scenario.toml"
    png.write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00")
    with pytest.raises(ConfigFileError, match=r"not a TOML text file \(not UTF-8 text: byte "
                                              r"0x89 at offset 0\)"):
        load_toml(png)
    assert cli_main(["check", str(png)]) == 2
    assert f"{png}: not a TOML text file" in capsys.readouterr().err


def test_a_folder_the_system_refuses_is_named_without_a_traceback(
        tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    from benchmarks.study import table

    blocker = tmp_path / "afile"
    out = _run(tmp_path)
    argv = ["export", str(out), "--parquet", str(blocker / "t.parquet")]
    real = table.export_parquet

    def changed_meanwhile(*args: object, **kwargs: object) -> object:
        blocker.write_text("x")  # a file where the command makes a folder, since the
        return real(*args, **kwargs)  # command line was read (checked there: below)

    monkeypatch.setattr(table, "export_parquet", changed_meanwhile)
    assert cli_main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"hexapod-bench: error: {blocker}") and "Traceback" not in err
    monkeypatch.undo()
    with pytest.raises(SystemExit) as refused:  # already there: refused before any work
        cli_main(argv)
    assert refused.value.code == 2
    err = capsys.readouterr().err
    assert f"argument --parquet: {blocker / 't.parquet'}: {blocker} is a file" in err


@pytest.mark.parametrize(("args", "says"), [
    (["run", "quick", "--workers", "-1"], "--workers -1: at least 1"),
    (["run", "quick", "--chunk", "0"], "--chunk 0: at least 1"),
    (["run", "quick", "--record", "-1"], "--record -1: at least 0"),
    (["run", "quick", "quick"], "scenario quick given twice: a study runs once"),
    (["calibrate", "quick", "--configurations", "random:0"],
     "--configurations: key 'calibration.configurations': expected 'random:N' with an "
     "integer N in [2, 100000], got 'random:0'"),
    (["calibrate", "quick", "--configurations", "extreme"], "expected 'extremal' or"),
    (["calibrate", "quick", "--repeat", "0"], "--repeat 0: at least 1 repetition"),
    # options a command would ignore, or not survive
    (["reproduce", "seed000", "--trials", "2"], "--trials: options of the sensitivity study"),
    (["reproduce", "seed000", "--gain", "1"], "--gain: options of the sensitivity study"),
    (["identify", "deltalab", "--duration", "1e9"], "--duration 1e+09: at most 3600 s"),
])
def test_options_a_command_cannot_use_are_refused_before_anything_is_written(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str],
        says: str) -> None:
    out = tmp_path / "out"
    assert cli_main([*args, "--out", str(out)]) == 2
    err = " ".join(capsys.readouterr().err.split())
    assert says in err and "Traceback" not in err
    assert not out.exists()


def test_text_where_numbers_are_read_is_refused(tmp_path: Path) -> None:
    """'410' in a list of lengths converted silently to 410.0 (a goal file, a robot file):
    text and booleans are refused, naming the key and the entry."""
    from hexapod.config import get_matrix

    with pytest.raises(ConfigFileError, match=r"f.toml: key 'lengths_mm': expected an "
                                              r"array of numbers of shape \(3,\), got '410'"):
        get_matrix({"lengths_mm": [400, "410", 420]}, "lengths_mm", (3,), "f.toml")
    with pytest.raises(ConfigFileError, match="got True"):
        get_matrix({"m": [[1.0, True], [0.0, 1.0]]}, "m", (2, 2), "f.toml")
    assert get_matrix({"m": [1, 2.5]}, "m", (2,), "f.toml").tolist() == [1.0, 2.5]


def test_a_report_of_no_trial_is_refused(tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "results.jsonl").write_text("")
    assert cli_main(["report", str(tmp_path)]) == 2
    assert "results.jsonl: no trial rows: nothing to report" in capsys.readouterr().err
    assert not (tmp_path / "report.md").exists()


def test_reproduce_checks_its_default_out_before_any_study(
        tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    """``--out`` not given: its default (runs/reproduce, not read by argparse's action) is
    checked as a given one is."""
    (tmp_path / "runs").write_text("my notes\n")  # a file where the default's folder goes
    monkeypatch.chdir(tmp_path)
    assert cli_main(["reproduce", "seed000", "--quick"]) == 2
    err = capsys.readouterr().err
    assert "--out runs/reproduce: runs is a file: no folder can be made under it" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["runs"]
