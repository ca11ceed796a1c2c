"""The errors of the link to a robot controller: the connection and its timeouts
(serial, GCS), the protocol's replies, the controller's faults and implausible readings
(all :class:`~hexapod.exceptions.BackendError`; the project's other errors are in
:mod:`hexapod.exceptions`)."""

from __future__ import annotations

from hexapod.exceptions import BackendError


class LinkError(BackendError):
    """The link to a robot controller failed (connection, port, timeout, disconnection).

    Attributes:
        url: The controller's address (device path, pyserial URL or ``tcp://HOST:PORT``).
        problem: What went wrong.
        command: The command being exchanged, if any.
    """

    #: How the message names the controller, before its address.
    device = ""

    def __init__(self, url: str, problem: str, command: str | None = None) -> None:
        self.url = url
        self.problem = problem
        self.command = command
        # a pipelined exchange ('POS?\nERR?') on one line, as it was sent: 'POS?; ERR?'
        during = f" during '{'; '.join(command.splitlines())}'" if command else ""
        super().__init__(f"{self.device}{url}: {problem}{during}")


def _silence(answer: str, timeout: float, received: bytes) -> str:
    """The problem of a timeout: no ``answer`` within ``timeout`` [s], and what came."""
    if received:  # bytes came, no line end: not silence (a baud rate, a device?)
        return (f"no complete {answer} within {timeout * 1e3:.1f} ms (received {received!r}, "
                "no line end)")
    return f"no {answer} within {timeout * 1e3:.1f} ms, nothing received"


class SerialLinkError(LinkError):
    """The serial link to a robot controller failed (port, timeout, disconnection).

    Attributes:
        url: The port (device path or pyserial URL).
    """


class SerialTimeoutError(SerialLinkError):
    """The robot controller did not answer within the timeout (a silent device).

    Attributes:
        timeout: The time waited for the reply [s].
        received: The bytes received before the timeout (an incomplete line).
    """

    def __init__(self, url: str, command: str, timeout: float, received: bytes = b"") -> None:
        self.timeout = timeout
        self.received = received
        super().__init__(url, _silence("reply", timeout, received), command)


class SerialDisconnectedError(SerialLinkError):
    """The port went away (cable pulled, emulator or socket closed)."""


class ProtocolError(BackendError):
    """A line that does not follow the serial protocol (garbled, unparsable, unexpected).

    Attributes:
        line: The offending line, as received.
        problem: What is wrong with it.
        command: The command it answered, if known.
    """

    def __init__(self, line: bytes | str, problem: str, command: str | None = None) -> None:
        self.line = line
        self.problem = problem
        self.command = command
        after = f" (reply to '{command}')" if command else ""
        super().__init__(f"{problem}: {line!r}{after}")


class ChecksumError(ProtocolError):
    """A line whose ``*HH`` checksum is missing or wrong.

    Attributes:
        expected: The checksum of the payload (two upper-case hex digits), if any payload.
        got: The checksum the line carries (None when missing).
    """

    def __init__(
        self, line: bytes | str, expected: str | None, got: str | None, command: str | None = None
    ) -> None:
        self.expected = expected
        self.got = got
        problem = (
            "missing checksum" if got is None else f"bad checksum {got!r} (expected {expected!r})"
        )
        super().__init__(line, problem, command)


class RobotFaultError(BackendError):
    """The robot controller answered ``ERR <code> <text>``.

    Attributes:
        code: The protocol error code (see :class:`hexapod.backends.protocol.ErrorCode`).
        text: The controller's text.
        command: The command that was refused, if known.
    """

    def __init__(self, code: int, text: str, command: str | None = None) -> None:
        self.code = int(code)
        self.text = text
        self.command = command
        after = f" in reply to '{command}'" if command else ""
        super().__init__(f"robot error {self.code} ({text}){after}")


class ImplausibleReadingError(BackendError):
    """A leg length the controller reported cannot be where the leg is: outside the
    board's stroke, or off the way between where the leg was and the setpoint it was sent
    (a glitching encoder, a corrupted reading). A setpoint computed from it would jump.

    Attributes:
        url: The controller's address.
        leg: Index of the leg (0-based).
        value: The length reported [m].
        low: The lowest length it could have [m].
        high: The highest length it could have [m].
    """

    def __init__(self, url: str, leg: int, value: float, low: float, high: float,
                 why: str) -> None:
        self.url = url
        self.leg = leg
        self.value = value
        self.low = low
        self.high = high
        super().__init__(f"{url}: implausible position reading: leg {leg} at "
                         f"{value * 1e3:.3f} mm, where it can only be in [{low * 1e3:.3f}, "
                         f"{high * 1e3:.3f}] mm ({why}); nothing was sent from it")


class CommandRejectedError(RobotFaultError):
    """The controller rejected a command it could not read (syntax 1, unknown 2, checksum 3)."""


class ServoOffError(RobotFaultError):
    """A motion command while the servo is off (code 5)."""


class OutsideStrokeError(RobotFaultError):
    """A setpoint outside the stroke (code 7): nothing moved."""


class SpeedRangeError(RobotFaultError):
    """A speed limit out of range (code 8)."""


class HaltedError(RobotFaultError):
    """The robot was halted by a command (code 10)."""


class WatchdogError(RobotFaultError):
    """The controller's watchdog tripped (code 20): no valid MOV within its period; the
    robot holds its position and refuses MOV until the host reads ``ERR?``."""


class GcsLinkError(LinkError):
    """The link to a PI GCS controller failed (connection, timeout, disconnection).

    Attributes:
        url: The controller's address (``tcp://HOST:PORT`` or a pyserial URL).
    """

    device = "GCS controller "


class GcsTimeoutError(GcsLinkError):
    """A GCS controller did not answer a query within the timeout.

    Attributes:
        timeout: The time waited for the answer [s].
        received: The bytes received before the timeout (an incomplete answer).
    """

    def __init__(self, url: str, command: str, timeout: float, received: bytes = b"") -> None:
        self.timeout = timeout
        self.received = received
        super().__init__(url, _silence("answer", timeout, received), command)


class GcsDisconnectedError(GcsLinkError):
    """The connection to a GCS controller was closed (socket closed, port gone)."""


class GcsReplyError(ProtocolError):
    """A GCS controller's answer that does not parse as the answer to the command sent."""


class GcsControllerError(RobotFaultError):
    """A GCS controller reported an error: ``ERR?`` answered a non-zero code.

    Attributes:
        code: The official GCS error number (``ERR?``).
        text: PI's text for that number (:data:`hexapod.backends.gcs_protocol.ERROR_TEXT`).
        command: The command after which ``ERR?`` reported it.
        url: The controller's address.
    """

    def __init__(self, code: int, text: str, command: str | None = None,
                 url: str | None = None) -> None:
        super().__init__(code, text, command)
        self.url = url
        where = f"GCS controller {url}: " if url else "GCS controller: "
        after = f" after '{command}'" if command else ""
        self.args = (f"{where}error {self.code} ({text}){after}",)


class GcsOutOfLimitsError(GcsControllerError):
    """GCS error 7 (position out of limits): the target pose is not reachable by the
    controller's own model; the controller refused it and nothing moved."""


class GcsStoppedError(GcsControllerError):
    """GCS error 10: the controller was stopped by command (``HLT``, ``STP``)."""


__all__ = [
    "ChecksumError", "CommandRejectedError", "GcsControllerError", "GcsDisconnectedError",
    "GcsLinkError", "GcsOutOfLimitsError", "GcsReplyError", "GcsStoppedError",
    "GcsTimeoutError", "HaltedError", "ImplausibleReadingError", "LinkError",
    "OutsideStrokeError", "ProtocolError", "RobotFaultError", "SerialDisconnectedError",
    "SerialLinkError", "SerialTimeoutError", "ServoOffError", "SpeedRangeError",
    "WatchdogError",
]
