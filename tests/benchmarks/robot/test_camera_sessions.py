"""The camera check in real servo sessions: the firmware emulator in its own process on
loopback TCP (``--backend serial:socket://...``, real hardware as far as the session can
tell), recordings rendered and encoded through OpenCV, the emulator's own log of the
commands it received (``HLT``), the session's record (its final line)."""

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
from hexapod.fk import forward_kinematics
from hexapod.geometry import deltalab
from tests.benchmarks.robot.sessions import final, periods

#: Wall-clock periods against real emulator processes: run alone (`make test`).
pytestmark = [pytest.mark.realtime, pytest.mark.slow]

GOAL_MM = [417.5, 412.5, 417.0, 413.0, 417.5, 412.5]
# deadlines not enforced: these tests are about the camera (the machine may be loaded)
ANY_LATE = ["--max-missed-consecutive", "0", "--max-missed-fraction", "1"]


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


def _servo(tmp_path: Path, backend: str, *args: str) -> tuple[int, Path]:
    """``servo.main`` on ``backend`` with the goal, its record in ``tmp_path/session``."""
    out = tmp_path / "session"
    code = servo.main(["--backend", backend, "--goal", str(_goal(tmp_path)), "--out",
                       str(out), *args, *ANY_LATE])
    return code, out


def test_a_recording_of_another_motion_halts_with_safety(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The issue's case: a video that starts where the robot is, then shows another motion
    (the platform sliding 40 mm aside): the session halts, it does not drive open loop."""
    video = _video(tmp_path / "other.avi", [(0.0, 0.0)] * 5
                   + [(1.0 * k, 0.0) for k in range(1, 41)])
    with tcp_emulator(tmp_path) as (backend, log):
        code, out = _servo(tmp_path, backend, "--camera", f"video:{video}",
                           "--max-steps", "100")
    stdout = capsys.readouterr().out
    assert code == ServoExit.SAFETY == 5, stdout
    assert f"stopped: the camera video:{video} disagrees with the encoders at period" in stdout
    assert "(exit 5, safety)" in stdout
    assert "robot: halted and confirmed stopped" in stdout
    rec = final(out)
    assert rec["exit_code"] == 5 and rec["exit"] == "safety"
    assert rec["halt_confirmed"] is True and rec["moved"] is True
    reason = rec["reason"]
    assert "disagrees with the encoders at period" in reason
    assert "camera pose (" in reason and "encoder pose (" in reason
    assert "(limits 10 mm, 3 deg: --consistency-mm, --consistency-deg)" in reason
    step = int(reason.split("disagrees with the encoders at period ")[1].split(":")[0])
    assert 10 <= step < 45, "caught once the recording is 10 mm off, not at its end"
    assert len(periods(out)) == step, "the stopping period's command was never sent"
    assert any("camera check:" in c and "largest disagreement" in c for c in rec["checks"])
    received = _received(log)
    assert "MOV" in received, "the robot moved before the recording went astray"
    assert "HLT" in received[-3:], received[-5:]


def test_a_recording_of_another_pose_is_stopped_before_any_motion(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    video = _video(tmp_path / "aside.avi", [(20.0, 0.0)] * 10)
    with tcp_emulator(tmp_path) as (backend, log):
        code, out = _servo(tmp_path, backend, "--camera", f"video:{video}",
                           "--max-steps", "20")
    stdout = capsys.readouterr().out
    assert code == ServoExit.SAFETY, stdout
    rec = final(out)
    assert rec["exit_code"] == 5 and rec["halt_confirmed"] is True
    assert rec["moved"] is False and periods(out) == []
    assert "disagrees with the encoders at start, before any motion" in rec["reason"]
    assert "camera pose (" in rec["reason"] and "encoder pose (" in rec["reason"]
    # the check's line is printed also when no period ran (it was in the record only)
    assert "camera check: 1 periods checked, largest disagreement" in stdout
    received = _received(log)
    assert "MOV" not in received, "not one command before the check"
    assert "HLT" in received


def test_a_recording_that_cannot_be_checked_at_start_is_refused(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    video = _video(tmp_path / "black.avi", [(np.nan, 0.0)] * 10)
    with tcp_emulator(tmp_path) as (backend, log):
        code, out = _servo(tmp_path, backend, "--camera", f"video:{video}",
                           "--max-steps", "20")
    stdout = capsys.readouterr().out
    assert code == ServoExit.REFUSED == 2, stdout
    rec = final(out)
    assert rec["exit_code"] == 2 and rec["moved"] is False
    assert "cannot be checked against the encoders at start (only 0 legs seen" \
        in rec["reason"]
    assert "MOV" not in _received(log)


def test_a_blind_camera_halts_after_its_timeout(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The camera goes black after 5 frames: 0.6 s later the session halts (exit 5)."""
    video = _video(tmp_path / "blind.avi", [(0.0, 0.0)] * 5 + [(np.nan, 0.0)] * 200)
    with tcp_emulator(tmp_path) as (backend, log):
        code, out = _servo(tmp_path, backend, "--camera", f"video:{video}",
                           "--blind-timeout-s", "0.6", "--max-steps", "150")
    stdout = capsys.readouterr().out
    assert code == ServoExit.SAFETY, stdout
    assert "(exit 5, safety)" in stdout and "robot: halted and confirmed stopped" in stdout
    rec = final(out)
    assert rec["exit_code"] == 5 and rec["exit"] == "safety"
    assert rec["halt_confirmed"] is True
    reason = rec["reason"]
    assert "has given no platform pose for " in reason
    assert "(--blind-timeout-s 0.6; at period" in reason
    blind_for = float(reason.split("no platform pose for ")[1].split(" s")[0])
    assert 0.6 <= blind_for < 1.5, reason  # one period past the timeout, on a loaded machine
    step = int(reason.split("; at period ")[1].split(":")[0])
    rows = periods(out)
    assert len(rows) == step and step > 5
    # black frames: images without an edge (not lost frames)
    assert all(r["visible_edges"] > 0 for r in rows[:5])
    assert all(r["visible_edges"] == 0 for r in rows[5:])
    assert rows[-1]["t_s"] - rows[4]["t_s"] >= 0.6 - 0.1, "blind for about the timeout"
    assert "HLT" in _received(log)[-3:]


def test_the_simulated_camera_runs_on_a_real_robot_only_when_asked_by_name(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    goal = _goal(tmp_path)
    with tcp_emulator(tmp_path) as (backend, log):
        code = servo.main(["--backend", backend, "--camera", "sim", "--goal", str(goal)])
        err = capsys.readouterr().err
        assert code == ServoExit.REFUSED, err
        assert "--simulated-camera-on-real-robot" in err
        code, out = _servo(tmp_path, backend, "--camera", "sim",
                           "--simulated-camera-on-real-robot", "-o", "gain=3",
                           "--tolerance-mm", "0.5", "--max-steps", "150")
    stdout = capsys.readouterr().out
    assert code == ServoExit.CONVERGED, stdout
    assert "camera sim (simulated: images rendered at the encoders' pose; file front" in stdout
    assert "camera check:" in stdout and "largest disagreement" in stdout
    rec = final(out)
    assert rec["exit_code"] == 0 and rec["halt_confirmed"] is True
    received = _received(log)
    first_mov = received.index("MOV") if "MOV" in received else -1
    assert first_mov > 0 and "HLT" in received[-3:]
    # the session's record replays as a trial (hexapod-bench viz): its periods, to the
    # goal of its header (no option given), the applied velocities
    from benchmarks.robot.replay import find_session_log, load_session

    steps = int(stdout.split("converged after ")[1].split()[0])
    log_path = find_session_log(out)
    assert log_path == out / "servo.jsonl"
    record = load_session(log_path)
    rows = periods(out)
    assert record.frames == steps == len(rows)
    assert str(record.arrays["controller"]) == "leg-edge"
    goal_pose = forward_kinematics(deltalab(), np.array(GOAL_MM) * 1e-3)
    assert np.allclose(record.arrays["goal_translation"], goal_pose.translation)
    assert record.arrays["position_error"][-1] < record.arrays["position_error"][0]
    assert np.allclose(record.arrays["velocities"] * 1e3,
                       [r["applied_mm_s"] for r in rows])


def test_teach_checks_the_camera_against_the_encoders_before_writing(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``--teach`` from a recording of the platform 20 mm aside of where the encoders put
    it: refused with the session's start check (exit 5), nothing written (it wrote a goal
    of features of another pose, which every later session would drive towards); the
    recording of the robot where it is teaches as before."""
    goal = tmp_path / "taught.toml"
    aside = _video(tmp_path / "aside.avi", [(20.0, 0.0)] * 3)
    code = servo.main(["--backend", "emulator", "--goal", str(goal), "--teach",
                       "--teach-frames", "3", "--camera", f"video:{aside}"])
    out = capsys.readouterr().out
    assert code == ServoExit.SAFETY, out
    assert "disagrees with the encoders at start, before any motion" in out
    assert f"nothing taught ({goal} not written)" in out
    assert not goal.exists() and not goal.with_suffix(".features.npz").exists()
    here = _video(tmp_path / "here.avi", [(0.0, 0.0)] * 3)
    assert servo.main(["--backend", "emulator", "--goal", str(goal), "--teach",
                       "--teach-frames", "3", "--camera", f"video:{here}"]) == 0, \
        capsys.readouterr().out
    assert goal.exists() and goal.with_suffix(".features.npz").exists()
