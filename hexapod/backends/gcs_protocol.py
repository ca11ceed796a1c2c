"""PI's GCS command set, the subset a hexapod controller (C-887 family) needs.

Shared by the host (:mod:`hexapod.backends.gcs`) and the emulated controller
(:mod:`hexapod.backends.gcs_emulator`), so that both speak exactly one protocol. The
facts below were checked against PI's own client library (pipython, its
``gcsmessages`` and ``gcserror`` modules) unless marked as an assumption; see
``docs/backends.md`` (section GCS) for the list of what is verified and what is not.

Framing:

- a command is one ASCII line ending in LF: ``MOV X 1.5 Y 0 Z 0``, ``POS?``;
- only queries (``...?``) are answered. An answer is one or more lines; every line
  but the last ends with a space before its LF (``X=1.500000 \\n`` ...
  ``W=0.000000\\n``): an LF *not* preceded by a space ends the answer;
- a set command that succeeds answers nothing, and so does a command that fails: the
  controller stores the error number, and ``ERR?`` returns it (and clears it). A
  client sends ``ERR?`` after its commands (pipython does, by default).

Units on the wire: X, Y, Z in millimetres, U, V, W in degrees; this module and the
pose conversion (:mod:`hexapod.backends.gcs_pose`) are where the code meets them.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Mapping, Sequence
from enum import IntEnum

from hexapod.link_errors import (
    GcsControllerError,
    GcsOutOfLimitsError,
    GcsReplyError,
    GcsStoppedError,
)

#: The line terminator of commands and answers.
TERMINATOR = b"\n"
#: The Cartesian axes of a hexapod: translations X, Y, Z [mm], rotations U, V, W [deg].
AXES: tuple[str, ...] = ("X", "Y", "Z", "U", "V", "W")
#: The axes of the pivot point (``SPI``): R, S, T [mm], along X, Y, Z.
PIVOT_AXES: tuple[str, ...] = ("R", "S", "T")
#: Decimals of the numbers the emulated controller answers with (1 nm, 1 micro-degree).
ANSWER_DECIMALS = 6
#: Decimals of the numbers the host sends (far below any hexapod's resolution).
COMMAND_DECIMALS = 9
#: Longest command line the emulated controller accepts, terminator included [bytes].
MAX_LINE = 1024


class GcsError(IntEnum):
    """The GCS error numbers used here (PI's controller error numbers, ``ERR?``)."""

    NO_ERROR = 0
    PARAM_SYNTAX = 1
    UNKNOWN_COMMAND = 2
    COMMAND_TOO_LONG = 3
    POS_OUT_OF_LIMITS = 7
    VEL_OUT_OF_LIMITS = 8
    SET_PIVOT_NOT_POSSIBLE = 9
    STOP = 10
    INVALID_AXIS_IDENTIFIER = 15
    PARAM_OUT_OF_RANGE = 17
    DOUBLE_AXIS = 22


#: PI's official texts of these numbers (as in pipython's ``gcserror``).
ERROR_TEXT: dict[int, str] = {
    GcsError.NO_ERROR: "No error",
    GcsError.PARAM_SYNTAX: "Parameter syntax error",
    GcsError.UNKNOWN_COMMAND: "Unknown command",
    GcsError.COMMAND_TOO_LONG: "Command length out of limits or command buffer overrun",
    GcsError.POS_OUT_OF_LIMITS: "Position out of limits",
    GcsError.VEL_OUT_OF_LIMITS: "Velocity out of limits",
    GcsError.SET_PIVOT_NOT_POSSIBLE: "Attempt to set pivot point while U,V and W not all 0",
    GcsError.STOP: "Controller was stopped by command",
    GcsError.INVALID_AXIS_IDENTIFIER: "Invalid axis identifier",
    GcsError.PARAM_OUT_OF_RANGE: "Parameter out of range",
    GcsError.DOUBLE_AXIS: "Axis identifier specified more than once",
}


def error_text(code: int) -> str:
    """PI's text of a GCS error number (a generic text for a number not listed here)."""
    return ERROR_TEXT.get(int(code), f"GCS error {int(code)} (see PI's error list)")


def controller_error(code: int, command: str | None = None,
                     url: str | None = None) -> GcsControllerError:
    """The exception for a non-zero ``ERR?`` answer (typed for 7 and 10)."""
    cls: type[GcsControllerError] = GcsControllerError
    if code == GcsError.POS_OUT_OF_LIMITS:
        cls = GcsOutOfLimitsError
    elif code == GcsError.STOP:
        cls = GcsStoppedError
    return cls(int(code), error_text(code), command, url)


# ============================================================================ numbers
def format_number(value: float, decimals: int = COMMAND_DECIMALS) -> str:
    """A number as GCS text: fixed point, trailing zeros dropped, never ``-0``.

    Raises:
        ValueError: A NaN or an infinity (they must never reach a controller).
    """
    x = float(value)
    if not math.isfinite(x):
        raise ValueError(f"not a finite number: {value!r}")
    text = f"{x:.{decimals}f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def format_answer_number(value: float) -> str:
    """A number as the controller answers it (``1.500000``: :data:`ANSWER_DECIMALS`)."""
    text = f"{float(value):.{ANSWER_DECIMALS}f}"
    return text[1:] if text.startswith("-") and float(text) == 0.0 else text


_NUMBER = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$")


def parse_number(text: str) -> float:
    """A GCS number (decimal, optional exponent).

    Raises:
        ValueError: Not a finite decimal number (``nan``, ``inf``, ``0x10`` are refused).
    """
    if not _NUMBER.match(text):
        raise ValueError(f"not a number: {text!r}")
    return float(text)


# ============================================================================ commands
def command(name: str, values: Mapping[str, float] | None = None) -> str:
    """A command line (without its LF): ``command("MOV", {"X": 1.5})`` is ``MOV X 1.5``."""
    if not values:
        return name
    return name + " " + " ".join(f"{a} {format_number(v)}" for a, v in values.items())


def encode(*commands: str) -> bytes:
    """Commands as bytes on the wire, each ending with LF (several: pipelined)."""
    return b"".join(c.encode("ascii") + TERMINATOR for c in commands)


def split_command(line: str) -> tuple[str, list[str]]:
    """The command name and its arguments (``"MOV X 1 Y 2"`` -> ``("MOV", [...])``)."""
    words = line.split()
    if not words:
        return "", []
    return words[0], words[1:]


class CommandSyntaxError(ValueError):
    """A command the controller cannot read; ``code`` is the GCS error it stores."""

    def __init__(self, code: GcsError, detail: str) -> None:
        super().__init__(f"{int(code)} {ERROR_TEXT[code]}: {detail}")
        self.code = code


def parse_axis_values(args: Sequence[str], allowed: Iterable[str] = AXES) -> dict[str, float]:
    """``X 1.5 Y -2`` -> ``{"X": 1.5, "Y": -2.0}`` (the arguments of MOV, VMO?, SPI).

    Raises:
        CommandSyntaxError: No pair, an odd count or a bad number (1), an unknown axis
            (15), an axis given twice (22).
    """
    allowed = tuple(allowed)
    if not args or len(args) % 2:
        raise CommandSyntaxError(GcsError.PARAM_SYNTAX, "expected AXIS VALUE pairs")
    out: dict[str, float] = {}
    for axis, value in zip(args[0::2], args[1::2], strict=True):
        if axis not in allowed:
            raise CommandSyntaxError(GcsError.INVALID_AXIS_IDENTIFIER,
                                     f"{axis!r} is not one of {' '.join(allowed)}")
        if axis in out:
            raise CommandSyntaxError(GcsError.DOUBLE_AXIS, axis)
        try:
            out[axis] = parse_number(value)
        except ValueError:
            raise CommandSyntaxError(GcsError.PARAM_SYNTAX, f"{value!r} is not a number"
                                     ) from None
    return out


def parse_axis_list(args: Sequence[str], allowed: Iterable[str] = AXES) -> list[str]:
    """The axes of a query (``POS? X Y``; none: all of ``allowed``).

    Raises:
        CommandSyntaxError: An unknown axis (15).
    """
    allowed = tuple(allowed)
    for a in args:
        if a not in allowed:
            raise CommandSyntaxError(GcsError.INVALID_AXIS_IDENTIFIER,
                                     f"{a!r} is not one of {' '.join(allowed)}")
    return list(args) if args else list(allowed)


# ============================================================================ answers
def frame_answer(lines: Sequence[str]) -> bytes:
    """An answer on the wire: every line but the last ends with ``" \\n"``, the last
    with ``"\\n"`` (no lines: nothing is sent)."""
    if not lines:
        return b""
    return (" \n".join(lines) + "\n").encode("ascii")


def answer_end(buffer: bytes | bytearray) -> int:
    """Where the first complete answer in ``buffer`` ends (index after its final LF), or
    -1: the first LF that does not follow a space ends an answer."""
    start = 0
    while True:
        i = buffer.find(b"\n", start)
        if i < 0:
            return -1
        if i == 0 or buffer[i - 1 : i] != b" ":
            return i + 1
        start = i + 1


def answer_lines(answer: bytes | str) -> list[str]:
    """The lines of one complete answer, without their LF and continuation spaces.

    Raises:
        GcsReplyError: Not ASCII.
    """
    if isinstance(answer, bytes | bytearray):
        try:
            answer = bytes(answer).decode("ascii")
        except UnicodeDecodeError:
            raise GcsReplyError(answer, "not ASCII") from None
    return [ln.rstrip(" \r") for ln in answer.rstrip("\n").split("\n")]


def parse_axis_answer(answer: bytes | str, axes: Sequence[str],
                      command_text: str | None = None) -> dict[str, float]:
    """``X=1.5 \\nY=2\\n`` -> ``{"X": 1.5, "Y": 2.0}``: exactly ``axes``, in any order.

    Raises:
        GcsReplyError: A line that is not ``AXIS=NUMBER``, a missing or unexpected axis.
    """
    out: dict[str, float] = {}
    for line in answer_lines(answer):
        key, sep, value = line.partition("=")
        key, value = key.strip(), value.strip()
        if not sep or key not in axes or key in out:
            raise GcsReplyError(answer, f"expected one line AXIS=VALUE for each of "
                                        f"{' '.join(axes)}, got {line!r}", command_text)
        try:
            out[key] = parse_number(value)
        except ValueError:
            raise GcsReplyError(answer, f"{value!r} is not a number", command_text) from None
    if len(out) != len(axes):
        missing = [a for a in axes if a not in out]
        raise GcsReplyError(answer, f"no value for {' '.join(missing)}", command_text)
    return out


def parse_int_answer(answer: bytes | str, command_text: str | None = None) -> int:
    """A one-line integer answer (``ERR?``, ``VMO?``).

    Raises:
        GcsReplyError: Not one line holding an integer.
    """
    lines = answer_lines(answer)
    if len(lines) != 1 or not re.fullmatch(r"[+-]?\d+", lines[0].strip()):
        raise GcsReplyError(answer, "expected one integer", command_text)
    return int(lines[0])


def parse_float_answer(answer: bytes | str, command_text: str | None = None) -> float:
    """A one-line number answer (``VLS?``).

    Raises:
        GcsReplyError: Not one line holding a number.
    """
    lines = answer_lines(answer)
    try:
        if len(lines) != 1:
            raise ValueError
        return parse_number(lines[0].strip())
    except ValueError:
        raise GcsReplyError(answer, "expected one number", command_text) from None
