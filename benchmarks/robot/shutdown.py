"""The signals of a servo session: SIGINT, SIGTERM and SIGHUP all end in its one shutdown
(:class:`SignalGuard`).
"""

from __future__ import annotations

import signal
import sys
from collections.abc import Callable
from types import FrameType, TracebackType
from typing import Any

import numpy as np

from benchmarks.robot.exits import SessionStop, exit_for_signal

#: The signals that end a session through its shutdown.
SESSION_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


def signal_name(signum: int) -> str:
    """A signal's name (``SIGHUP``)."""
    return signal.Signals(signum).name


class SignalGuard:
    """SIGINT, SIGTERM and SIGHUP turned into a :class:`SessionStop` with their exit code
    (130, 143, 129), for the duration of a ``with`` block (the previous handlers are
    restored after). Outside the loop a signal stops the session at once; inside it the
    first signal is taken at the next period (no exchange with the robot is cut) and a
    second one at once; during the shutdown signals are only noted (never skip the halt).

    Args:
        say: Shows a line to the user (during the shutdown).

    Attributes:
        in_loop: The loop polls :meth:`__call__` every period (the first signal waits
            for it).
        shutting_down: The shutdown has begun: signals are only noted.
        received: Every signal received, in order (names).
    """

    def __init__(self, say: Callable[[str], None] | None = None) -> None:
        self.say = say or (lambda text: print(text, file=sys.stderr, flush=True))
        self.in_loop = False
        self.shutting_down = False
        self.received: list[str] = []
        self.pending: int | None = None
        self._previous: dict[int, Any] = {}

    def _stop(self, signum: int) -> SessionStop:
        return SessionStop(exit_for_signal(signum), f"{signal_name(signum)} received")

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        self.received.append(signal_name(signum))
        if self.shutting_down:
            self.say(f"{signal_name(signum)} received during the shutdown: the robot is being "
                     "halted first")
            return
        if self.in_loop and self.pending is None:
            self.pending = signum  # taken at the next period
            return
        self.pending = signum
        raise self._stop(signum)

    def __call__(self, step: int, lengths: np.ndarray, features: Any) -> None:
        """A per-period check (:class:`~benchmarks.robot.loop.PeriodCheck`): a pending
        signal ends the session (:class:`SessionStop`)."""
        if self.pending is not None and not self.shutting_down:
            raise self._stop(self.pending)

    def __enter__(self) -> SignalGuard:
        for sig in SESSION_SIGNALS:
            self._previous[sig] = signal.signal(sig, self._handle)
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        for sig, previous in self._previous.items():
            signal.signal(sig, previous)
        self._previous.clear()
