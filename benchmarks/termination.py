"""SIGTERM stops a command the way Ctrl-C does.

A study stopped by a service manager (``systemctl stop``, ``docker stop``), a batch
scheduler at the end of its time (Slurm sends SIGTERM first) or a plain ``kill`` should
end as an interrupted one does: the rows written are kept, the report is written from
them, and the command prints how to finish the run (``--resume``). Python's default for
SIGTERM is to die at once, so ``hexapod-bench`` installs :func:`sigterm_interrupts` around
each command: SIGTERM raises :class:`Terminated`, a :class:`KeyboardInterrupt`, so every
place that handles Ctrl-C (the study runner, the robot backends' halt) handles it too.
The exit status is the shell's for a signal, ``128 + signal`` (130 for Ctrl-C, 143 for
SIGTERM). A second SIGTERM during that shutdown ends the process at once.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType


class Terminated(KeyboardInterrupt):
    """A SIGTERM, raised where the command was (see the module docstring).

    Attributes:
        signum: The signal's number.
    """

    def __init__(self, signum: int = int(signal.SIGTERM)) -> None:
        self.signum = signum
        super().__init__(f"terminated by signal {signum}")


def _raise(signum: int, frame: FrameType | None) -> None:
    signal.signal(signum, signal.SIG_DFL)  # a second one ends the process at once
    raise Terminated(signum)


@contextmanager
def sigterm_interrupts() -> Iterator[None]:
    """SIGTERM raises :class:`Terminated` inside the block (main thread only, and only
    when SIGTERM has Python's default action: a parent that ignores it, or a handler
    installed before, is left as it is); the previous action is restored after."""
    if (threading.current_thread() is not threading.main_thread()
            or signal.getsignal(signal.SIGTERM) is not signal.SIG_DFL):
        yield
        return
    signal.signal(signal.SIGTERM, _raise)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)


def exit_status(stop: KeyboardInterrupt) -> int:
    """The shell's exit status of a command stopped by ``stop``: 143 for SIGTERM, 130 for
    Ctrl-C."""
    return 128 + (stop.signum if isinstance(stop, Terminated) else int(signal.SIGINT))


def how_stopped(stop: KeyboardInterrupt) -> str:
    """``interrupted (Ctrl-C)`` or ``terminated (SIGTERM)``."""
    if isinstance(stop, Terminated):
        return f"terminated ({signal.Signals(stop.signum).name})"
    return "interrupted (Ctrl-C)"


__all__ = ["Terminated", "exit_status", "how_stopped", "sigterm_interrupts"]
