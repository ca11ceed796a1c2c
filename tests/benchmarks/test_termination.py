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


@pytest.mark.parametrize(("argv", "module", "says"), [
    (["tune", "quick", "--controllers", "leg-edge"], "benchmarks.study.tune_command",
     "finish the tuning with the same command and --resume"),
    (["reproduce", "seed001", "--quick"], "benchmarks.study.reproduce_cli",
     "the same command again finishes it (the trials and calibrations done are kept)")])
def test_a_stopped_tune_or_reproduce_says_how_to_finish_it(
        argv: list[str], module: str, says: str, tmp_path: Path,
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """Ctrl-C where a command has no handling of its own (tune's report, any stage of
    reproduce) said only that each file is whole; a command that can be finished says
    how. (The commands stopped at once: their function replaced by one that raises.)"""
    import importlib

    from benchmarks.cli import main

    def stopped(args: object) -> int:
        raise KeyboardInterrupt

    name = "cmd_" + argv[0]
    monkeypatch.setattr(importlib.import_module(module), name, stopped)
    assert main([*argv, "--out", str(tmp_path / "out")]) == 130
    err = capsys.readouterr().err
    assert f"hexapod-bench {argv[0]}: interrupted (Ctrl-C)" in err and says in err
