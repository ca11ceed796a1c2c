"""Replaying a servo session (benchmarks.robot.replay, ``hexapod-bench viz LOG``): the log's
periods as a trial record (the data path; the live viewer and the browser are tested with
recorded trials in tests/hexapod/test_visualize.py)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from benchmarks.cli import main as cli_main
from benchmarks.exceptions import BenchmarkError
from benchmarks.robot.loop import PeriodStatus
from benchmarks.robot.records import is_servo_log
from benchmarks.robot.replay import find_session_log, load_session
from hexapod.fk import forward_kinematics
from hexapod.geometry import deltalab

G = deltalab()
START = np.full(6, 0.415)
GOAL_MM = [417.5, 412.5, 417.0, 413.0, 417.5, 412.5]


def _log(path: Path, periods: int = 6, extra: str = "") -> Path:
    """A servo log as the loop writes it (:meth:`PeriodStatus.to_json`): the lengths go
    from 415 mm to the goal; period 2 is a lost frame."""
    goal = np.array(GOAL_MM) * 1e-3
    lines = []
    for k in range(periods):
        q = START + (goal - START) * k / (periods - 1)
        lost = k == 2
        s = PeriodStatus(step=k, t=0.02 * k, lengths=q, leg_error=float(np.abs(q - goal).max()),
                         feature_error=np.nan if lost else 0.01 / (k + 1),
                         controller_error=0.1, velocities=np.full(6, 0.001 * k),
                         visible_edges=0 if lost else 12,
                         reason="lost camera frame" if lost else None, lost_frame=lost,
                         rtt=0.001, missed=False, missed_total=0, lost_total=int(k >= 2),
                         refused_total=0, applied=np.full(6, 0.001 * k))
        lines.append(json.dumps(s.to_json()))
    path.write_text("\n".join(lines) + "\n" + extra)
    return path


def test_a_session_log_loads_as_a_trial(tmp_path: Path) -> None:
    goal = tmp_path / "goal.toml"
    goal.write_text(f"lengths_mm = {GOAL_MM}\n")
    log = _log(tmp_path / "servo.jsonl", extra='{"final": true, "reason": "converged"}\n')
    rec = load_session(log, goal_file=str(goal))
    assert rec.frames == 6 and rec.title == "servo session servo.jsonl / servo / trial 0"
    a = rec.arrays
    assert np.allclose(a["t"], 0.02 * np.arange(6))
    assert np.allclose(a["lengths"][0], START) and np.allclose(a["lengths"][-1], 1e-3 *
                                                               np.array(GOAL_MM))
    sol = forward_kinematics(G, START)
    assert np.allclose(a["rotations"][0], sol.rotation, atol=1e-9)
    assert np.allclose(a["translations"][0], sol.translation, atol=1e-9)
    # the last period is at the goal: no pose error there, some at the start
    assert a["position_error"][-1] < 1e-6 and a["orientation_error"][-1] < 1e-6
    assert a["position_error"][0] > 1e-4
    assert np.isnan(a["error_norm"][2]) and a["error_norm"][0] == pytest.approx(0.01)
    assert not a["edge_visible"][2].any() and a["edge_visible"][[0, 1, 3, 4, 5]].all()
    assert np.allclose(a["velocities"][3], 0.003)
    assert np.allclose(a["camera_from_base"][3], [0, 0, 0, 1])


def _session_record(path: Path, periods: int = 6) -> Path:
    """A record as a session writes it (benchmarks.robot.records.SessionLog): the header,
    the periods (applied velocities half the commanded ones: a speed cap) and the final
    record."""
    from benchmarks.robot.records import SessionLog

    goal = np.array(GOAL_MM) * 1e-3
    log = SessionLog(path)
    log.open({"backend": "emulator", "camera": "sim", "camera_file": "omni",
              "camera_pose": None, "controller": "leg-edge", "geometry": "deltalab",
              "goal": "elsewhere/goal.toml", "goal_lengths_mm": GOAL_MM})
    for k in range(periods):
        q = START + (goal - START) * k / (periods - 1)
        log.write(PeriodStatus(
            step=k, t=0.02 * k, lengths=q, leg_error=float(np.abs(q - goal).max()),
            feature_error=0.01, controller_error=0.1, velocities=np.full(6, 0.002 * k),
            visible_edges=12, reason=None, lost_frame=False, rtt=0.001, missed=False,
            missed_total=0, lost_total=0, refused_total=0,
            applied=np.full(6, 0.001 * k)).to_json())
    log.final({"exit_code": 3, "reason": "--max-steps 6 reached", "halt_confirmed": True})
    return path


def test_a_session_record_replays_with_its_header(tmp_path: Path) -> None:
    """The session record's format: the header gives the robot, camera, goal and
    controller; its final record is not a period; the applied velocities are shown."""
    log = _session_record(tmp_path / "servo.jsonl")
    lines = log.read_text().splitlines()
    assert '"servo_session"' in lines[0] and '"final": true' in lines[-1]
    assert is_servo_log(log) and find_session_log(tmp_path) == log
    rec = load_session(log)
    a = rec.arrays
    assert rec.frames == 6 and str(a["controller"]) == "leg-edge"
    assert str(a["camera_kind"]) == "unified", "the header's omni camera"
    # the goal is the header's goal lengths (the goal file is not there)
    goal = forward_kinematics(G, np.array(GOAL_MM) * 1e-3)
    assert np.allclose(a["goal_translation"], goal.translation)
    assert a["position_error"][-1] < 1e-6 < a["position_error"][0]
    assert np.allclose(a["velocities"][3], 0.003), "applied, not the commanded 0.006"
    # an option replaces the header's
    assert str(load_session(log, camera_file="front").arrays["camera_kind"]) == "perspective"


def test_a_session_stopped_before_its_first_period_says_why(tmp_path: Path) -> None:
    from benchmarks.robot.records import SessionLog

    log = SessionLog(tmp_path / "servo.jsonl")
    log.open({"controller": "leg-edge"})
    log.final({"exit_code": 5, "reason": "the camera sim disagrees with the encoders at "
                                         "start"})
    assert is_servo_log(log.path)
    with pytest.raises(BenchmarkError, match=r"no period in this servo log \(the session "
                                             r"ended before its first period: the camera"):
        load_session(log.path)


def test_without_a_goal_the_errors_are_to_the_last_pose(tmp_path: Path) -> None:
    rec = load_session(_log(tmp_path / "s.jsonl"))
    assert rec.arrays["position_error"][-1] == 0.0
    assert np.allclose(rec.arrays["goal_translation"], rec.arrays["translations"][-1])


def test_finding_the_log(tmp_path: Path) -> None:
    (tmp_path / "session").mkdir()
    log = _log(tmp_path / "session" / "servo.jsonl")
    assert is_servo_log(log)
    assert find_session_log(log) == log
    assert find_session_log(tmp_path / "session") == log
    (tmp_path / "session" / "notes.jsonl").write_text('{"note": 1}\n')
    assert find_session_log(tmp_path / "session") == log, "another JSON-lines file is not one"
    _log(tmp_path / "session" / "second.jsonl")
    with pytest.raises(BenchmarkError, match="2 servo session logs"):
        find_session_log(tmp_path / "session")
    assert find_session_log(tmp_path / "nothing") is None


@pytest.mark.parametrize(("text", "fragment"), [
    ('{"step": 0, "t_s": 0.0, "lengths_mm": [415, 415]}\n', "line 1: lengths_mm must be 6 "
                                                             "finite numbers"),
    ('{"step": 0, "t_s": 0.0, "lengths_mm": [415, 415, 415, 415, 415, 415]}\nnot json\n',
     "line 2: not JSON"),
    ('{"final": true}\n', "no period in this servo log"),
])
def test_bad_logs_are_refused_with_the_line(tmp_path: Path, text: str, fragment: str) -> None:
    path = tmp_path / "bad.jsonl"
    path.write_text(text)
    with pytest.raises(BenchmarkError, match=fragment):
        load_session(path)


def test_a_line_cut_by_a_crash_ends_the_log(tmp_path: Path) -> None:
    log = _log(tmp_path / "s.jsonl", extra='{"step": 6, "t_s": 0.1')  # no newline: cut
    assert load_session(log).frames == 6


def test_viz_names_what_it_replays(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    other = tmp_path / "notes.txt"
    other.write_text("hello\n")
    assert cli_main(["viz", str(other)]) == 2
    err = capsys.readouterr().err
    assert "not a servo session log" in err and "servo --log FILE.jsonl" in err
    assert "servo-runs/<UTC time>-<controller>/" in err
    assert "--record K" not in err.split("or a servo session")[1], "no --record for servo"
    assert cli_main(["viz", str(tmp_path / "missing")]) == 2
    assert "no such file or directory" in capsys.readouterr().err


@pytest.mark.slow
def test_viz_writes_the_replay_of_a_session(tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    log = _log(tmp_path / "servo.jsonl")
    html = tmp_path / "replay.html"
    assert cli_main(["viz", str(log), "--html", str(html)]) == 0
    out = capsys.readouterr().out
    assert out.startswith("servo session servo.jsonl / servo / trial 0: wrote")
    assert html.stat().st_size > 10_000 and html.with_suffix(".png").stat().st_size > 1000
