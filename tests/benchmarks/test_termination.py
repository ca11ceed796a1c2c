"""SIGTERM stops a command as Ctrl-C does (benchmarks.termination), in a real process."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from benchmarks.termination import Terminated, exit_status, how_stopped, sigterm_interrupts


def test_sigterm_raises_terminated_inside_the_block_only() -> None:
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL
    with pytest.raises(Terminated) as caught, sigterm_interrupts():
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(1)  # the handler runs at the next bytecode
    assert isinstance(caught.value, KeyboardInterrupt)  # every Ctrl-C handler takes it
    assert exit_status(caught.value) == 143 and how_stopped(caught.value) == \
        "terminated (SIGTERM)"
    assert exit_status(KeyboardInterrupt()) == 130
    assert how_stopped(KeyboardInterrupt()) == "interrupted (Ctrl-C)"
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL  # restored


def test_a_parent_s_ignored_sigterm_is_left_ignored() -> None:
    previous = signal.signal(signal.SIGTERM, signal.SIG_IGN)
    try:
        with sigterm_interrupts():
            assert signal.getsignal(signal.SIGTERM) is signal.SIG_IGN
            os.kill(os.getpid(), signal.SIGTERM)  # ignored: nothing happens
        assert signal.getsignal(signal.SIGTERM) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGTERM, previous)


@pytest.mark.realtime
def test_sigterm_during_a_command_exits_143_without_a_traceback(tmp_path: Path) -> None:
    """A command without its own handling (here ``list``, its work replaced by a wait),
    stopped by SIGTERM: the message of an interrupted command, exit 143, no traceback."""
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])}
    code = ("import sys, time\n"
            "from benchmarks import cli\n"
            "def busy(args):\n"
            "    print('ready', flush=True)\n"
            "    time.sleep(30)\n"
            "    return 0\n"
            "cli.cmd_list = busy\n"
            "sys.exit(cli.main(['list']))\n")
    proc = subprocess.Popen([sys.executable, "-c", code], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    assert proc.stdout.readline().strip() == "ready"
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=20)
    assert proc.returncode == 143, err
    assert "hexapod-bench list: terminated (SIGTERM)" in err and "Traceback" not in err, err
