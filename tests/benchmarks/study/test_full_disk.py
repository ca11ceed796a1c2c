"""A full disk during a run: the file is named, nothing half written is left, the rows
written stay and the run says how to finish it."""

from __future__ import annotations

import errno
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from benchmarks.cli import main as cli_main
from benchmarks.study import results as results_module
from benchmarks.study.results import TRIALS_DIR, ResultsWriter
from benchmarks.study.runner import read_results
from hexapod.visualize import records
from hexapod.visualize.records import save_trial

_FULL = Path("/dev/full")  # every write: ENOSPC (Linux)


def test_a_full_disk_under_the_results_file_names_it(tmp_path: Path) -> None:
    writer = ResultsWriter(tmp_path)
    writer._f.close()
    writer._f = _FULL.open("a", encoding="utf-8")  # the system's own ENOSPC
    with pytest.raises(OSError) as caught:
        writer.write([{"trial": 0}], [])
    assert caught.value.errno == errno.ENOSPC
    assert caught.value.filename == str(tmp_path / "results.jsonl")
    writer._f = open(tmp_path / "results.jsonl", "a", encoding="utf-8")  # noqa: SIM115
    writer.close()


def test_a_record_not_written_whole_leaves_no_part_and_is_named(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    real = np.savez_compressed

    def fills_the_disk(file: Any, **arrays: Any) -> None:
        real(file, **arrays)  # the part is on the disk, then the disk is full
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(records.np, "savez_compressed", fills_the_disk)
    target = tmp_path / "t.npz"
    arrays = _record()
    with pytest.raises(OSError) as caught:
        save_trial(target, **arrays)
    assert caught.value.filename == str(target) and caught.value.errno == errno.ENOSPC
    assert list(tmp_path.iterdir()) == []  # neither the record nor its part


def test_a_killed_run_s_half_written_records_are_removed_by_the_next(tmp_path: Path) -> None:
    (tmp_path / TRIALS_DIR).mkdir(parents=True)
    part = tmp_path / TRIALS_DIR / "a__p0__x__00000.npz.4242.tmp.npz"
    part.write_bytes(b"PK\x03\x04 cut")
    kept = tmp_path / TRIALS_DIR / "a__p0__x__00001.npz"
    kept.write_bytes(b"a whole record")
    ResultsWriter(tmp_path).close()
    assert not part.exists() and kept.exists()


def test_a_run_stopped_by_a_full_disk_says_how_to_finish(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "run"
    real = ResultsWriter.write
    calls = []

    def full_after_one(self: ResultsWriter, rows: Any, recs: Any) -> None:
        calls.append(len(rows))
        if len(calls) > 1:
            raise OSError(errno.ENOSPC, "No space left on device", str(self.path))
        real(self, rows, recs)

    monkeypatch.setattr(results_module.ResultsWriter, "write", full_after_one)
    code = cli_main(["run", "quick", "--out", str(out), "--trials", "4", "--chunk", "2",
                     "--controllers", "leg-edge", "--record", "0", "--no-progress",
                     "--max-steps", "20"])
    assert code == 2
    raw = capsys.readouterr().out
    text = " ".join(raw.split())
    assert "a file could not be written: 2 of 4 trials are in" in text, text
    assert "--resume" in text.split("a file could not be written")[1]
    # the command to paste is on one line, whatever the console's width (it was cut)
    (hint,) = [line for line in raw.splitlines() if "finish with:" in line]
    assert hint.rstrip().endswith("--resume") and f"--out {out}" in hint
    err = capsys.readouterr().err
    assert len(read_results(out)) == 2
    monkeypatch.setattr(results_module.ResultsWriter, "write", real)
    assert cli_main(["run", "quick", "--out", str(out), "--trials", "4", "--chunk", "2",
                     "--controllers", "leg-edge", "--record", "0", "--no-progress",
                     "--max-steps", "20", "--resume"]) == 0, err
    assert sorted(r["trial"] for r in read_results(out)) == [0, 1, 2, 3]


def _record() -> dict[str, Any]:
    """A small valid trial record (every key of ``RECORD_SHAPES``, 3 periods)."""
    scalars = {"camera_kind": "perspective", "camera_xi": 0.0, "leg_radius": 0.01,
               "scenario": "s", "controller": "c", "trial": 0}
    out: dict[str, Any] = {}
    for key, shape in records.RECORD_SHAPES.items():
        if not shape:
            out[key] = np.array(scalars[key])
            continue
        dims = tuple(3 if d == "T" else d for d in shape)
        out[key] = np.zeros(dims)
    out["rotations"][:] = np.eye(3)
    out["goal_rotation"] = np.eye(3)
    out["edge_visible"] = np.ones((3, 6, 2), dtype=bool)
    return out
