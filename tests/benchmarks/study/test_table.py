"""A run as a pandas table (load) and as Parquet (export)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

from benchmarks.cli import main as cli_main
from benchmarks.exceptions import ResultsError
from benchmarks.study import load
from benchmarks.study.results import deduplicate, read_results
from benchmarks.study.table import RUN_METADATA
from tests.benchmarks.study.helpers_rows import make_rows, write_run


def _sweep_run(tmp_path: Path) -> Path:
    rng = np.random.default_rng(4)
    rows = []
    for p, amp in enumerate((0.01, 0.05)):
        for ctrl in ("a", "b"):
            err = rng.lognormal(-2, 0.5, 20)
            rows += make_rows(ctrl, err, err < 0.2, rng.integers(50, 90, 20), point=p,
                              sweep={"noise_amplitude_deg": amp})
    rows[3]["final_position_error_mm"] = None  # a crashed trial
    rows[5]["calibration_per_leg"] = [1.0, 2.0]  # a list-valued key
    return write_run(tmp_path / "run", rows)


def test_load_one_row_per_trial_with_sweep_columns(tmp_path: Path) -> None:
    out = _sweep_run(tmp_path)
    df = load(out)
    ref, _, _ = deduplicate(read_results(out))
    assert len(df) == len(ref) == 80
    assert list(df.columns[:6]) == ["scenario", "point", "controller", "backend", "trial",
                                    "noise_amplitude_deg"]
    assert df.attrs["sweep_columns"] == ["noise_amplitude_deg"]
    assert df["converged"].dtype == bool
    assert np.isnan(df.loc[3, "final_position_error_mm"])
    # every value equals the row it came from
    for i in (0, 17, 45, 79):
        for k, v in ref[i].items():
            got = df.loc[i, k]
            if v is None:
                assert got is None or (isinstance(got, float) and np.isnan(got))
            elif isinstance(v, list):
                assert got == "[1.0, 2.0]"
            else:
                assert got == v, (i, k)
    means = df.groupby(["noise_amplitude_deg", "controller"])["final_position_error_mm"].count()
    assert means.sum() == 79


def test_load_drops_duplicates_and_a_partial_line(tmp_path: Path) -> None:
    out = _sweep_run(tmp_path)
    path = out / "results.jsonl"
    lines = path.read_text().splitlines(keepends=True)
    path.write_text("".join(lines) + lines[0] + lines[1][:30])
    df = load(out)
    assert len(df) == 80


def test_load_names_a_corrupted_line(tmp_path: Path) -> None:
    out = _sweep_run(tmp_path)
    path = out / "results.jsonl"
    lines = path.read_text().splitlines(keepends=True)
    lines[7] = "{not json\n"
    path.write_text("".join(lines))
    with pytest.raises(ResultsError, match=r"results.jsonl:8"):
        load(out)
    with pytest.raises(ResultsError, match="no results file"):
        load(tmp_path / "nothing")


def test_export_parquet_round_trip(tmp_path: Path) -> None:
    out = _sweep_run(tmp_path)
    record = {"commands": [{"argv": ["run", "quick", "--seed", "7"]}], "workers": 2,
              "scenarios": {"quick": {"description": "a study", "source": "quick.toml"}}}
    (out / "run.json").write_text(json.dumps(record))
    target = tmp_path / "t.parquet"
    assert cli_main(["export", str(out), "--parquet", str(target)]) == 0
    back = pd.read_parquet(target)
    df = load(out)
    pd.testing.assert_frame_equal(back, df, check_dtype=False)
    # the run's record travels with the file: pandas gives back the attrs, other
    # readers find run.json in the schema metadata
    assert back.attrs == df.attrs
    assert back.attrs["meta"] == record
    metadata = pq.read_schema(target).metadata
    assert json.loads(metadata[RUN_METADATA]) == record
    assert b"generator" in metadata
