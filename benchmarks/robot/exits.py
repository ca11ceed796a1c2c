"""How a servo session ends: its exit codes (:class:`ServoExit`, documented in
``docs/servo.md``; scripts and lab supervisors may rely on them), the stop request a
per-period check raises (:class:`SessionStop`) and the signals SIGINT, SIGTERM and SIGHUP
(:class:`SignalGuard`). Every way out goes through the session's one shutdown (halt the
robot, wait for its confirmation, write the final record), then returns one code.
"""

from __future__ import annotations

import enum
import signal
import sys
from collections.abc import Callable
from types import FrameType, TracebackType
from typing import Any

import numpy as np

#: The signals that end a session through its shutdown.
SESSION_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


class ServoExit(enum.IntEnum):
    """Exit codes of a servo session.

    Attributes:
        CONVERGED: the goal was reached (or ``--teach`` recorded it).
        INTERNAL: an unexpected error during motion; the robot was halted.
        REFUSED: bad input, refused before the robot moved.
        LIMIT: stopped by a limit the user or the robot file set (time, travel,
            steps, missed deadlines, the end of a recording).
        LINK: the link to the robot failed during motion.
        SAFETY: a safety stop (camera disagreeing with the encoders, a blind camera
            past its timeout).
        INTERRUPTED: SIGINT (Ctrl-C), 128 + 2.
        HANGUP: SIGHUP (a closed terminal, a dropped SSH session), 128 + 1.
        TERMINATED: SIGTERM (``systemctl stop``, ``docker stop``, an IDE's stop
            button), 128 + 15.
    """

    CONVERGED = 0
    INTERNAL = 1
    REFUSED = 2
    LIMIT = 3
    LINK = 4
    SAFETY = 5
    INTERRUPTED = 130
    HANGUP = 129
    TERMINATED = 143


def exit_for_signal(signum: int) -> ServoExit:
    """The exit code of a session ended by signal ``signum``: 128 + its number (SIGINT
    130, SIGTERM 143, SIGHUP 129).

    Raises:
        ValueError: A signal the session does not handle (only SIGINT, SIGTERM, SIGHUP).
    """
    return ServoExit(128 + int(signal.Signals(signum)))


class SessionStop(Exception):  # noqa: N818 (a stop request, not an error)
    """A request to end a servo session (raised by a limit or a per-period check), turned
    by the session into its one shutdown and the exit code ``code``.

    Args:
        code: The exit code the session ends with.
        reason: What happened, in words (printed and written to the final record).
    """

    code: ServoExit
    reason: str

    def __init__(self, code: ServoExit, reason: str) -> None:
        super().__init__(reason)
        self.code = ServoExit(code)
        self.reason = reason


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
        return SessionStop(exit_for_signal(signum), f"{signal.Signals(signum).name} received")

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        self.received.append(signal.Signals(signum).name)
        if self.shutting_down:
            self.say(f"{self.received[-1]} received during the shutdown: the robot is being "
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
        self.check()

    def check(self) -> None:
        """A pending signal (one that waited for this point) raises :class:`SessionStop`."""
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
