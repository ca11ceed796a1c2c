"""The emulated PI GCS hexapod controller, over a real TCP socket on 127.0.0.1.

Framing (single- and multi-line answers, silent set commands, errors only through
``ERR?``), every command, the motion at the system velocity, the limits of the TRUE
robot, the pivot point, the conventions, and the console script (TCP and pty).
"""

from __future__ import annotations

import signal
import socket
import time
from collections.abc import Iterator

import numpy as np
import pytest
import serial

from hexapod import HexapodGeometry, deltalab
from hexapod.backends import gcs_protocol as gp
from hexapod.backends.emulator_server import FaultConfig
from hexapod.backends.gcs_emulator import GcsConfig, GcsEmulator
from hexapod.backends.gcs_pose import PoseConvention, rotation_from_uvw
from hexapod.exceptions import BackendError
from hexapod.kinematics import inverse_kinematics
from tests.hexapod.emulator_process import emulator_process, spawn_emulator


class Link:
    """A raw GCS client on a TCP socket: send lines, read complete answers."""

    def __init__(self, address: str, timeout: float = 1.0) -> None:
        host, _, port = address.rpartition(":")
        self.sock = socket.create_connection((host, int(port)), timeout=timeout)
        self.buf = bytearray()

    def send(self, *lines: str) -> None:
        self.sock.sendall(gp.encode(*lines))

    def answer(self, timeout: float = 1.0) -> bytes:
        """The next complete answer, raw (continuation spaces and LFs included)."""
        deadline = time.monotonic() + timeout
        while (end := gp.answer_end(self.buf)) < 0:
            self.sock.settimeout(max(1e-3, deadline - time.monotonic()))
            chunk = self.sock.recv(4096)
            assert chunk, "connection closed"
            self.buf += chunk
        out = bytes(self.buf[:end])
        del self.buf[:end]
        return out

    def silent(self, wait: float = 0.1) -> bool:
        """Nothing arrives within ``wait`` [s]."""
        self.sock.settimeout(wait)
        try:
            data = self.sock.recv(4096)
        except TimeoutError:
            return not self.buf
        self.buf += data
        return False

    def query(self, line: str) -> str:
        self.send(line)
        return self.answer().decode("ascii")

    def err(self) -> int:
        return gp.parse_int_answer(self.query("ERR?"))

    def pos(self, axes: tuple[str, ...] = gp.AXES) -> dict[str, float]:
        cmd = "POS? " + " ".join(axes) if axes != gp.AXES else "POS?"
        return gp.parse_axis_answer(self.query(cmd), axes)

    def close(self) -> None:
        self.sock.close()


@pytest.fixture
def emulator(geometry: HexapodGeometry) -> Iterator[GcsEmulator]:
    with GcsEmulator(GcsConfig(geometry, velocity=0.02)) as emu:
        yield emu


@pytest.fixture
def link(emulator: GcsEmulator) -> Iterator[Link]:
    lk = Link(emulator.device)
    yield lk
    lk.close()


# ----------------------------------------------------------------------------- framing
def test_url_is_loopback_tcp(emulator: GcsEmulator) -> None:
    assert emulator.url.startswith("tcp://127.0.0.1:")
    assert emulator.url.endswith(emulator.device.rpartition(":")[2])


def test_single_line_answer_ends_without_a_space(link: Link) -> None:
    link.send("*IDN?")
    assert link.answer() == b"hexapod-vs, GCS hexapod emulator, 0, 0.1.0\n"
    link.send("VLS?")
    assert link.answer() == b"20.000000\n"


def test_multi_line_answer_continues_with_space_lf(link: Link) -> None:
    link.send("POS?")
    raw = link.answer()
    assert raw == (b"X=0.000000 \nY=0.000000 \nZ=0.000000 \nU=0.000000 \nV=0.000000 \n"
                   b"W=0.000000\n")
    assert gp.answer_end(raw) == len(raw)
    assert gp.answer_end(raw[:-1]) == -1  # incomplete until the final LF
    link.send("POS? Z X")
    assert link.answer() == b"Z=0.000000 \nX=0.000000\n"


def test_pipelined_queries_give_one_answer_each(link: Link) -> None:
    link.send("ONT?", "ERR?", "SPI? T")
    assert link.answer() == b"X=1 \nY=1 \nZ=1 \nU=1 \nV=1 \nW=1\n"
    assert link.answer() == b"0\n"
    assert link.answer() == b"T=0.000000\n"


def test_set_commands_are_silent_and_errors_wait_for_err(link: Link) -> None:
    link.send("MOV X 0.5")
    assert link.silent()
    link.send("NOPE 1")  # unknown: silent too, the number is stored
    assert link.silent()
    assert link.err() == gp.GcsError.UNKNOWN_COMMAND
    assert link.err() == gp.GcsError.NO_ERROR  # reading it cleared it


@pytest.mark.parametrize(("line", "code"), [
    ("MOV X", gp.GcsError.PARAM_SYNTAX),
    ("MOV X abc", gp.GcsError.PARAM_SYNTAX),
    ("MOV X nan", gp.GcsError.PARAM_SYNTAX),
    ("MOV Q 1", gp.GcsError.INVALID_AXIS_IDENTIFIER),
    ("MOV X 1 X 2", gp.GcsError.DOUBLE_AXIS),
    ("mov X 1", gp.GcsError.UNKNOWN_COMMAND),
    ("VLS", gp.GcsError.PARAM_SYNTAX),
    ("VLS fast", gp.GcsError.PARAM_SYNTAX),
    ("VLS 0", gp.GcsError.PARAM_OUT_OF_RANGE),
    ("VLS 100000", gp.GcsError.PARAM_OUT_OF_RANGE),
    ("SPI Q 1", gp.GcsError.INVALID_AXIS_IDENTIFIER),
    ("STP X", gp.GcsError.PARAM_SYNTAX),
    ("X" * 2000, gp.GcsError.COMMAND_TOO_LONG),
])
def test_bad_set_commands_store_their_error_and_change_nothing(
        link: Link, emulator: GcsEmulator, line: str, code: int) -> None:
    link.send(line)
    assert link.err() == code
    assert np.all(emulator.coords() == 0.0)
    assert link.query("VLS?") == "20.000000\n"


@pytest.mark.parametrize(("line", "code"), [
    ("POS? Q", gp.GcsError.INVALID_AXIS_IDENTIFIER),
    ("*IDN? 1", gp.GcsError.PARAM_SYNTAX),
    ("VMO? X", gp.GcsError.PARAM_SYNTAX),
    ("SPI? X", gp.GcsError.INVALID_AXIS_IDENTIFIER),
    ("FOO?", gp.GcsError.UNKNOWN_COMMAND),
])
def test_bad_queries_answer_nothing(link: Link, line: str, code: int) -> None:
    link.send(line, "ERR?")
    assert link.answer() == f"{int(code)}\n".encode()  # the first answer is ERR?'s


# ----------------------------------------------------------------------------- motion
@pytest.mark.realtime
def test_mov_moves_in_a_straight_line_at_the_system_velocity(
        link: Link, emulator: GcsEmulator) -> None:
    t0 = time.monotonic()
    link.send("VLS 20", "MOV X 4 Y 3")  # 5 mm at 20 mm/s: 250 ms
    assert link.err() == 0  # the MOV was processed after t0 and before this answer
    time.sleep(0.05)
    p = link.pos(("X", "Y"))
    elapsed = time.monotonic() - t0  # POS? was processed before this
    assert 0 < p["X"] < 4 and abs(p["Y"] / p["X"] - 0.75) < 1e-5  # a straight line
    assert 20 * 0.05 - 1e-6 <= np.hypot(p["X"], p["Y"]) <= 20 * elapsed + 1e-6  # 20 mm/s
    assert "=0" in link.query("ONT? X")
    time.sleep(0.3)
    assert link.query("ONT? X Y") == "X=1 \nY=1\n"
    assert link.pos() == {"X": 4.0, "Y": 3.0, "Z": 0.0, "U": 0.0, "V": 0.0, "W": 0.0}


def test_rotation_speed_is_vls_in_degrees_per_second(geometry: HexapodGeometry) -> None:
    fast_legs = geometry.replace(max_speed=10.0)  # the velocity, not the legs, sets the pace
    with GcsEmulator(GcsConfig(fast_legs)) as emu:
        lk = Link(emu.device)
        try:
            t0 = time.monotonic()
            lk.send("VLS 20", "MOV W 5")  # 5 deg at 20 deg/s: 250 ms
            assert lk.err() == 0
            time.sleep(0.05)
            w = lk.pos(("W",))["W"]
            assert 20 * 0.05 - 1e-6 <= w <= 20 * (time.monotonic() - t0) + 1e-6
            time.sleep(0.3)
            assert lk.pos(("W",))["W"] == 5.0
        finally:
            lk.close()


def test_the_true_legs_never_beat_their_speed_limit(link: Link, emulator: GcsEmulator) -> None:
    link.send("VLS 500", "MOV Z 10")  # 10 mm at 500 mm/s, but legs at 50 mm/s
    assert link.err() == 0
    t0 = time.monotonic()  # before the first reading and after the last: dt >= their interval
    q0 = emulator.true_lengths()
    time.sleep(0.05)
    q1 = emulator.true_lengths()
    dt = time.monotonic() - t0
    assert np.max(np.abs(q1 - q0)) <= emulator.config.geometry.max_speed * dt + 1e-6
    assert emulator.moving()


def test_mov_out_of_the_true_stroke_is_refused_and_nothing_moves(
        link: Link, emulator: GcsEmulator) -> None:
    q_before = emulator.true_lengths()
    assert link.query("VMO? Z 100") == "0\n"
    assert link.query("VMO? Z 10") == "1\n"
    link.send("MOV Z 100")
    assert link.err() == gp.GcsError.POS_OUT_OF_LIMITS
    assert not emulator.moving()
    assert np.all(emulator.true_lengths() == q_before)
    assert link.pos(("Z",)) == {"Z": 0.0}


def test_vmo_uses_the_true_robot_not_a_nominal_one(geometry: HexapodGeometry) -> None:
    # a TRUE robot with a shorter upper stroke than the nominal one
    true = geometry.replace(stroke=(geometry.q_min, geometry.q_max - 0.02))
    conv = PoseConvention.for_geometry(true)
    z = 0.0
    while np.max(inverse_kinematics(true, *conv.pose(np.array([0, 0, z, 0, 0, 0])))) \
            < true.q_max - 1e-3:
        z += 1e-3
    with GcsEmulator(GcsConfig(true)) as emu:
        lk = Link(emu.device)
        try:
            assert lk.query(f"VMO? Z {z * 1e3:.3f}") == "1\n"
            z_out = z + 5e-3  # inside the nominal stroke, outside the true one
            q_nominal = inverse_kinematics(geometry, *PoseConvention.for_geometry(
                true).pose(np.array([0, 0, z_out, 0, 0, 0])))
            assert np.all(q_nominal < geometry.q_max)
            assert lk.query(f"VMO? Z {z_out * 1e3:.3f}") == "0\n"
        finally:
            lk.close()


def test_hlt_stops_the_platform_where_it_is_and_stores_error_10(
        link: Link, emulator: GcsEmulator) -> None:
    link.send("VLS 10", "MOV X 10")  # one second of motion
    time.sleep(0.1)
    link.send("HLT")
    assert link.silent(0.05)
    x1 = link.pos(("X",))["X"]
    time.sleep(0.1)
    assert link.pos(("X",))["X"] == x1
    assert 0.5 < x1 < 5.0
    assert link.query("ONT?").count("=1") == 6
    assert link.err() == gp.GcsError.STOP
    assert link.err() == 0
    assert "HLT" in emulator.history()


def test_stp_stops_too(link: Link, emulator: GcsEmulator) -> None:
    link.send("VLS 10", "MOV Y -10")
    time.sleep(0.05)
    link.send("STP")
    assert link.err() == gp.GcsError.STOP
    assert link.pos(("Y",))["Y"] < 0


def test_vls_sets_and_reports_the_system_velocity(link: Link) -> None:
    link.send("VLS 12.5")
    assert link.query("VLS?") == "12.500000\n"
    assert link.err() == 0


def test_idn_and_err(link: Link) -> None:
    assert link.query("*IDN?").startswith("hexapod-vs, GCS hexapod emulator")
    assert link.err() == 0


# ----------------------------------------------------------------------------- conventions
def test_rotations_are_about_the_pivot_point(link: Link, emulator: GcsEmulator) -> None:
    R0, t0 = emulator.pose()
    link.send("SPI R 10 S -20 T 50")
    assert link.err() == 0
    assert link.query("SPI?") == "R=10.000000 \nS=-20.000000 \nT=50.000000\n"
    R1, t1 = emulator.pose()
    assert np.allclose(t1, t0) and np.allclose(R1, R0)  # setting the pivot moves nothing
    p = np.array([0.01, -0.02, 0.05])
    pivot_before = R0 @ p + t0
    link.send("VLS 100", "MOV U 1 V -2 W 3")
    assert link.err() == 0  # processed
    while emulator.moving():
        time.sleep(0.01)
    R, t = emulator.pose()
    assert np.allclose(R, rotation_from_uvw(*np.deg2rad([1, -2, 3]), "moving-xyz"),
                       atol=1e-12)
    assert np.allclose(R @ p + t, pivot_before, atol=1e-12)  # the pivot point stayed
    link.send("SPI T 0")  # U, V, W not all 0: refused
    assert link.err() == gp.GcsError.SET_PIVOT_NOT_POSSIBLE
    assert link.query("SPI? T") == "T=50.000000\n"


def test_fixed_axes_convention(geometry: HexapodGeometry) -> None:
    with GcsEmulator(GcsConfig(geometry, rotation_order="fixed-xyz", velocity=0.1)) as emu:
        lk = Link(emu.device)
        try:
            lk.send("MOV U 2 V 3 W -4")
            assert lk.err() == 0  # processed
            while emu.moving():
                time.sleep(0.01)
            R, _ = emu.pose()
            assert np.allclose(R, rotation_from_uvw(*np.deg2rad([2, 3, -4]), "fixed-xyz"))
            assert not np.allclose(R, rotation_from_uvw(*np.deg2rad([2, 3, -4]),
                                                        "moving-xyz"))
        finally:
            lk.close()


def test_starts_at_the_given_leg_lengths(geometry: HexapodGeometry) -> None:
    q0 = np.array([0.40, 0.41, 0.42, 0.43, 0.42, 0.41])
    with GcsEmulator(GcsConfig(geometry, lengths=tuple(q0))) as emu:
        assert np.allclose(emu.true_lengths(), q0, atol=1e-12)


def test_bad_configurations(geometry: HexapodGeometry) -> None:
    with pytest.raises(BackendError, match="outside the stroke"):
        GcsConfig(geometry, lengths=(0.3,) * 6)
    with pytest.raises(BackendError, match="velocity"):
        GcsConfig(geometry, velocity=1.0, max_velocity=0.5)
    with pytest.raises(BackendError, match="rotation order"):
        GcsConfig(geometry, rotation_order="zyx")
    with pytest.raises(BackendError, match="non-loopback"):
        GcsEmulator(GcsConfig(geometry), host="0.0.0.0")


def test_disconnect_fault_closes_the_socket(geometry: HexapodGeometry) -> None:
    with GcsEmulator(GcsConfig(geometry), FaultConfig(disconnect_after=2)) as emu:
        lk = Link(emu.device)
        try:
            assert lk.query("*IDN?")
            lk.send("POS?")
            assert lk.answer()  # the second answer still arrives
            lk.sock.settimeout(2.0)
            assert lk.sock.recv(10) == b""  # then the controller hangs up
        finally:
            lk.close()


# ----------------------------------------------------------------------------- command line
@pytest.mark.realtime
def test_cli_gcs_tcp() -> None:
    with emulator_process("--gcs", "--tcp", "127.0.0.1:0", "--pose", "1", "2", "3", "0.5",
                          "0", "0", "--velocity", "25") as (proc, url):
        assert url.startswith("tcp://127.0.0.1:")
        lk = Link(url.removeprefix("tcp://"), timeout=5.0)
        try:
            assert lk.pos(("X", "Y", "Z", "U")) == {"X": 1.0, "Y": 2.0, "Z": 3.0, "U": 0.5}
            assert lk.query("VLS?") == "25.000000\n"
        finally:
            lk.close()
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(10) == 0


@pytest.mark.realtime
def test_cli_gcs_pty() -> None:
    with emulator_process("--gcs", "--pty", "--lengths", "400") as (proc, url):
        assert url.startswith("serial:/dev/")
        port = serial.serial_for_url(url.removeprefix("serial:"), timeout=2.0)
        try:
            port.write(b"POS? Z\n")
            z = gp.parse_axis_answer(port.readline(), ("Z",))["Z"]
            conv = PoseConvention.for_geometry(deltalab())
            q = inverse_kinematics(deltalab(), *conv.pose(np.array([0, 0, z * 1e-3, 0, 0, 0])))
            assert np.allclose(q, 0.4, atol=1e-8)
        finally:
            port.close()
        proc.send_signal(signal.SIGINT)
        assert proc.wait(10) == 0


def test_cli_gcs_refuses_board_options() -> None:
    proc = spawn_emulator("--gcs", "--tcp", "127.0.0.1:0", "--watchdog", "200")
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 2 and out == ""
    assert "--watchdog" in err
