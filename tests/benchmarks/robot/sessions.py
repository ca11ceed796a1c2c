"""Real processes for the servo session's exit paths: a ``hexapod-emulator`` (its log kept
in a file, at INFO, so the ``HLT`` it received can be read back) and a
``python -m benchmarks.robot.servo`` in its own process group (its own session, so a
signal reaches it as a terminal's or a service manager's would)."""

from __future__ import annotations

import json
import os
import select
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[3]
ENV = {**os.environ, "PYTHONUNBUFFERED": "1", "PYTHONPATH": str(ROOT)}
# a reachable goal 2 to 3 mm from the emulator's initial (mid-stroke, 415 mm) lengths
GOAL_MM = [417.5, 412.5, 417.0, 413.0, 417.5, 412.5]


def goal_file(tmp_path: Path, lengths_mm: list[float] = GOAL_MM) -> Path:
    """A goal TOML file."""
    path = tmp_path / "goal.toml"
    path.write_text("lengths_mm = [" + ", ".join(f"{x:.3f}" for x in lengths_mm) + "]\n")
    return path


def start_pose_video(tmp_path: Path, frames: int = 8) -> Path:
    """A video file (``start.avi``) of ``frames`` frames of deltalab seen by the front
    camera at the emulator's initial pose (every leg at mid-stroke)."""
    import numpy as np

    from hexapod.fk import forward_kinematics
    from hexapod.geometry import deltalab
    from vision.cameras import front_camera
    from vision.render import Renderer
    from vision.sources import VideoRecorder

    g = deltalab()
    cam = front_camera(g)
    sol = forward_kinematics(g, np.full(6, np.mean(g.stroke)))
    image = Renderer(cam, g).render(sol.rotation, sol.translation)
    video = tmp_path / "start.avi"
    with VideoRecorder.for_camera(video, cam) as rec:
        for _ in range(frames):
            rec.write(image)
    return video


class EmulatorProc:
    """``python -m hexapod.backends.emulator OPTIONS --log-level INFO``, its stderr in
    ``log_path``; :attr:`url` is the first line it prints."""

    def __init__(self, log_path: Path, *options: str) -> None:
        self.log_path = log_path
        self._err = log_path.open("w")
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "hexapod.backends.emulator", *options, "--log-level",
             "INFO"], stdout=subprocess.PIPE, stderr=self._err, text=True, cwd=ROOT, env=ENV)
        assert self.proc.stdout is not None
        ready, _, _ = select.select([self.proc.stdout], [], [], 30)
        self.url = self.proc.stdout.readline().strip() if ready else ""
        assert self.url, self.log()

    def log(self) -> str:
        """What the emulator logged so far."""
        self._err.flush()
        return self.log_path.read_text()

    def stop(self) -> None:
        """Terminate it (if it still runs)."""
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        if self.proc.stdout is not None:
            self.proc.stdout.close()
        self._err.close()


def start_servo(args: list[str], out: Path) -> subprocess.Popen[str]:
    """``python -m benchmarks.robot.servo ARGS --out OUT`` as the leader of its own
    process group."""
    return subprocess.Popen([sys.executable, "-m", "benchmarks.robot.servo", *args,
                             "--out", str(out)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, cwd=ROOT, env=ENV,
                            start_new_session=True)


def records(out: Path) -> list[dict[str, Any]]:
    """The session record's lines (header, periods, final)."""
    path = out / "servo.jsonl"
    if not path.exists():
        return []
    return [json.loads(x) for x in path.read_text().splitlines() if x.strip()]


def periods(out: Path) -> list[dict[str, Any]]:
    """The period lines of a session record."""
    return [r for r in records(out) if "step" in r]


def final(out: Path) -> dict[str, Any]:
    """The final record (the last line, which must be one)."""
    last = records(out)[-1]
    assert last.get("final") is True, last
    return last


def wait_periods(proc: subprocess.Popen[str], out: Path, n: int, wait_s: float = 60) -> None:
    """Wait until the session logged ``n`` periods (the process must still run)."""
    deadline = time.monotonic() + wait_s
    while len(periods(out)) < n:
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, f"fewer than {n} periods in {wait_s} s"
        time.sleep(0.05)


def finish(proc: subprocess.Popen[str], timeout: float = 30) -> tuple[int, str, str]:
    """Wait for the servo; its exit code, stdout and stderr (killed if it hangs)."""
    try:
        out, err = proc.communicate(timeout=timeout)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.communicate()
    return proc.returncode, out, err
