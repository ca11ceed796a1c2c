"""The emulated controller board, driven through a real pseudo-terminal with pyserial.

Every command and error code, all-or-nothing MOV, the watchdog, checksums, the leg
motion in real time, the faults, the TCP server and the console script.
"""

from __future__ import annotations

import os
import signal
import time
from collections.abc import Iterator

import numpy as np
import pytest
import serial

from hexapod.backends import protocol
from hexapod.backends.emulator import BoardConfig, Emulator, FaultConfig
from hexapod.exceptions import BackendError
from hexapod.link_errors import ChecksumError
from tests.hexapod.emulator_process import emulator_process, spawn_emulator

STROKE = (0.345, 0.485)
SPEED = 0.05
Q0 = (0.40, 0.41, 0.42, 0.43, 0.44, 0.45)


class Link:
    """A raw pyserial link: send a payload, read one framed reply."""

    def __init__(self, url: str, timeout: float = 0.5) -> None:
        self.port = serial.serial_for_url(url, baudrate=115200, timeout=timeout)

    def raw(self, line: bytes) -> bytes:
        self.port.write(line)
        return self.port.readline()

    def send(self, payload: str) -> str:
        reply = self.raw(protocol.frame(payload))
        assert reply.endswith(b"\n"), f"no reply to {payload!r}: {reply!r}"
        return protocol.unframe(reply)

    def pos(self) -> np.ndarray:
        return protocol.parse_pos(self.send("POS?"))

    def sta(self) -> protocol.Status:
        return protocol.parse_sta(self.send("STA?"))

    def close(self) -> None:
        self.port.close()


@pytest.fixture
def emulator() -> Iterator[Emulator]:
    emu = Emulator(BoardConfig(stroke=STROKE, max_speed=SPEED, lengths=Q0, watchdog=1.0))
    emu.start()
    yield emu
    emu.stop()


@pytest.fixture
def link(emulator: Emulator) -> Iterator[Link]:
    lk = Link(emulator.device)
    yield lk
    lk.close()


def mov(q: np.ndarray | tuple[float, ...]) -> str:
    return protocol.mov(np.asarray(q))


# ----------------------------------------------------------------------------- queries
def test_device_is_a_real_pty(emulator: Emulator) -> None:
    assert emulator.device.startswith("/dev/")
    assert os.path.exists(emulator.device)
    assert emulator.url == emulator.device


def test_queries_at_power_on(link: Link) -> None:
    assert link.send("*IDN?").startswith("IDN hexapod-emulator")
    assert link.send("LIM?") == "LIM 345.000 485.000 50.000"
    assert link.send("POS?") == "POS 400.000 410.000 420.000 430.000 440.000 450.000"
    assert link.send("STA?") == "STA servo=0 moving=0 error=0 watchdog=0"
    assert link.send("ERR?") == "ERR 0 none"


def test_reply_lines_carry_correct_checksums(link: Link) -> None:
    for cmd in ("*IDN?", "LIM?", "POS?", "STA?", "ERR?", "BOGUS", "SVO 1", "HLT"):
        line = link.raw(protocol.frame(cmd))
        payload, _, hh = line.rstrip(b"\n").rpartition(b"*")
        x = 0
        for b in payload:
            x ^= b
        assert hh == f"{x:02X}".encode(), line


def test_one_reply_line_per_command(link: Link) -> None:
    # ten commands written at once: ten reply lines, in order, then nothing
    cmds = ["POS?", "STA?", "BOGUS", "SVO 1", "SVO 0", "LIM?", "*IDN?", "HLT", "ERR?", "ERR?"]
    link.port.write(b"".join(protocol.frame(c) for c in cmds))
    replies = [protocol.unframe(link.port.readline()) for _ in cmds]
    heads = [r.split()[0] for r in replies]
    assert heads == ["POS", "STA", "ERR", "OK", "OK", "LIM", "IDN", "OK", "ERR", "ERR"]
    assert replies[-2].startswith("ERR 10 ") and replies[-1] == "ERR 0 none"
    link.port.timeout = 0.1
    assert link.port.readline() == b""


def test_queries_take_no_argument(link: Link) -> None:
    for cmd in ("POS? 1", "STA? x", "LIM? 2", "*IDN? a", "ERR? 0", "HLT now"):
        assert link.send(cmd).startswith("ERR 1 "), cmd


# ----------------------------------------------------------------------------- errors
def test_unknown_command_is_error_2(link: Link) -> None:
    assert link.send("FLY 1").startswith("ERR 2 unknown command")
    assert link.send("pos?").startswith("ERR 2 ")  # commands are upper-case
    assert link.send("ERR?").startswith("ERR 2 ")
    assert link.send("ERR?") == "ERR 0 none"


def test_empty_command_is_syntax(link: Link) -> None:
    assert link.send("").startswith("ERR 1 ")


def test_a_line_over_256_bytes_is_refused_whole_or_in_pieces(link: Link) -> None:
    """docs/serial-protocol.md: lines are at most 256 bytes (the terminator included). A
    longer one is discarded with ``ERR 1 syntax: line too long``, whether its terminator comes in
    the same write (it was executed) or the board's buffer fills first; the next line is
    served as usual, and a line of 256 bytes is; the rest of a line that filled the buffer
    is discarded up to its terminator (it was executed as a command of its own)."""
    assert protocol.MAX_LINE == 256
    payload = "MOV " + " ".join(["440.000" + "0" * 36] * 6)
    long_mov = f"{payload}*{protocol.checksum(payload)}\n".encode("ascii")
    assert len(long_mov) == 271
    assert link.send("SVO 1") == "OK"
    assert protocol.unframe(link.raw(long_mov)) == "ERR 1 syntax: line too long"
    time.sleep(0.05)
    np.testing.assert_allclose(link.pos(), Q0)  # not moved
    link.port.write(b"X" * 300)  # no terminator: the buffer overflows
    assert protocol.unframe(link.port.readline()) == "ERR 1 syntax: line too long"
    link.port.write(b" " * 10 + protocol.frame("SVO 0"))  # the rest of that line: not a
    assert link.port.readline() == b""  # command (no answer; the servo stays on)
    assert link.sta().servo
    at_limit = "POS?" + " " * 248  # 256 bytes framed ("*XX\n")
    assert len(protocol.frame(at_limit)) == 256
    np.testing.assert_allclose(protocol.parse_pos(link.send(at_limit)), Q0)


def test_bad_checksum_is_error_3_and_has_no_effect(link: Link, emulator: Emulator) -> None:
    assert link.send("SVO 1") == "OK"
    line = protocol.frame("MOV 480.000 470.000 460.000 450.000 440.000 430.000")
    assert line.endswith(b"*5F\n")
    for bad in (line.replace(b"*5F", b"*5E"),                  # wrong digits
                line.replace(b"*5F", b""),                     # missing checksum
                line.replace(b"*5F", b"*5f"),                  # lower-case hex
                line.replace(b"480", b"481")):                 # payload corrupted in transit
        reply = link.raw(bad)
        assert protocol.unframe(reply) == "ERR 3 checksum", bad
    time.sleep(0.05)
    assert link.sta().moving is False
    np.testing.assert_allclose(link.pos(), Q0)
    assert link.send("ERR?") == "ERR 3 checksum"


def test_servo_on_off_and_mov_with_servo_off_is_error_5(link: Link) -> None:
    assert link.send("SVO 2").startswith("ERR 1 ")
    assert link.send("SVO").startswith("ERR 1 ")
    assert link.send(mov((0.41,) * 6)) == "ERR 5 servo off"
    time.sleep(0.03)
    np.testing.assert_allclose(link.pos(), Q0)
    assert link.sta().error == 5
    assert link.send("SVO 1") == "OK"
    assert link.sta().servo is True
    assert link.send("SVO 0") == "OK"
    assert link.sta().servo is False


@pytest.mark.realtime
def test_mov_moves_every_leg_at_the_speed_limit(link: Link) -> None:
    assert link.send("SVO 1") == "OK"
    target = np.array(Q0) + np.array([0.004, -0.004, 0.002, -0.002, 0.0, 0.001])
    t0 = time.monotonic()
    assert link.send(mov(target)) == "OK"
    time.sleep(0.04)
    q = link.pos()
    elapsed = time.monotonic() - t0
    assert link.sta().moving is True
    # after ~40 ms at 50 mm/s a leg has moved at most v * elapsed and the 2 mm legs arrived
    moved = np.abs(q - np.array(Q0))
    assert np.all(moved <= SPEED * elapsed + 1e-6)
    assert moved[0] >= SPEED * 0.04 - 1e-6 and moved[0] < 0.004
    np.testing.assert_allclose(q[[2, 3, 4, 5]], target[[2, 3, 4, 5]], atol=1e-9)
    time.sleep(0.1)
    np.testing.assert_allclose(link.pos(), target, atol=1e-9)
    assert link.sta().moving is False


@pytest.mark.parametrize("bad", [
    "MOV 400 400 400 400 400",                      # five values
    "MOV 400 400 400 400 400 400 400",              # seven values
    "MOV 400 400 400 400 400 abc",                  # not a number
    "MOV 400 400 400 400 400 nan",                  # not a finite number
    "MOV 400 400 400 400 400 inf",
])
def test_mov_syntax_moves_nothing(link: Link, bad: str) -> None:
    assert link.send("SVO 1") == "OK"
    assert link.send(bad).startswith("ERR 1 ")
    time.sleep(0.02)
    np.testing.assert_allclose(link.pos(), Q0)
    assert link.sta().moving is False


@pytest.mark.parametrize("leg", range(6))
@pytest.mark.parametrize("value", [0.485001, 0.344999, 0.600, 0.0])
def test_mov_is_all_or_nothing(link: Link, leg: int, value: float) -> None:
    assert link.send("SVO 1") == "OK"
    target = np.array(Q0) + 0.003
    target[leg] = value
    reply = link.send(mov(target))
    assert reply.startswith("ERR 7 outside stroke"), reply
    assert f"l{leg + 1}=" in reply
    time.sleep(0.02)
    np.testing.assert_allclose(link.pos(), Q0)  # not one leg moved
    assert link.sta().moving is False
    assert link.send("ERR?").startswith("ERR 7 ")


def test_mov_at_the_stroke_limits_is_accepted(link: Link) -> None:
    assert link.send("SVO 1") == "OK"
    assert link.send("MOV 345.000 485.000 345.000 485.000 400 400") == "OK"


def test_vel_sets_the_speed_limit_and_error_8(link: Link) -> None:
    assert link.send("VEL 20") == "OK"
    assert link.send("LIM?") == "LIM 345.000 485.000 20.000"
    for bad in ("VEL 0", "VEL -5", "VEL 50.001", "VEL 1000"):
        assert link.send(bad).startswith("ERR 8 speed out of range"), bad
    assert link.send("VEL x").startswith("ERR 1 ")
    assert link.send("VEL").startswith("ERR 1 ")
    assert link.send("LIM?") == "LIM 345.000 485.000 20.000"
    # the legs now move at 20 mm/s
    assert link.send("SVO 1") == "OK"
    t0 = time.monotonic()
    assert link.send(mov(np.array(Q0) + 0.01)) == "OK"
    time.sleep(0.05)
    moved = link.pos() - np.array(Q0)
    elapsed = time.monotonic() - t0
    assert np.all(moved <= 0.020 * elapsed + 1e-6)
    assert np.all(moved >= 0.020 * 0.05 - 1e-6)
    assert link.send("VEL 50") == "OK"


def test_wdt_range(link: Link) -> None:
    for ok in ("WDT 20", "WDT 1000", "WDT 100"):
        assert link.send(ok) == "OK"
    for bad in ("WDT 19", "WDT 1001", "WDT 0", "WDT -50", "WDT 50.5", "WDT x", "WDT"):
        assert link.send(bad).startswith("ERR 1 "), bad


def test_hlt_stops_every_leg_and_reports_10(link: Link) -> None:
    assert link.send("SVO 1") == "OK"
    target = np.array(Q0) + 0.02  # 400 ms of travel
    assert link.send(mov(target)) == "OK"
    time.sleep(0.05)
    assert link.send("HLT") == "OK"
    q = link.pos()
    assert link.sta().moving is False
    time.sleep(0.05)
    np.testing.assert_allclose(link.pos(), q)
    assert np.all(q < target - 0.01)
    assert link.sta().error == 10
    assert link.send("ERR?") == "ERR 10 halted by command"
    assert link.send("ERR?") == "ERR 0 none"
    # HLT does not latch: the next MOV moves again
    assert link.send(mov(target)) == "OK"
    time.sleep(0.02)
    assert link.sta().moving is True


def test_err_returns_the_last_error_then_clears(link: Link) -> None:
    link.send("BOGUS")
    link.send("VEL 0")
    st = link.sta()
    assert st.error == 8  # STA does not clear
    assert link.send("ERR?").startswith("ERR 8 ")
    assert link.send("ERR?") == "ERR 0 none"
    assert link.sta().error == 0


# ----------------------------------------------------------------------------- watchdog
@pytest.mark.realtime
def test_watchdog_trips_holds_and_latches_until_err(link: Link) -> None:
    assert link.send("WDT 50") == "OK"
    assert link.send("SVO 1") == "OK"
    target = np.array(Q0) + 0.02  # 400 ms of travel
    assert link.send(mov(target)) == "OK"
    t_mov = time.monotonic()
    time.sleep(0.12)
    st = link.sta()
    assert st == protocol.Status(servo=True, moving=False, error=20, watchdog=True)
    q = link.pos()
    # held where it was when the watchdog tripped, 50 ms after the MOV (+ the link delay)
    moved = q - np.array(Q0)
    assert np.all(moved >= SPEED * 0.05 - 1e-6)
    assert np.all(moved <= SPEED * (0.05 + (time.monotonic() - t_mov - 0.12) + 0.01))
    # latched: MOVs are refused, and nothing moves
    for _ in range(3):
        assert link.send(mov(target)) == "ERR 20 watchdog: latched, read ERR? to clear"
    time.sleep(0.06)
    np.testing.assert_allclose(link.pos(), q)
    assert link.sta().watchdog is True
    # other errors do not hide it: ERR? reports 20 first
    link.send("BOGUS")
    assert link.send("ERR?") == "ERR 20 watchdog"
    assert link.sta() == protocol.Status(servo=True, moving=False, error=0, watchdog=False)
    assert link.send(mov(target)) == "OK"
    time.sleep(0.02)
    assert link.sta().moving is True


@pytest.mark.realtime
def test_watchdog_fed_by_mov_does_not_trip(link: Link) -> None:
    assert link.send("WDT 60") == "OK"
    assert link.send("SVO 1") == "OK"
    q = np.array(Q0)
    for _ in range(15):  # 300 ms of 20 ms MOVs
        q = q + 0.0005
        assert link.send(mov(q)) == "OK"
        time.sleep(0.02)
    assert link.sta().watchdog is False
    assert link.send("ERR?") == "ERR 0 none"


def test_watchdog_only_with_servo_on_and_only_valid_mov_feeds_it(link: Link) -> None:
    assert link.send("WDT 30") == "OK"
    time.sleep(0.06)
    assert link.sta().watchdog is False  # servo off: disarmed
    assert link.send("SVO 1") == "OK"
    for _ in range(4):  # refused MOVs and queries do not feed the watchdog
        link.send("MOV 400 400 400 400 400 999")
        link.send("POS?")
        time.sleep(0.015)
    assert link.sta().watchdog is True


# ----------------------------------------------------------------------------- lag
@pytest.mark.realtime
def test_first_order_lag() -> None:
    tau = 0.05
    cfg = BoardConfig(stroke=STROKE, max_speed=SPEED, lengths=Q0, lag=tau)
    with Emulator(cfg) as emu:
        lk = Link(emu.device)
        try:
            assert lk.send("SVO 1") == "OK"
            step = 0.001  # 1 mm, below v tau = 2.5 mm: pure exponential
            t0 = time.monotonic()
            assert lk.send(mov(np.array(Q0) + step)) == "OK"
            time.sleep(0.05)
            q = lk.pos()
            t = time.monotonic() - t0
            err = np.array(Q0) + step - q
            # between the errors expected at the earliest and the latest sampling time
            assert np.all(err <= step * np.exp(-0.05 / tau) + 1e-6)
            assert np.all(err >= step * np.exp(-t / tau) - 1e-6)
            assert lk.sta().moving is True
        finally:
            lk.close()


# ----------------------------------------------------------------------------- faults
@pytest.mark.realtime
def test_latency_fault(emulator: Emulator, link: Link) -> None:
    emulator.set_faults(FaultConfig(latency=0.03, jitter=0.01, seed=3))
    for _ in range(3):
        t0 = time.perf_counter()
        assert link.send("POS?").startswith("POS ")
        assert 0.03 <= time.perf_counter() - t0 < 0.2


def test_garble_fault_is_seeded_and_always_detected(emulator: Emulator, link: Link) -> None:
    def run(seed: int) -> list[bytes]:
        emulator.set_faults(FaultConfig(garble_rate=0.5, seed=seed))
        return [link.raw(protocol.frame("LIM?")) for _ in range(40)]

    first, again, other = run(7), run(7), run(8)
    assert first == again
    assert first != other
    good = protocol.frame("LIM 345.000 485.000 50.000")
    n_bad = 0
    for line in first:
        assert line.endswith(b"\n")
        if line == good:
            continue
        n_bad += 1
        with pytest.raises(protocol.ProtocolError):
            payload = protocol.unframe(line)
            # a garbled command that the board rejected is a valid ERR 3 line
            if payload == "ERR 3 checksum":
                raise ChecksumError(line, None, None)
    assert 10 < n_bad < 35  # about 1 - 0.5 * 0.5 = 75 % of the exchanges


def test_drop_fault(emulator: Emulator, link: Link) -> None:
    emulator.set_faults(FaultConfig(drop_rate=1.0))
    link.port.timeout = 0.1
    assert link.raw(protocol.frame("SVO 1")) == b""
    emulator.set_faults(FaultConfig())
    assert link.sta().servo is True  # the command was executed, its reply lost


def test_silent_after_fault(emulator: Emulator, link: Link) -> None:
    emulator.set_faults(FaultConfig(silent_after=2))
    assert link.send("POS?").startswith("POS")
    assert link.send("STA?").startswith("STA")
    link.port.timeout = 0.1
    assert link.raw(protocol.frame("SVO 1")) == b""
    assert emulator.status().servo is True  # still obeys


def test_disconnect_fault_closes_the_pty(emulator: Emulator, link: Link) -> None:
    emulator.set_faults(FaultConfig(disconnect_after=2))
    assert link.send("POS?").startswith("POS")
    assert link.send("POS?").startswith("POS")
    assert emulator.wait_stopped(1.0)
    assert not emulator.running
    with pytest.raises(serial.SerialException):
        link.port.write(protocol.frame("POS?"))
        link.port.read(1)


# ----------------------------------------------------------------------------- TCP, config
def test_tcp_loopback() -> None:
    cfg = BoardConfig(stroke=STROKE, max_speed=SPEED, lengths=Q0)
    with Emulator(cfg, transport="tcp", host="127.0.0.1", port=0) as emu:
        assert emu.url.startswith("socket://127.0.0.1:")
        for _ in range(2):  # a new connection after the first one closed
            lk = Link(emu.url)
            try:
                assert lk.send("POS?") == "POS 400.000 410.000 420.000 430.000 440.000 450.000"
                assert lk.send("SVO 1") == "OK"
            finally:
                lk.close()


def test_tcp_refuses_non_loopback_addresses() -> None:
    with pytest.raises(BackendError, match="non-loopback"):
        Emulator(transport="tcp", host="0.0.0.0", port=0)


def test_bad_configurations() -> None:
    with pytest.raises(BackendError):
        BoardConfig(stroke=(0.5, 0.4))
    with pytest.raises(BackendError):
        BoardConfig(watchdog=0.01)
    with pytest.raises(BackendError):
        BoardConfig(lengths=(0.3,) * 6)
    with pytest.raises(BackendError):
        FaultConfig(drop_rate=1.5)
    with pytest.raises(BackendError):
        Emulator(transport="usb")


def test_from_geometry(other_geometry: object) -> None:
    from hexapod import HexapodGeometry

    assert isinstance(other_geometry, HexapodGeometry)
    cfg = BoardConfig.from_geometry(other_geometry, lag=0.01)
    assert cfg.stroke == other_geometry.stroke
    assert cfg.max_speed == other_geometry.max_speed
    assert cfg.lag == 0.01 and cfg.identity.endswith("other")


# ----------------------------------------------------------------------------- command line
@pytest.mark.realtime
@pytest.mark.slow
def test_cli_pty_prints_the_device_then_serves(tmp_path: object) -> None:
    with emulator_process("--pty", "--lengths", "400", "--speed", "30", "--watchdog", "200",
                          "--stroke", "350", "480") as (proc, device):
        assert device.startswith("/dev/")
        lk = Link(device, timeout=2.0)
        try:
            assert lk.send("LIM?") == "LIM 350.000 480.000 30.000"
            assert lk.send("POS?") == "POS " + " ".join(["400.000"] * 6)
        finally:
            lk.close()
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(10) == 0


@pytest.mark.realtime
@pytest.mark.slow
def test_cli_tcp_and_faults() -> None:
    with emulator_process("--tcp", "127.0.0.1:0", "--geometry", "deltalab", "--latency", "20",
                          "--seed", "4") as (proc, url):
        assert url.startswith("socket://127.0.0.1:")
        lk = Link(url, timeout=2.0)
        try:
            t0 = time.perf_counter()
            assert lk.send("LIM?") == "LIM 345.000 485.000 50.000"
            assert time.perf_counter() - t0 >= 0.02
        finally:
            lk.close()
        proc.send_signal(signal.SIGINT)
        assert proc.wait(10) == 0


def test_cli_refuses_remote_address() -> None:
    proc = spawn_emulator("--tcp", "0.0.0.0:0")
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 2
    assert out == ""
    assert "non-loopback" in err


@pytest.mark.realtime
def test_line_rate_emulates_the_transmission_time() -> None:
    cfg = BoardConfig(stroke=STROKE, max_speed=SPEED, lengths=Q0)
    with Emulator(cfg, line_rate=9600) as emu:
        lk = Link(emu.device)
        try:
            cmd = protocol.frame("POS?")
            t0 = time.perf_counter()
            reply = lk.raw(cmd)
            rtt = time.perf_counter() - t0
            # 8 + 53 bytes of 10 bits at 9600 baud: 63.5 ms
            assert rtt >= 10 * (len(cmd) + len(reply)) / 9600
            assert rtt < 0.2
        finally:
            lk.close()


def test_every_fault_survives_the_command_line() -> None:
    """A child emulator gets its faults as options (``FaultConfig.to_args``): each one,
    the glitching reading and the drive fault included, parses back to itself."""
    from hexapod.backends.emulator import _faults_from_args, build_parser

    f = FaultConfig(latency=0.002, jitter=0.001, drop_rate=0.01, garble_rate=0.02,
                    silent_after=9, disconnect_after=11, stall_after=2, stall_s=0.5,
                    glitch_after=3, glitch=0.012, drive_fault_after=5, drive_fault_code=41,
                    seed=4)
    assert _faults_from_args(build_parser().parse_args(["--pty", *f.to_args()])) == f
    with pytest.raises(BackendError, match="drive_fault_code must be >= 1"):
        FaultConfig(drive_fault_code=0)


@pytest.mark.parametrize(("args", "says"), [
    (["--speed", "-1"], "--speed -1: must be positive and finite [mm/s]"),
    (["--stroke", "485", "345"], "--stroke 485 345: expected 0 < MIN < MAX [mm]"),
])
def test_cli_names_a_bad_robot_option_in_its_own_units(args: list[str], says: str) -> None:
    """(It said 'got -0.001' and '(0.485 m)' for options given in mm.)"""
    from hexapod.backends.emulator import build_parser, config_from_args

    with pytest.raises(BackendError) as exc:
        config_from_args(build_parser().parse_args(["--pty", *args]))
    assert str(exc.value) == says


def test_an_identity_too_long_for_a_line_or_a_port_out_of_range_is_refused(
        capsys: pytest.CaptureFixture[str]) -> None:
    """Both crashed the emulator with a traceback (the identity at the first ``*IDN?``,
    after the device was printed); they are refused naming the option, exit 2."""
    from hexapod.backends.emulator import main

    assert main(["--pty", "--identity", "x" * 249]) == 2
    err = capsys.readouterr().err
    assert "hexapod-emulator: error: emulator identity must be printable ASCII that fits " \
           "a 256-byte line" in err and "(248 characters at most), got 249" in err
    BoardConfig(identity="x" * 248)  # the longest that fits
    with pytest.raises(SystemExit) as info:
        main(["--tcp", "127.0.0.1:99999"])
    assert info.value.code == 2
    assert "argument --tcp: expected HOST:PORT (a port of 0 to 65535)" in capsys.readouterr().err


@pytest.mark.parametrize("token", ["4_15", "1e3", "415.", "+inf", "0x19F", "nan"])
def test_a_length_not_written_as_a_decimal_number_is_syntax(link: Link, token: str) -> None:
    """Lengths are millimetres as decimals; Python's own syntax (``4_15``, exponents) was
    accepted by ``float`` and moved the legs."""
    assert link.send("SVO 1") == "OK"
    reply = link.send(f"MOV {token} 415.5 415.5 415.5 415.5 415.5")
    assert reply.startswith("ERR 1 "), reply


def test_a_plain_decimal_is_a_number() -> None:
    for token, value in (("415", 415.0), ("415.500", 415.5), ("-2", -2.0), ("+3.25", 3.25)):
        assert protocol.parse_number(token) == value
