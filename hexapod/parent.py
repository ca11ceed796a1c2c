"""A child process that ends with its parent, however the parent ends (killed, SIGTERM to
it alone): a study's pool workers, an emulator started by a servo session."""

from __future__ import annotations

import os
import signal
import sys


def end_with_parent(parent: int | None = None) -> None:
    """Ask Linux for SIGTERM when this process's parent ends (``PR_SET_PDEATHSIG``; on
    other systems nothing), and send it now if the parent has already ended: re-parented
    to init, or (``parent``) no longer the process that started this one."""
    if not sys.platform.startswith("linux"):
        return
    import ctypes

    ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGTERM))  # PR_SET_PDEATHSIG
    if os.getppid() == 1 or (parent is not None and os.getppid() != parent):
        os.kill(os.getpid(), signal.SIGTERM)
