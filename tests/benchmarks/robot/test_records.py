"""Where a servo session is recorded (benchmarks.robot.records): never over a user's file."""

from __future__ import annotations

import datetime as dt
import json
from pathlib import Path

import pytest

from benchmarks.robot.records import SessionLog, is_servo_log, session_path
from hexapod.exceptions import OutputError

NOW = dt.datetime(2026, 11, 28, 10, 45, 59, tzinfo=dt.UTC)


def test_the_default_is_a_new_directory_each_time(tmp_path: Path,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    first = session_path(None, None, "leg-edge", NOW)
    assert first == Path("servo-runs/20261128T104559Z-leg-edge/servo.jsonl")
    first.parent.mkdir(parents=True)
    second = session_path(None, None, "leg-edge", NOW)
    assert second == Path("servo-runs/20261128T104559Z-leg-edge-2/servo.jsonl")
    odd = session_path(None, None, "tests.benchmarks.plugins:Crash At", NOW)
    assert odd.parent.name == "20261128T104559Z-tests.benchmarks.plugins-Crash-At"


def test_out_must_be_new_or_empty(tmp_path: Path) -> None:
    assert session_path(str(tmp_path / "new"), None, "c") == tmp_path / "new" / "servo.jsonl"
    (tmp_path / "empty").mkdir()
    assert session_path(str(tmp_path / "empty"), None, "c").parent == tmp_path / "empty"
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "x").write_text("mine")
    with pytest.raises(OutputError, match="full: is not empty"):
        session_path(str(tmp_path / "full"), None, "c")
    with pytest.raises(OutputError, match="not both"):
        session_path(str(tmp_path / "new"), str(tmp_path / "l.jsonl"), "c")


def test_the_log_holds_header_periods_and_final(tmp_path: Path) -> None:
    log = SessionLog(tmp_path / "d" / "servo.jsonl").open({"backend": "sim"})
    log.write({"step": 0, "t_s": 0.0, "x": float("nan")})
    log.final({"exit_code": 3})
    log.final({"exit_code": 4})  # once only
    lines = [json.loads(x) for x in log.path.read_text().splitlines()]
    assert lines == [{"servo_session": 1, "backend": "sim"}, {"step": 0, "t_s": 0.0, "x": None},
                     {"final": True, "exit_code": 3}]
    assert is_servo_log(log.path)
    mine = tmp_path / "mine.jsonl"
    mine.write_text('{"my": 1}\n')
    assert not is_servo_log(mine)


def test_a_log_without_its_final_record_is_never_replaced(tmp_path: Path) -> None:
    """--log over a finished session's log: replaced; over one whose session was killed
    (no final record: the only record of what the robot did): refused, kept."""
    done = SessionLog(tmp_path / "done.jsonl").open({"backend": "sim"})
    done.write({"step": 0, "t_s": 0.0})
    done.final({"exit_code": 0})
    assert session_path(None, str(done.path), "c") == done.path
    cut = SessionLog(tmp_path / "cut.jsonl").open({"backend": "sim"})
    cut.write({"step": 0, "t_s": 0.0})
    cut._f.close()  # type: ignore[union-attr]  (SIGKILL: no final record)
    before = cut.path.read_bytes()
    with pytest.raises(OutputError, match=r"cut\.jsonl: holds a session that ended without "
                                          r"its final record"):
        session_path(None, str(cut.path), "c")
    assert cut.path.read_bytes() == before
