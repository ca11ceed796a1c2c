"""The GCS backend in the command-line tools, as real processes on 127.0.0.1.

``hexapod-bench servo --backend gcs:tcp://...`` against ``hexapod-emulator --gcs``: Ctrl-C
(a real SIGINT) halts the platform, checked over a second connection to the controller;
``hexapod-bench run --backend gcs-emulator`` with a dropped connection: the trial fails
with a clear error and the rows written before are kept.
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from hexapod.backends import gcs_protocol as gp
from tests.benchmarks.robot.interrupt import interrupt_servo

ROOT = Path(__file__).resolve().parents[2]
ENV = {**os.environ, "PYTHONUNBUFFERED": "1"}
# a reachable goal 2 to 3 mm from the zero position (every leg at 415 mm)
GOAL_MM = [417.5, 412.5, 417.0, 413.0, 417.5, 412.5]


def _query(address: str, *lines: str) -> list[bytes]:
    """Answers to queries on a fresh connection (a second client of the controller)."""
    host, _, port = address.rpartition(":")
    with socket.create_connection((host, int(port)), timeout=5.0) as sock:
        sock.sendall(gp.encode(*lines))
        buf, out = bytearray(), []
        while len(out) < len(lines):
            while (end := gp.answer_end(buf)) < 0:
                chunk = sock.recv(4096)
                assert chunk, "the controller closed the connection"
                buf += chunk
            out.append(bytes(buf[:end]))
            del buf[:end]
    return out


@pytest.fixture
def controller() -> Iterator[str]:
    """``hexapod-emulator --gcs`` in its own process; yields HOST:PORT."""
    proc = subprocess.Popen([sys.executable, "-m", "hexapod.backends.emulator", "--gcs",
                             "--tcp", "127.0.0.1:0"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=ENV)
    try:
        assert proc.stdout is not None
        url = proc.stdout.readline().strip()
        assert url.startswith("tcp://127.0.0.1:"), proc.communicate(timeout=5)
        yield url.removeprefix("tcp://")
    finally:
        proc.terminate()
        proc.communicate(timeout=10)


@pytest.mark.slow
def test_ctrl_c_on_servo_halts_the_platform(controller: str, tmp_path: Path) -> None:
    goal = tmp_path / "goal.toml"
    goal.write_text("lengths_mm = [" + ", ".join(f"{x:.3f}" for x in GOAL_MM) + "]\n")
    log = tmp_path / "servo.jsonl"
    # VLS 0.1 mm/s: the platform lags its targets, so it would still be moving after the
    # process exits if nothing halted it
    spec = f"gcs:tcp://{controller}?velocity=0.1"
    code, out, err = interrupt_servo(
        ["--backend", spec, "--camera", "sim", "--simulated-camera-on-real-robot", "--goal",
         str(goal), "-o", "gain=3", "--max-missed-consecutive", "0", "--max-missed-fraction",
         "1"], log, ROOT, ENV, 60)
    assert code == 130, (out, err)
    assert "stopped: SIGINT received (exit 130" in out
    assert "robot: halted and confirmed stopped" in out and "HLT confirmed" in out
    assert "Traceback" not in err
    records = [json.loads(x) for x in log.read_text().splitlines()]
    rows = [r for r in records if "step" in r]
    assert rows[-1]["rtt_ms"] > 0
    assert records[-1]["final"] is True and records[-1]["halt_confirmed"] is True
    # a second connection: the platform stands still, on target, error 10 already read
    first, ont, err_code = _query(controller, "POS?", "ONT?", "ERR?")
    time.sleep(0.3)
    (second,) = _query(controller, "POS?")
    assert first == second
    p = gp.parse_axis_answer(first, gp.AXES)
    assert max(abs(p[a]) for a in gp.AXES) > 0  # it had moved before the halt
    assert ont == b"X=1 \nY=1 \nZ=1 \nU=1 \nV=1 \nW=1\n"
    assert err_code == b"0\n"


@pytest.mark.slow
def test_study_with_a_dropped_connection_keeps_the_rows(tmp_path: Path) -> None:
    out = tmp_path / "run"
    base = [sys.executable, "-m", "benchmarks.cli", "run", "quick", "--out", str(out),
            "--controllers", "leg-edge", "--max-steps", "15", "--no-progress"]
    ok = subprocess.run([*base, "--trials", "1", "--backend", "gcs-emulator"],
                        capture_output=True, text=True, cwd=ROOT, env=ENV, timeout=120)
    assert ok.returncode == 0, ok.stderr[-2000:]
    # the next trial's controller hangs up after 40 commands (about 7 periods)
    dropped = subprocess.run([*base, "--trials", "2", "--resume",
                              "--backend", "gcs-emulator:disconnect_after=40"],
                             capture_output=True, text=True, cwd=ROOT, env=ENV, timeout=120)
    assert dropped.returncode == 0, dropped.stderr[-2000:]
    rows = [json.loads(x) for x in (out / "results.jsonl").read_text().splitlines()]
    assert [r["trial"] for r in rows] == [0, 1]
    kept, failed = rows
    assert kept["backend"] == "gcs-emulator" and "Gcs" not in (kept["failure"] or "")
    assert kept["final_position_error_mm"] is not None and kept["rtt_median_ms"] > 0
    assert failed["backend"] == "gcs-emulator:disconnect_after=40"
    assert failed["failure"].startswith("GcsDisconnectedError: GCS controller tcp://127.0.0.1:")
    assert "closed the connection" in failed["failure"]
    assert (out / "report.md").exists()
