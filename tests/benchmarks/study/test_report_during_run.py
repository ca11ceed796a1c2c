"""``hexapod-bench report DIR`` while a run writes into DIR: the report of the rows so far,
the run's record left to the run (a real run in another process)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from benchmarks.cli import main as cli_main
from benchmarks.study.runner import read_results


@pytest.mark.realtime
def test_a_report_during_a_run_leaves_the_run_s_record_to_it(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scen = tmp_path / "long.toml"
    scen.write_text('name = "long"\nseed = 5\ntrials = 30\ncontrollers = ["leg-edge"]\n'
                    '[task]\nmax_steps = 120\n')
    out = tmp_path / "out"
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[3])}
    proc = subprocess.Popen([sys.executable, "-m", "benchmarks.cli", "run", str(scen),
                             "--out", str(out), "--chunk", "1", "--record", "0",
                             "--no-progress"], env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)
    results = out / "results.jsonl"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not (
            results.exists() and len(results.read_text().splitlines()) >= 2):
        time.sleep(0.05)
    try:
        assert cli_main(["report", str(out)]) == 0
        text = " ".join(capsys.readouterr().out.split())
        assert f"note: another hexapod-bench command (PID {proc.pid}: " in text, text
        assert f"run {scen}" in text and f"holds {out}" in text, text
        report = (out / "report.md").read_text()
        assert "**Incomplete**" in report  # its rows so far, and it says so
    finally:
        _, err = proc.communicate(timeout=120)
    assert proc.returncode == 0, err[-2000:]
    meta = json.loads((out / "run.json").read_text())
    assert [c["did"] for c in meta["commands"]] == ["30 trials to run"], meta["commands"]
    assert len(read_results(out)) == 30
    # the run ended: the report command records itself again
    assert cli_main(["report", str(out)]) == 0
    meta = json.loads((out / "run.json").read_text())
    assert [c["did"] for c in meta["commands"]][-1] == "rebuilt report.md and its figures"
    assert "note: a run" not in capsys.readouterr().out


def test_report_of_a_mistyped_directory_makes_nothing(tmp_path: Path) -> None:
    """report typo_dir/sub failed as it should, and left typo_dir/sub/.lock behind."""
    missing = tmp_path / "typo_dir" / "sub"
    assert cli_main(["report", str(missing)]) == 2
    assert not (tmp_path / "typo_dir").exists()
