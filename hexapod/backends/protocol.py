"""The serial protocol of the hexapod's controller board (``docs/serial-protocol.md``).

ASCII lines ending in ``\\n``, 115200 8N1 by default. Every line in both directions is
``PAYLOAD*HH`` where ``HH`` is the XOR of the payload's bytes as two upper-case
hexadecimal digits (as in NMEA). Lengths are millimetres with three decimals, speeds
millimetres per second: this module is the only place where the code meets millimetres.

This module is shared by the host (:mod:`hexapod.backends.serial`) and the emulated
board (:mod:`hexapod.backends.emulator`), so that both speak exactly one protocol.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from hexapod.link_errors import (
    ChecksumError,
    CommandRejectedError,
    HaltedError,
    OutsideStrokeError,
    ProtocolError,
    RobotFaultError,
    ServoOffError,
    SpeedRangeError,
    WatchdogError,
)

#: Default baud rate of the link.
BAUDRATE = 115200
#: Watchdog period bounds and default [ms].
WATCHDOG_MIN_MS = 20
WATCHDOG_MAX_MS = 1000
WATCHDOG_DEFAULT_MS = 100
#: Longest line either side accepts, terminator included [bytes].
MAX_LINE = 256
#: Number of legs.
N_LEGS = 6


class ErrorCode(IntEnum):
    """Error codes of the board (``ERR <code> <text>``)."""

    NONE = 0
    SYNTAX = 1
    UNKNOWN_COMMAND = 2
    CHECKSUM = 3
    SERVO_OFF = 5
    OUTSIDE_STROKE = 7
    SPEED_RANGE = 8
    HALTED = 10
    WATCHDOG = 20


#: The short text the board sends with each code.
ERROR_TEXT: dict[ErrorCode, str] = {
    ErrorCode.NONE: "none",
    ErrorCode.SYNTAX: "syntax",
    ErrorCode.UNKNOWN_COMMAND: "unknown command",
    ErrorCode.CHECKSUM: "checksum",
    ErrorCode.SERVO_OFF: "servo off",
    ErrorCode.OUTSIDE_STROKE: "outside stroke",
    ErrorCode.SPEED_RANGE: "speed out of range",
    ErrorCode.HALTED: "halted by command",
    ErrorCode.WATCHDOG: "watchdog",
}

#: The exception raised on the host for each code.
FAULT_CLASSES: dict[int, type[RobotFaultError]] = {
    ErrorCode.SYNTAX: CommandRejectedError,
    ErrorCode.UNKNOWN_COMMAND: CommandRejectedError,
    ErrorCode.CHECKSUM: CommandRejectedError,
    ErrorCode.SERVO_OFF: ServoOffError,
    ErrorCode.OUTSIDE_STROKE: OutsideStrokeError,
    ErrorCode.SPEED_RANGE: SpeedRangeError,
    ErrorCode.HALTED: HaltedError,
    ErrorCode.WATCHDOG: WatchdogError,
}

_CHECKSUM_RE = re.compile(rb"^[0-9A-F]{2}$")


# ----------------------------------------------------------------------------- framing
def checksum(payload: str | bytes) -> str:
    """The XOR of the payload's bytes as two upper-case hexadecimal digits.

    Args:
        payload: The text before ``*`` (ASCII).

    Returns:
        For example ``checksum("POS?") == "73"`` (0x50 ^ 0x4F ^ 0x53 ^ 0x3F).
    """
    data = payload.encode("ascii") if isinstance(payload, str) else payload
    x = 0
    for b in data:
        x ^= b
    return f"{x:02X}"


def frame(payload: str) -> bytes:
    """The line for a payload: ``PAYLOAD*HH\\n`` as ASCII bytes.

    Raises:
        ProtocolError: The payload is not printable ASCII (a line break included) or
            is too long.
    """
    if not payload.isascii() or not payload.isprintable():
        raise ProtocolError(payload, "a payload must be printable ASCII")
    line = f"{payload}*{checksum(payload)}\n".encode("ascii")
    if len(line) > MAX_LINE:
        raise ProtocolError(payload, f"line longer than {MAX_LINE} bytes")
    return line


def unframe(line: bytes | str, command: str | None = None) -> str:
    """Check a received line's checksum and return its payload.

    A trailing ``\\n`` (and ``\\r``) is ignored. The checksum is the two upper-case hex
    digits after the LAST ``*``.

    Args:
        line: The received line.
        command: The command this line answers, for the error message (host side).

    Returns:
        The payload (text before ``*``).

    Raises:
        ChecksumError: The checksum is missing or does not match.
        ProtocolError: The line is not ASCII.
    """
    data = line.encode("latin-1") if isinstance(line, str) else bytes(line)
    data = data.rstrip(b"\r\n")
    star = data.rfind(b"*")
    if star < 0:
        raise ChecksumError(line, None, None, command)
    payload, given = data[:star], data[star + 1 :]
    expected = checksum(payload)
    if not _CHECKSUM_RE.match(given) or given.decode("ascii") != expected:
        raise ChecksumError(line, expected, given.decode("latin-1"), command)
    try:
        text = payload.decode("ascii")
    except UnicodeDecodeError:
        raise ProtocolError(line, "payload is not ASCII", command) from None
    if not text.isprintable():
        raise ProtocolError(line, "payload is not printable", command)
    return text


# ----------------------------------------------------------------------------- numbers
def format_mm(value_m: float) -> str:
    """A length [m] as protocol millimetres with three decimals (``0.4155 -> "415.500"``)."""
    return f"{value_m * 1000.0:.3f}"


def format_lengths(lengths_m: np.ndarray) -> str:
    """Six lengths [m] as six space-separated millimetre fields."""
    q = np.asarray(lengths_m, dtype=float).reshape(-1)
    if q.shape != (N_LEGS,):
        raise ProtocolError(str(q), f"expected {N_LEGS} lengths")
    return " ".join(format_mm(x) for x in q)


#: A number of the protocol: decimal digits, an optional sign and fraction (Python's own
#: syntax, ``4_15``, ``1e3``, ``inf``, was accepted by ``float``).
_NUMBER = re.compile(r"[+-]?\d+(?:\.\d+)?")


def parse_number(token: str) -> float:
    """A decimal number (``"415.500"``, ``"-2"``); raises ValueError otherwise."""
    if not _NUMBER.fullmatch(token):
        raise ValueError(f"not a decimal number: {token!r}")
    return float(token)


def mm_to_m(value_mm: float) -> float:
    """Millimetres to metres (division, so that ``485.000 mm`` is exactly ``0.485``)."""
    return value_mm / 1000.0


# ----------------------------------------------------------------------------- commands
def mov(lengths_m: np.ndarray) -> str:
    """The payload ``MOV l1 ... l6`` for setpoints [m]."""
    return "MOV " + format_lengths(lengths_m)


def vel(speed_m_s: float) -> str:
    """The payload ``VEL <v>`` for a leg speed limit [m/s]."""
    return f"VEL {format_mm(speed_m_s)}"


def wdt(period_s: float) -> str:
    """The payload ``WDT <ms>`` for a watchdog period [s] (rounded to the millisecond)."""
    return f"WDT {round(period_s * 1000.0)}"


# ----------------------------------------------------------------------------- replies
@dataclass(frozen=True)
class Status:
    """The reply to ``STA?``.

    Attributes:
        servo: The servo is on.
        moving: At least one leg is not at its setpoint.
        error: The pending error code (what ``ERR?`` would return).
        watchdog: The watchdog has tripped and is latched.
    """

    servo: bool
    moving: bool
    error: int
    watchdog: bool


@dataclass(frozen=True)
class Limits:
    """The reply to ``LIM?``, in SI units.

    Attributes:
        stroke: (q_min, q_max) [m].
        max_speed: Leg speed limit [m/s].
    """

    stroke: tuple[float, float]
    max_speed: float


def split_reply(payload: str, expected: str, command: str | None = None) -> list[str]:
    """Split a reply payload, checking its keyword.

    Args:
        payload: The unframed reply.
        expected: Its expected first word (``"POS"``, ``"OK"``...).
        command: The command it answers (for the error message).

    Returns:
        The words after the keyword.

    Raises:
        RobotFaultError: The reply is ``ERR <code> <text>`` with a non-zero code
            (and ``expected`` is not ``"ERR"``): the subclass for that code.
        ProtocolError: Another keyword (a stale or garbled reply).
    """
    words = payload.split()
    if not words:
        raise ProtocolError(payload, "empty reply", command)
    if words[0] == "ERR" and expected != "ERR":
        code, text = parse_err(payload, command)
        raise fault(code, text, command)
    if words[0] != expected:
        raise ProtocolError(payload, f"expected a '{expected}' reply", command)
    return words[1:]


def parse_err(payload: str, command: str | None = None) -> tuple[int, str]:
    """Parse ``ERR <code> <text>`` into (code, text)."""
    words = payload.split(maxsplit=2)
    if len(words) < 2 or words[0] != "ERR":
        raise ProtocolError(payload, "expected 'ERR <code> <text>'", command)
    try:
        code = int(words[1])
    except ValueError:
        raise ProtocolError(payload, "error code is not an integer", command) from None
    if code < 0:
        raise ProtocolError(payload, "negative error code", command)
    return code, words[2] if len(words) > 2 else ""


def fault(code: int, text: str, command: str | None = None) -> RobotFaultError:
    """The typed exception for an error code (:class:`RobotFaultError` for unknown codes)."""
    return FAULT_CLASSES.get(code, RobotFaultError)(code, text, command)


def parse_ok(payload: str, command: str | None = None) -> None:
    """Check that a reply is ``OK`` (raising the typed fault for ``ERR``)."""
    if split_reply(payload, "OK", command):
        raise ProtocolError(payload, "'OK' takes no argument", command)


def parse_pos(payload: str, command: str | None = "POS?") -> np.ndarray:
    """Parse ``POS l1 ... l6`` into (6,) lengths [m]."""
    words = split_reply(payload, "POS", command)
    if len(words) != N_LEGS:
        raise ProtocolError(payload, f"expected {N_LEGS} lengths", command)
    try:
        return np.array([mm_to_m(parse_number(w)) for w in words])
    except ValueError:
        raise ProtocolError(payload, "a length is not a number", command) from None


def parse_sta(payload: str, command: str | None = "STA?") -> Status:
    """Parse ``STA servo=<0/1> moving=<0/1> error=<code> watchdog=<0/1>``."""
    words = split_reply(payload, "STA", command)
    fields: dict[str, int] = {}
    try:
        for w in words:
            key, value = w.split("=", 1)
            fields[key] = int(value)
    except ValueError:
        raise ProtocolError(payload, "expected key=integer fields", command) from None
    keys = ("servo", "moving", "error", "watchdog")
    if sorted(fields) != sorted(keys) or any(fields[k] not in (0, 1) for k in keys if k != "error"):
        raise ProtocolError(payload, f"expected the fields {', '.join(keys)}", command)
    return Status(bool(fields["servo"]), bool(fields["moving"]), fields["error"],
                  bool(fields["watchdog"]))


def parse_lim(payload: str, command: str | None = "LIM?") -> Limits:
    """Parse ``LIM <qmin> <qmax> <vmax>`` (mm, mm/s) into SI :class:`Limits`."""
    words = split_reply(payload, "LIM", command)
    if len(words) != 3:
        raise ProtocolError(payload, "expected 'LIM <qmin> <qmax> <vmax>'", command)
    try:
        lo, hi, v = (mm_to_m(parse_number(w)) for w in words)
    except ValueError:
        raise ProtocolError(payload, "a limit is not a number", command) from None
    if not 0 < lo < hi or v <= 0:
        raise ProtocolError(payload, "inconsistent limits", command)
    return Limits((lo, hi), v)


def parse_idn(payload: str, command: str | None = "*IDN?") -> str:
    """Parse ``IDN <text>`` into the identity text."""
    split_reply(payload, "IDN", command)
    return payload[3:].strip()
