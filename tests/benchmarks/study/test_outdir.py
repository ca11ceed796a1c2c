"""benchmarks.study.outdir: which entries of a ``reproduce --out`` are its own."""

from __future__ import annotations

from pathlib import Path

import pytest

from benchmarks.study.outdir import check_reproduce_directory
from hexapod.exceptions import OutputError


def test_reproduce_out_accepts_its_studies_and_refuses_anything_else(tmp_path: Path) -> None:
    out = tmp_path / "r"
    check_reproduce_directory(out)  # absent: fine
    (out / "run_a-quick").mkdir(parents=True)
    (out / "run_a-quick" / "results.jsonl").write_text("")
    (out / "run_a-quick" / "run.json").write_text("{}")
    (out / "run_b").mkdir()
    (out / "run_b" / ".lock").write_text("")  # interrupted before its first row
    (out / "calibrate_c").mkdir()
    (out / "calibrate_c" / "calibration.json").write_text("{}")
    (out / "empty").mkdir()
    check_reproduce_directory(out)
    (out / "mine").mkdir()
    (out / "mine" / "thesis.tex").write_text("chapter 1")
    (out / "notes.txt").write_text("mine")
    with pytest.raises(OutputError, match=r"it holds mine/, notes.txt; choose another --out, "
                                          r"or add --overwrite"):
        check_reproduce_directory(out)
    check_reproduce_directory(out, overwrite=True)
