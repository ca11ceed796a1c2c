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


@pytest.mark.slow
def test_blind_camera_with_a_controller_that_needs_none_runs(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    own_robot().to_toml(tmp_path / "robot.toml")
    (tmp_path / "camera.toml").write_text(BLIND_CAMERA)
    study = write_study(tmp_path, camera="camera.toml", trials=1,
                        controllers='["leg-edge", "joint-space"]')
    code, stdout, stderr = _run([str(study), "--out", str(tmp_path / "o")], capsys)
    assert code == 3  # it runs; leg-edge fails its only trial: its own exit code
    assert "hexapod-bench: warning: own: the camera sees no leg edge at the home pose" in stderr
    assert "(the trials of leg-edge would fail; the other controllers do not need the camera)" \
        in stderr
    assert "1 of 2 trials failed" in stdout


@pytest.mark.slow
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


def test_unreachable_fixed_goal_is_refused(tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    """Legs 0 and 1: base joints 61 mm apart, platform joints 324 mm apart, so
    q_0 <= 324 + q_1 + 61 mm (triangle inequality): q_0 = 990 mm with q_1 = 260 mm has no
    pose, although every length is inside the stroke [250, 1000] mm."""
    g = own_robot(stroke=(0.250, 1.000))
    g.to_toml(tmp_path / "robot.toml")
    import numpy as np

    d_base = np.linalg.norm(g.base_points[0] - g.base_points[1]) * 1e3
    d_plat = np.linalg.norm(g.platform_points[0] - g.platform_points[1]) * 1e3
    assert d_base + d_plat + 260 < 990
    study = write_study(tmp_path)
    study.write_text(study.read_text().replace(
        "[task]\n", '[task]\nkind = "fixed"\nstart_mm = [460, 460, 460, 460, 460, 460]\n'
                    "goal_mm = [990, 260, 600, 600, 600, 600]\n"))
    code, _, stderr = _run([str(study), "--out", str(tmp_path / "o")], capsys)
    assert code == 2
    assert stderr.startswith(f"hexapod-bench: error: {study}: the setup cannot run, every "
                             "trial would fail: task.goal_mm: no platform pose near the home "
                             "pose has these six leg lengths (the goal is unreachable)")
    assert "start_mm" not in stderr  # the start (home) is reachable


def test_a_camera_that_never_sees_three_edges_is_refused(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A camera pose given in metres where the file wants mm (the camera 1 mm from the
    base centre): an edge or two at home, fewer than three at every reachable pose.
    check said 'The setup can run' and run failed every trial with exit 1 ('interaction
    matrix rank 0 < 6'); both now refuse, naming the camera file's key."""
    own_robot().to_toml(tmp_path / "robot.toml")
    (tmp_path / "camera.toml").write_text(BLIND_CAMERA.replace(
        "translation_mm = [0.0, 0.0, -2000.0]\nrotation_vector_deg = [0.0, 0.0, 0.0]",
        "translation_mm = [0.0, 0.267449, 1.001957]\n"
        "rotation_vector_deg = [44.217, 76.586, -99.710]"))
    study = write_study(tmp_path, camera="camera.toml")
    out = tmp_path / "out"
    code, _, stderr = _run([str(study), "--out", str(out)], capsys)
    assert code == 2, stderr
    assert "the camera sees fewer than 3 leg edges at every reachable pose" in stderr
    assert f"change [camera_from_base] in {tmp_path / 'camera.toml'}" in stderr
    assert not (out / "results.jsonl").exists()
