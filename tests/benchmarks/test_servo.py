"""hexapod-bench servo: the real loop against the firmware emulator and a rendered camera."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from benchmarks.cli import main as cli_main


def _goal(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "goal.toml"
    path.write_text(text)
    return path


def test_servo_converges_through_the_emulator(tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    goal = _goal(tmp_path, "lengths_mm = [420.0, 411.0, 419.0, 412.0, 418.0, 410.0]\n")
    log = tmp_path / "servo.jsonl"
    code = cli_main(["servo", "--backend", "emulator", "--camera", "sim", "--controller",
                     "leg-edge", "--goal", str(goal), "--max-steps", "250", "--log", str(log),
                     "--start-mm", "415", "415", "415", "415", "415", "415"])
    out = capsys.readouterr().out
    assert code == 0, out[-2000:]
    assert "converged after" in out
    lines = [json.loads(x) for x in log.read_text().splitlines()]
    assert 10 < len(lines) < 250
    assert lines[-1]["max_leg_error_mm"] < 0.5
    assert lines[0]["max_leg_error_mm"] > 3.0, "the goal was a few millimetres away"


@pytest.mark.parametrize(("text", "fragment"), [
    ("length_mm = [415.0, 415.0, 415.0, 415.0, 415.0, 415.0]\n", "lengths_mm"),
    ("lengths_mm = [415.0, 415.0, 415.0]\n", "shape"),
    ("lengths_mm = [415.0, 415.0, 415.0, 415.0, 415.0, 600.0]\n", "leg 5"),
])
def test_bad_goal_files_are_refused_before_the_robot_moves(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str, fragment: str) -> None:
    goal = _goal(tmp_path, text)
    code = cli_main(["servo", "--backend", "emulator", "--controller", "leg-edge", "--goal",
                     str(goal)])
    err = capsys.readouterr().err
    assert code == 2
    assert str(goal) in err and fragment in err


def test_unknown_controller_suggests_the_closest(tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    goal = _goal(tmp_path, "lengths_mm = [415.0, 415.0, 415.0, 415.0, 415.0, 415.0]\n")
    code = cli_main(["servo", "--backend", "emulator", "--controller", "leg-edg", "--goal",
                     str(goal)])
    assert code == 2
    assert "did you mean 'leg-edge'" in capsys.readouterr().err
