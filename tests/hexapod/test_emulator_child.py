"""An emulator started as a child process (``process=True``, ``gcs-emulator:process=1``)
is out of the host's process group: a Ctrl-C at the terminal reaches the host, which
halts the robot through the emulator and has the halt confirmed (the emulator died of the
same SIGINT first: "NOT confirmed stopped"); it still ends with the host, however the
host ends."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

HOST = r"""
import logging, signal, sys
import numpy as np
signal.signal(signal.SIGINT, signal.default_int_handler)  # (a background job ignores it)
from hexapod import deltalab
from hexapod.backends.emulator import BoardConfig, EmulatorProcess
from hexapod.backends.serial import SerialRobot
proc = EmulatorProcess(BoardConfig.from_geometry(deltalab()))
robot = SerialRobot(proc.url)
print("connected", flush=True)
try:
    while True:
        robot.step(np.full(6, 0.001), 0.02)
except KeyboardInterrupt:  # the robot sent HLT and closed its port
    print("emulator alive" if proc.running else "emulator dead", flush=True)
if proc.running:  # what the board says now, to a new connection (its open reads ERR?)
    logging.basicConfig(level=logging.INFO, stream=sys.stdout, format="%(message)s")
    again = SerialRobot(proc.url)
    print("moving", int(again.status().moving), flush=True)
    again.close()
proc.stop()
"""

ORPHAN = r"""
import os
from hexapod import deltalab
from hexapod.backends.emulator import BoardConfig, EmulatorProcess
proc = EmulatorProcess(BoardConfig.from_geometry(deltalab()))
print(proc.proc.pid, flush=True)
os._exit(0)  # the host dies without stopping its emulator
"""


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    with open(f"/proc/{pid}/stat") as f:  # a zombie (ended, not yet reaped) is not alive
        return f.read().split(") ", 1)[1][0] != "Z"


def test_a_ctrl_c_to_the_hosts_group_is_halted_through_a_living_emulator(
        tmp_path: Path) -> None:
    host = subprocess.Popen([sys.executable, "-c", HOST], stdout=subprocess.PIPE, text=True,
                            start_new_session=True, cwd=Path(__file__).parents[2])
    try:
        assert host.stdout is not None
        host.stdout.readline()  # connected
        time.sleep(0.3)  # stepping
        os.killpg(host.pid, signal.SIGINT)  # the terminal's Ctrl-C: the foreground group
        out, _ = host.communicate(timeout=30)
    finally:
        if host.poll() is None:
            host.kill()
    # the board heard the HLT of the Ctrl-C (its error 10, read by the next connection)
    lines = out.splitlines()
    assert lines[0] == "emulator alive", out
    assert any(line.endswith("cleared a pending error 10 (halted by command)")
               for line in lines), out
    assert "moving 0" in lines, out


def test_an_emulator_ends_with_its_host() -> None:
    host = subprocess.run([sys.executable, "-c", ORPHAN], capture_output=True, text=True,
                          timeout=60, cwd=Path(__file__).parents[2], check=True)
    pid = int(host.stdout.split()[0])
    deadline = time.monotonic() + 10
    while _alive(pid) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not _alive(pid)
