"""The emulator's command line in a real process, for the CLI tests of the board
(test_emulator.py) and of the GCS controller (test_gcs_emulator.py)."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager


def spawn_emulator(*args: str) -> subprocess.Popen[str]:
    """``python -m hexapod.backends.emulator ARGS`` with its output piped (text)."""
    return subprocess.Popen([sys.executable, "-m", "hexapod.backends.emulator", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


@contextmanager
def emulator_process(*args: str) -> Iterator[tuple[subprocess.Popen[str], str]]:
    """The emulator serving: yields its process and the first line it printed (the
    device or the address it serves); killed on the way out if it still runs."""
    proc = spawn_emulator(*args)
    try:
        assert proc.stdout is not None
        yield proc, proc.stdout.readline().strip()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
