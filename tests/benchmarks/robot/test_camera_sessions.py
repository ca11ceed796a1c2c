"""The camera check in real servo sessions: the firmware emulator in its own process on
loopback TCP (``--backend serial:socket://...``, real hardware as far as the session can
tell), recordings rendered and encoded through OpenCV, the emulator's own log of the
commands it received (``HLT``)."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from benchmarks.robot import servo
from benchmarks.robot.exits import ServoExit

#: Wall-clock periods against real emulator processes: run alone (`make test`).
pytestmark = [pytest.mark.realtime, pytest.mark.slow]

GOAL_MM = [417.5, 412.5, 417.0, 413.0, 417.5, 412.5]


@contextmanager
def tcp_emulator(tmp_path: Path) -> Iterator[tuple[str, Path]]:
    """``hexapod-emulator --tcp 127.0.0.1:0`` logging every command it receives to a file:
    yields ``serial:socket://...`` and the log (complete once the block ends)."""
    log = tmp_path / "emulator.log"
    with log.open("w") as err:
        proc = subprocess.Popen([sys.executable, "-m", "hexapod.backends.emulator", "--tcp",
                                 "127.0.0.1:0", "--log-level", "DEBUG"],
                                stdout=subprocess.PIPE, stderr=err, text=True)
        try:
            assert proc.stdout is not None
            url = proc.stdout.readline().strip()
            assert url.startswith("socket://"), url
            yield f"serial:{url}", log
        finally:
            proc.terminate()
            proc.wait(10)


def _received(log: Path) -> list[str]:
    """The command words the emulator received, in order (``MOV``, ``POS?``, ``HLT``)."""
    out = []
    for line in log.read_text().splitlines():
        if "emulator: received b'" in line:
            words = line.split("received b'")[1].split("*")[0].split()
            out.append(words[0] if words else "")
    return out


def _goal(tmp_path: Path) -> Path:
    path = tmp_path / "goal.toml"
    path.write_text("lengths_mm = [" + ", ".join(f"{x:.3f}" for x in GOAL_MM) + "]\n")
    return path


def _video(path: Path, offsets: list[tuple[float, float]]) -> Path:
    """A recording of the robot at the emulator's start pose (mid-stroke) moved by
    ``(x [mm], yaw [deg])`` per frame (a black frame for NaN)."""
    from hexapod.fk import forward_kinematics
    from hexapod.geometry import deltalab
    from hexapod.se3 import exp_so3
    from vision.cameras import front_camera
    from vision.render import Renderer
    from vision.sources import VideoRecorder

    g = deltalab()
    cam = front_camera(g)
    sol = forward_kinematics(g, np.full(6, np.mean(g.stroke)))
    renderer = Renderer(cam, g)
    with VideoRecorder.for_camera(path, cam) as rec:
        for dx, yaw in offsets:
            if np.isnan(dx):
                rec.write(np.zeros_like(renderer.render(sol.rotation, sol.translation)))
                continue
            R = exp_so3(np.radians([0.0, 0.0, yaw])) @ sol.rotation
            rec.write(renderer.render(R, sol.translation + np.array([dx * 1e-3, 0.0, 0.0])))
    return path


def test_a_recording_of_another_motion_halts_with_safety(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The issue's case: a video that starts where the robot is, then shows another motion
    (the platform sliding 40 mm aside): the session halts, it does not drive open loop."""
    video = _video(tmp_path / "other.avi", [(0.0, 0.0)] * 5
                   + [(1.0 * k, 0.0) for k in range(1, 41)])
    with tcp_emulator(tmp_path) as (backend, log):
        code = servo.main(["--backend", backend, "--camera", f"video:{video}",
                           "--goal", str(_goal(tmp_path)), "--max-steps", "100"])
    out = capsys.readouterr().out
    assert code == ServoExit.SAFETY == 5, out
    assert "stopped (safety, exit 5): the camera video:" in out
    assert "disagrees with the encoders at period" in out
    assert "camera pose (" in out and "encoder pose (" in out
    assert "the robot was halted" in out
    step = int(out.split("disagrees with the encoders at period ")[1].split(":")[0])
    assert 10 <= step < 45, "caught once the recording is 10 mm off, not at its end"
    received = _received(log)
    assert "MOV" in received, "the robot moved before the recording went astray"
    assert received[-1] == "HLT" or "HLT" in received[-3:], received[-5:]


def test_a_recording_of_another_pose_is_stopped_before_any_motion(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    video = _video(tmp_path / "aside.avi", [(20.0, 0.0)] * 10)
    with tcp_emulator(tmp_path) as (backend, log):
        code = servo.main(["--backend", backend, "--camera", f"video:{video}",
                           "--goal", str(_goal(tmp_path)), "--max-steps", "20"])
    out = capsys.readouterr().out
    assert code == ServoExit.SAFETY, out
    assert "disagrees with the encoders at start, before any motion" in out
    received = _received(log)
    assert "MOV" not in received, "not one command before the check"
    assert "HLT" in received


def test_a_recording_that_cannot_be_checked_at_start_is_refused(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    video = _video(tmp_path / "black.avi", [(np.nan, 0.0)] * 10)
    with tcp_emulator(tmp_path) as (backend, log):
        code = servo.main(["--backend", backend, "--camera", f"video:{video}",
                           "--goal", str(_goal(tmp_path)), "--max-steps", "20"])
    out = capsys.readouterr().out
    assert code == ServoExit.REFUSED == 2, out
    assert "cannot be checked against the encoders at start (only 0 legs seen" in out
    assert "MOV" not in _received(log)


def test_a_blind_camera_halts_after_its_timeout(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The camera goes black after 5 frames: 0.6 s later (30 periods) the session halts."""
    video = _video(tmp_path / "blind.avi", [(0.0, 0.0)] * 5 + [(np.nan, 0.0)] * 200)
    with tcp_emulator(tmp_path) as (backend, log):
        code = servo.main(["--backend", backend, "--camera", f"video:{video}",
                           "--goal", str(_goal(tmp_path)), "--blind-timeout-s", "0.6",
                           "--max-steps", "150"])
    out = capsys.readouterr().out
    assert code == ServoExit.SAFETY, out
    assert "has given no platform pose for 0.6" in out
    assert "(--blind-timeout-s 0.6; at period" in out
    step = int(out.split("; at period ")[1].split(":")[0])
    assert 5 + 20 <= step < 5 + 60, "about 30 periods of 20 ms after the camera went blind"
    assert "HLT" in _received(log)[-3:]


def test_the_simulated_camera_runs_on_a_real_robot_only_when_asked_by_name(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    goal = _goal(tmp_path)
    with tcp_emulator(tmp_path) as (backend, log):
        code = servo.main(["--backend", backend, "--camera", "sim", "--goal", str(goal)])
        err = capsys.readouterr().err
        assert code == ServoExit.REFUSED, err
        assert "--simulated-camera-on-real-robot" in err
        code = servo.main(["--backend", backend, "--camera", "sim",
                           "--simulated-camera-on-real-robot", "--goal", str(goal),
                           "-o", "gain=3", "--tolerance-mm", "0.5", "--max-steps", "150",
                           "--log", str(tmp_path / "session.jsonl")])
    out = capsys.readouterr().out
    assert code == ServoExit.CONVERGED, out
    # the session's log replays as a trial (hexapod-bench viz): its periods, to the goal
    from benchmarks.robot.replay import load_session

    steps = int(out.split("converged after ")[1].split()[0])
    record = load_session(tmp_path / "session.jsonl", goal_file=str(goal))
    assert record.frames == steps
    assert record.arrays["position_error"][-1] < record.arrays["position_error"][0]
    assert "camera sim (simulated: images rendered at the encoders' pose; file front" in out
    assert "camera check:" in out and "largest disagreement" in out
    received = _received(log)
    first_mov = received.index("MOV") if "MOV" in received else -1
    assert first_mov > 0 and "HLT" in received[-3:]
