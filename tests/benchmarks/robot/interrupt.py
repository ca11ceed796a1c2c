"""Ctrl-C of a running servo loop, shared by the tests of the backends it drives."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path


def interrupt_servo(args: list[str], log: Path, cwd: Path, env: dict[str, str],
                    wait_s: float) -> tuple[int, str, str]:
    """Start ``python -m benchmarks.robot.servo ARGS --log LOG``, send SIGINT once the
    log holds 10 periods (within ``wait_s`` seconds), and return the exit code, the
    standard output and the standard error."""
    proc = subprocess.Popen([sys.executable, "-m", "benchmarks.robot.servo", *args,
                             "--log", str(log)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=cwd, env=env)
    try:
        deadline = time.monotonic() + wait_s
        while time.monotonic() < deadline and (
                not log.exists() or log.read_text().count('"step"') < 10):
            assert proc.poll() is None, proc.communicate()
            time.sleep(0.05)
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=20)
    finally:
        if proc.poll() is None:
            proc.kill()
    return proc.returncode, out, err
