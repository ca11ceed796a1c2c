"""Exit codes of ``hexapod-bench servo``: what happened, in one number.

Every exit path of a servo session ends in the same shutdown (halt the robot, wait for
its confirmation, write the final record), then returns one of these codes. They are
documented in ``docs/servo.md``; scripts and lab supervisors may rely on them.
"""

from __future__ import annotations

import enum
import signal


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
    """The exit code of a session ended by a signal: 128 + its number (shell convention).

    Args:
        signum: the signal's number (``signal.SIGINT`` gives 130, ``SIGTERM`` 143,
            ``SIGHUP`` 129).

    Returns:
        The exit code.

    Raises:
        ValueError: A signal the session does not handle (only SIGINT, SIGTERM, SIGHUP).
    """
    return ServoExit(128 + int(signal.Signals(signum)))


class SessionStop(Exception):  # noqa: N818 (a stop request, not an error)
    """A request to end a servo session: raised by a per-period check (a limit, the camera
    consistency check, the blind-camera timeout, ...) and turned by the session into the
    one shutdown (halt, confirmation, final record) and the exit code ``code``.

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
