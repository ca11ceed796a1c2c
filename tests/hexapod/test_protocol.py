"""The serial protocol: framing, checksums, reply parsing, error codes and their exceptions."""

from __future__ import annotations

import functools
import operator

import numpy as np
import pytest

from hexapod.backends import protocol
from hexapod.backends.protocol import ErrorCode
from hexapod.exceptions import BackendError
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


def xor_hex(text: str) -> str:
    """An independent checksum: fold XOR over the bytes, format by hand."""
    x = functools.reduce(operator.xor, text.encode("ascii"), 0)
    return "0123456789ABCDEF"[x >> 4] + "0123456789ABCDEF"[x & 15]


@pytest.mark.parametrize("payload", ["POS?", "*IDN?", "OK", "SVO 1", "ERR 0 none",
                                     "MOV 415.500 415.500 415.500 415.500 415.500 415.500",
                                     "STA servo=1 moving=0 error=0 watchdog=0", ""])
def test_checksum_is_xor_of_payload(payload: str) -> None:
    assert protocol.checksum(payload) == xor_hex(payload)
    line = protocol.frame(payload)
    assert line == f"{payload}*{xor_hex(payload)}\n".encode()
    assert protocol.unframe(line) == payload
    assert protocol.unframe(line.rstrip(b"\n") + b"\r\n") == payload


def test_known_checksums() -> None:
    # worked by hand: P ^ O ^ S ^ ? = 0x50 ^ 0x4F ^ 0x53 ^ 0x3F = 0x73
    assert protocol.frame("POS?") == b"POS?*73\n"
    assert protocol.frame("OK") == b"OK*04\n"  # 0x4F ^ 0x4B
    assert protocol.frame("*IDN?") == b"*IDN?*56\n"  # a '*' inside the payload is fine


def test_every_single_byte_corruption_is_detected() -> None:
    line = protocol.frame("POS 415.500 400.000 380.125 470.000 350.001 484.999")
    body = line.rstrip(b"\n")
    for i in range(len(body)):
        for c in range(0x20, 0x7F):
            if c == body[i]:
                continue
            bad = body[:i] + bytes([c]) + body[i + 1 :] + b"\n"
            with pytest.raises(ProtocolError):
                protocol.unframe(bad)


@pytest.mark.parametrize("line,got", [
    (b"POS?\n", None),              # missing
    (b"POS?*\n", ""),               # empty
    (b"POS?*7\n", "7"),             # one digit
    (b"POS?*073\n", "073"),         # three digits
    (b"POS?*74\n", "74"),           # wrong
    (b"OK*04 \n", "04 "),           # trailing junk
])
def test_bad_or_missing_checksum(line: bytes, got: str | None) -> None:
    with pytest.raises(ChecksumError) as info:
        protocol.unframe(line, command="POS?")
    assert info.value.got == got
    assert info.value.command == "POS?"
    assert isinstance(info.value, BackendError)


def test_lower_case_checksum_is_rejected() -> None:
    # "upper-case hex digits": the board compares them as text
    line = protocol.frame("MOV 415.500 415.500 415.500 415.500 415.500 490.000")
    assert line.endswith(b"*5C\n")
    with pytest.raises(ChecksumError):
        protocol.unframe(line.replace(b"*5C", b"*5c"))


def test_non_ascii_payload() -> None:
    payload = "POS é".encode("latin-1")
    with pytest.raises(ProtocolError):
        protocol.unframe(payload + b"*" + protocol.checksum(payload).encode() + b"\n")
    with pytest.raises(ProtocolError):
        protocol.frame("OK\n")


def test_millimetres_with_three_decimals() -> None:
    assert protocol.format_mm(0.4155) == "415.500"
    assert protocol.format_mm(0.0000004) == "0.000"
    assert protocol.mov(np.array([0.345, 0.485, 0.4, 0.41, 0.42, 0.4300004])) == \
        "MOV 345.000 485.000 400.000 410.000 420.000 430.000"
    assert protocol.vel(0.05) == "VEL 50.000"
    assert protocol.wdt(0.1) == "WDT 100"
    # mm -> m by division: the stroke limits come back exactly
    assert protocol.mm_to_m(485.0) == 0.485
    assert protocol.mm_to_m(345.0) == 0.345
    with pytest.raises(ProtocolError):
        protocol.format_lengths(np.zeros(5))


def test_parse_replies() -> None:
    q = protocol.parse_pos("POS 415.500 400.000 380.125 470.000 350.001 484.999")
    np.testing.assert_array_equal(q * 1000.0, [415.5, 400.0, 380.125, 470.0, 350.001, 484.999])
    st = protocol.parse_sta("STA servo=1 moving=0 error=20 watchdog=1")
    assert st == protocol.Status(servo=True, moving=False, error=20, watchdog=True)
    lim = protocol.parse_lim("LIM 345.000 485.000 50.000")
    assert lim.stroke == (0.345, 0.485) and lim.max_speed == 0.05
    assert protocol.parse_idn("IDN hexapod-emulator 0.1.0 deltalab") == \
        "hexapod-emulator 0.1.0 deltalab"
    assert protocol.parse_err("ERR 7 outside stroke: l6=490.000") == \
        (7, "outside stroke: l6=490.000")
    assert protocol.parse_err("ERR 0 none") == (0, "none")
    protocol.parse_ok("OK")


@pytest.mark.parametrize("parse,payload", [
    (protocol.parse_pos, "POS 1 2 3 4 5"),
    (protocol.parse_pos, "POS 1 2 3 4 5 x"),
    (protocol.parse_pos, "POS 1 2 3 4 5 nan"),
    (protocol.parse_pos, "OK"),
    (protocol.parse_pos, ""),
    (protocol.parse_sta, "STA servo=1 moving=0 error=0"),
    (protocol.parse_sta, "STA servo=2 moving=0 error=0 watchdog=0"),
    (protocol.parse_sta, "STA servo=1 moving=0 error=x watchdog=0"),
    (protocol.parse_lim, "LIM 485.000 345.000 50.000"),
    (protocol.parse_lim, "LIM 345.000 485.000"),
    (protocol.parse_idn, "POS 1 2 3 4 5 6"),
    (protocol.parse_ok, "OK 1"),
    (protocol.parse_err, "ERR x none"),
    (protocol.parse_err, "OK"),
])
def test_unparsable_replies(parse: object, payload: str) -> None:
    with pytest.raises(ProtocolError):
        parse(payload)  # type: ignore[operator]


def test_error_codes_are_the_issue_list() -> None:
    assert {int(c): c.name for c in ErrorCode} == {
        0: "NONE", 1: "SYNTAX", 2: "UNKNOWN_COMMAND", 3: "CHECKSUM", 5: "SERVO_OFF",
        7: "OUTSIDE_STROKE", 8: "SPEED_RANGE", 10: "HALTED", 20: "WATCHDOG"}
    assert set(protocol.ERROR_TEXT) == set(ErrorCode)


@pytest.mark.parametrize("code,cls", [
    (1, CommandRejectedError), (2, CommandRejectedError), (3, CommandRejectedError),
    (5, ServoOffError), (7, OutsideStrokeError), (8, SpeedRangeError), (10, HaltedError),
    (20, WatchdogError), (99, RobotFaultError),
])
def test_error_reply_raises_typed_fault(code: int, cls: type[RobotFaultError]) -> None:
    with pytest.raises(cls) as info:
        protocol.parse_ok(f"ERR {code} some text", "MOV 1 2 3 4 5 6")
    assert type(info.value) is cls
    assert info.value.code == code
    assert info.value.text == "some text"
    assert info.value.command == "MOV 1 2 3 4 5 6"
    assert "some text" in str(info.value)
    # the same on any query that expects another keyword
    with pytest.raises(cls):
        protocol.parse_pos(f"ERR {code} x")


def test_documented_exchanges_have_correct_checksums() -> None:
    """Every example line of docs/serial-protocol.md is well framed, except the commands
    the board answers with ``ERR 3 checksum`` (the doc's examples of bad lines; an
    ``ERR?`` answered 3 is reporting an earlier one)."""
    from pathlib import Path

    doc = Path(__file__).resolve().parents[2] / "docs" / "serial-protocol.md"
    lines = [ln for ln in doc.read_text().splitlines() if ln.startswith(("> ", "< "))]
    pairs = list(zip(lines[::2], lines[1::2], strict=True))
    assert len(pairs) >= 30
    bad = 0
    for cmd, reply in pairs:
        assert cmd.startswith("> ") and reply.startswith("< ")
        payload = protocol.unframe(reply[2:] + "\n")
        if payload == "ERR 3 checksum" and not cmd.startswith("> ERR?*"):
            bad += 1
            with pytest.raises(ChecksumError):
                protocol.unframe(cmd[2:] + "\n")
        else:
            protocol.unframe(cmd[2:] + "\n")
    assert bad == 2
