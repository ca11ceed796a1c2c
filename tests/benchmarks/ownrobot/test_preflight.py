"""``run`` refuses, before its first trial, a setup where every trial would fail the same
way: one message in the user's terms, a non-zero exit code, nothing run."""

from __future__ import annotations

from pathlib import Path

import pytest

from benchmarks.cli import main
from tests.benchmarks.ownrobot.robots import BLIND_CAMERA, own_robot, write_study


def _run(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = main(["run", *args, "--no-progress"])
    cap = capsys.readouterr()
    return code, cap.out, cap.err


def test_blind_camera_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    own_robot().to_toml(tmp_path / "robot.toml")
    (tmp_path / "camera.toml").write_text(BLIND_CAMERA)
    study = write_study(tmp_path, camera="camera.toml",
                        controllers='["leg-edge", "leg-direction"]')
    out = tmp_path / "out"
    code, stdout, stderr = _run([str(study), "--out", str(out)], capsys)
    assert code == 2
    assert stderr.count("\n") == 1, stderr  # one message
    assert stderr.startswith(f"hexapod-bench: error: {study}: the setup cannot run, every "
                             "trial would fail: the camera sees no leg edge at the home pose: "
                             "the robot is behind the camera")
    assert f"change [camera_from_base] in {tmp_path / 'camera.toml'}" in stderr
    assert not (out / "results.jsonl").exists() and stdout == ""


def test_blind_camera_with_a_controller_that_needs_none_runs(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    own_robot().to_toml(tmp_path / "robot.toml")
    (tmp_path / "camera.toml").write_text(BLIND_CAMERA)
    study = write_study(tmp_path, camera="camera.toml", trials=1,
                        controllers='["leg-edge", "joint-space"]')
    code, stdout, stderr = _run([str(study), "--out", str(tmp_path / "o")], capsys)
    assert code == 0
    assert "hexapod-bench: warning: own: the camera sees no leg edge at the home pose" in stderr
    assert "(the trials of leg-edge would fail; the other controllers do not need the camera)" \
        in stderr
    assert "1 of 2 trials failed" in stdout


def test_empty_workspace_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    own_robot(stroke=(0.100, 0.150)).to_toml(tmp_path / "robot.toml")
    study = write_study(tmp_path)
    out = tmp_path / "out"
    code, stdout, stderr = _run([str(study), "--out", str(out)], capsys)
    assert code == 2
    assert stderr.count("\n") == 1, stderr
    assert stderr.startswith(f"hexapod-bench: error: {study}: the setup cannot run, every "
                             "trial would fail: empty workspace, no home pose: even with the "
                             "platform lowered onto the base the legs measure")
    assert "longer than the longest length of the stroke [100, 150] mm; change stroke_mm in " \
           f"{tmp_path / 'robot.toml'}" in stderr
    assert not (out / "results.jsonl").exists()
    # --no-check runs it anyway: every trial fails, with the cause once, exit code 1
    code, stdout, stderr = _run([str(study), "--out", str(out), "--no-check"], capsys)
    assert code == 1
    assert "2 of 2 trials failed" in stdout and "every trial failed" in stderr
