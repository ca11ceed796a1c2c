"""SerialRobot through the emulator on a real pseudo-terminal (real pyserial, no mocks).

Opening, reset, clamped streaming at the control period, error mapping, retries on
garbled exchanges, halting on a timeout / disconnection / Ctrl-C / leaving ``with``,
and a closed-loop joint-space run that ends where the simulated robot ends.
"""

from __future__ import annotations

import re
import signal
import threading
import time
from collections.abc import Iterator

import numpy as np
import pytest

from hexapod import HexapodGeometry, deltalab
from hexapod.backends import Backend, SimulatedRobot, clamp_velocities, protocol
from hexapod.backends.emulator import BoardConfig, Emulator, FaultConfig
from hexapod.backends.rate import RateLimiter
from hexapod.backends.serial import SerialRobot
from hexapod.backends.serial_emulated import open_emulated_robot
from hexapod.exceptions import StrokeLimitError
from hexapod.link_errors import (
    ChecksumError,
    ImplausibleReadingError,
    OutsideStrokeError,
    ProtocolError,
    RobotFaultError,
    SerialDisconnectedError,
    SerialLinkError,
    SerialTimeoutError,
    ServoOffError,
    WatchdogError,
)

#: Wall-clock periods against real emulator processes: run alone (`make test`).
pytestmark = pytest.mark.realtime

DT = 0.02
Q0 = np.array([0.40, 0.405, 0.41, 0.415, 0.42, 0.425])


@pytest.fixture
def emulator(geometry: HexapodGeometry) -> Iterator[Emulator]:
    emu = Emulator(BoardConfig.from_geometry(geometry, Q0)).start()
    yield emu
    emu.stop()


@pytest.fixture
def robot(emulator: Emulator) -> Iterator[SerialRobot]:
    r = SerialRobot(emulator.device, timeout=0.2, watchdog=0.1)
    yield r
    r.close()


def test_open_reads_identity_and_limits_from_the_board(other_geometry: HexapodGeometry) -> None:
    emu = Emulator(BoardConfig.from_geometry(other_geometry)).start()
    try:
        with SerialRobot(emu.device, watchdog=0.25) as r:
            assert isinstance(r, Backend)
            assert r.identity == "hexapod-emulator 0.1.0 other"
            assert r.stroke == other_geometry.stroke == (0.38, 0.56)
            assert r.max_speed == other_geometry.max_speed
            st = emu.status()
            # servo off until the first MOV: the legs hold, the watchdog is disarmed
            assert not st.servo and not st.watchdog and st.error == 0
            assert emu.board.watchdog == 0.25
            np.testing.assert_allclose(r.measured_lengths(), other_geometry.q_mid, atol=1e-9)
            r.step(np.zeros(6), DT)
            assert emu.status().servo  # SVO 1 came with the first MOV
        assert not r.is_open
    finally:
        emu.stop()


def test_reset_arms_the_servo_once_before_its_mov(robot: SerialRobot, emulator: Emulator,
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    """docs/serial-protocol.md's reset: ``ERR?``, ``STA?``, ``SVO 1`` (the servo was off),
    then ``MOV`` and the polls; ``SVO 1`` was sent twice (the move's own check and the
    first MOV's arming each sent one). A second reset with the servo on sends none, and
    one with the servo switched off since (``SVO 0``) one again."""
    seen: list[str] = []
    handle = emulator.board.handle

    def spy(payload: str, now: float) -> str:
        seen.append(payload)
        return handle(payload, now)

    monkeypatch.setattr(emulator.board, "handle", spy)
    q = Q0 + 0.001
    robot.reset(q)
    assert seen[:3] == ["ERR?", "STA?", "SVO 1"] and seen[3].startswith("MOV ")
    assert seen.count("SVO 1") == 1
    seen.clear()
    robot.reset(q - 0.001)
    assert "SVO 1" not in seen and seen[:2] == ["ERR?", "STA?"]
    assert robot.command("SVO 0") == "OK"
    seen.clear()
    robot.reset(q)
    assert seen[:3] == ["ERR?", "STA?", "SVO 1"] and seen.count("SVO 1") == 1


def test_open_clears_a_stale_error(emulator: Emulator) -> None:
    with SerialRobot(emulator.device) as r:
        r.command("BOGUS")
    with SerialRobot(emulator.device) as r:
        assert r.read_error() == (0, "none")


def test_open_failure_is_a_link_error(tmp_path: object) -> None:
    with pytest.raises(SerialLinkError, match="cannot open"):
        SerialRobot("/dev/does-not-exist-hexapod")


def test_reset_moves_to_the_lengths(robot: SerialRobot, emulator: Emulator) -> None:
    target = np.array([0.41, 0.39, 0.41, 0.40, 0.405, 0.4])
    t0 = time.perf_counter()
    q = robot.reset(target)
    elapsed = time.perf_counter() - t0
    np.testing.assert_allclose(q, target, atol=1e-9)
    np.testing.assert_allclose(emulator.true_lengths(), target, atol=1e-9)
    assert not emulator.status().moving
    # 25 mm at 50 mm/s: the move takes real time, and the watchdog (100 ms) did not trip
    assert elapsed >= 0.025 / 0.05 - 0.01
    assert emulator.status().error == 0
    np.testing.assert_allclose(robot.reset(), target, atol=1e-9)


def test_reset_outside_the_stroke_sends_nothing(robot: SerialRobot, emulator: Emulator) -> None:
    before = emulator.board.commands
    bad = Q0.copy()
    bad[3] = 0.49
    with pytest.raises(StrokeLimitError) as info:
        robot.reset(bad)
    assert info.value.leg == 3 and info.value.upper == 0.485
    assert emulator.board.commands == before


def test_step_streams_clamped_setpoints(geometry: HexapodGeometry) -> None:
    start = np.array([0.4845, 0.3455, 0.40, 0.40, 0.40, 0.40])
    with open_emulated_robot(geometry, start) as robot:
        check_clamped_step(robot, robot.emulator, start)


def check_clamped_step(robot: SerialRobot, emulator: Emulator, start: np.ndarray) -> None:
    q = robot.reset(start)
    v = np.array([0.049, -0.049, 0.2, -0.01, np.nan, 0.0])  # stroke, stroke, speed, -, NaN
    expected_v, expected_clamped = clamp_velocities(q, v, DT, robot.stroke, robot.max_speed)
    st = robot.step(v, DT)
    np.testing.assert_allclose(st.applied_velocities, expected_v)
    np.testing.assert_array_equal(st.clamped, expected_clamped)
    assert st.clamped.tolist() == [True, True, True, False, True, False]
    target = np.clip(q + expected_v * DT, *robot.stroke)
    np.testing.assert_allclose(emulator.board.setpoints, target, atol=1.5e-6)  # streamed
    # Every leg reached its setpoint within the period but leg 2: commanded at the board's
    # own speed limit, it needs the whole period from the MOV's arrival, which comes a
    # fraction of a millisecond after the period's start (a wall-clock race): it is on its
    # way, never past the setpoint.
    others = [0, 1, 3, 4, 5]
    np.testing.assert_allclose(st.lengths[others], target[others], atol=1.5e-6)
    assert q[2] < st.lengths[2] <= target[2] + 1.5e-6
    assert st.lengths[0] == 0.485 and st.lengths[1] == 0.345
    assert emulator.status().error == 0  # never an ERR 7
    assert 0 < st.round_trip_s < DT
    assert st.extras["mov_rtt_s"] + st.extras["pos_rtt_s"] == pytest.approx(st.round_trip_s)


def test_step_keeps_the_period(robot: SerialRobot) -> None:
    q = robot.reset(Q0)
    t0 = time.perf_counter()
    n, missed = 25, 0
    for _ in range(n):
        st = robot.step(np.full(6, 0.01), DT)
        missed += st.missed_period
    elapsed = time.perf_counter() - t0
    assert elapsed == pytest.approx(n * DT, abs=0.5 * DT)
    assert missed <= 2
    np.testing.assert_allclose(st.lengths, q + n * 0.01 * DT, atol=5e-6)
    # a caller late by more than a period misses it
    time.sleep(1.5 * DT)
    assert robot.step(np.zeros(6), DT).missed_period


class _SimulatedTime:
    """A clock and a sleep that advances it (the limiter's arithmetic without the
    machine's scheduling: a loaded machine made a real 10 ms window miss a tick)."""

    def __init__(self) -> None:
        self.now = 100.0
        self.slept: list[float] = []

    def clock(self) -> float:
        return self.now

    def sleep(self, duration: float) -> None:
        self.slept.append(duration)
        self.now += duration


def test_rate_limiter_keeps_its_ticks_and_restarts_after_a_late_one(
        caplog: pytest.LogCaptureFixture) -> None:
    sim = _SimulatedTime()
    rate = RateLimiter(0.01, name="loop", warn=True, clock=sim.clock, sleep=sim.sleep)
    for _ in range(10):  # 4 ms of work each period: 6 ms of sleep
        sim.now += 0.004
        assert rate.sleep() == pytest.approx(0.006, abs=1e-12)
    assert sim.now == pytest.approx(100.1, abs=1e-12) and rate.missed == 0
    assert rate.frequency == pytest.approx(100.0) and rate.iterations == 10
    sim.now += 0.0105  # 0.5 ms late: missed, no warning (within 10 % of the period)
    assert rate.sleep() == pytest.approx(-0.0005, abs=1e-12) and rate.missed == 1
    assert rate.remaining() == pytest.approx(0.01, abs=1e-12)  # restarted from now
    assert not caplog.records
    sim.now += 0.03  # 20 ms late: missed, warned
    with caplog.at_level("WARNING"):
        assert rate.sleep() == pytest.approx(-0.02, abs=1e-12)
    assert rate.missed == 2 and "loop is late by 20.0 ms" in caplog.text
    assert rate.remaining() == pytest.approx(0.01, abs=1e-12)  # no burst of catch-up ticks
    slept = len(sim.slept)
    sim.now += 0.002
    rate.sleep()
    assert len(sim.slept) == slept + 1 and sim.slept[-1] == pytest.approx(0.008, abs=1e-12)


def test_rate_limiter_sleeps_in_real_time() -> None:
    """The real clock and sleep: ten ticks of 10 ms take at least 90 ms (a lower bound,
    which a loaded machine cannot break)."""
    rate = RateLimiter(0.01)
    t0 = time.perf_counter()
    for _ in range(10):
        rate.sleep()
    assert time.perf_counter() - t0 >= 0.09


# ----------------------------------------------------------------------------- errors
def test_servo_off_is_mapped_and_halts(robot: SerialRobot, emulator: Emulator) -> None:
    robot.reset(Q0)
    assert robot.command("SVO 0") == "OK"
    with pytest.raises(ServoOffError) as info:
        robot.step(np.full(6, 0.01), DT)
    assert info.value.code == 5 and str(info.value.command).startswith("MOV ")
    assert emulator.board.last_command == "HLT"
    assert robot.read_error()[0] == 10


def test_outside_stroke_reply_is_mapped(robot: SerialRobot) -> None:
    robot.reset(Q0)  # the servo on (the first motion command turns it on)
    with pytest.raises(OutsideStrokeError) as info:
        robot._guarded(lambda: robot._checked("MOV 400 400 400 400 400 999",
                                              protocol.parse_ok))
    assert info.value.code == 7 and "l6=999" in info.value.text


def test_watchdog_trip_while_idle_is_rearmed(robot: SerialRobot, emulator: Emulator) -> None:
    q = robot.reset(Q0)
    time.sleep(0.15)  # idle longer than the 100 ms watchdog
    assert emulator.status().watchdog
    st = robot.step(np.full(6, 0.01), DT)
    assert robot.watchdog_trips == robot.watchdog_rearms == 1
    np.testing.assert_allclose(st.lengths, q + 0.01 * DT, atol=2e-6)


def test_a_slow_first_period_after_open_does_not_trip_the_watchdog(
        robot: SerialRobot, emulator: Emulator, caplog: pytest.LogCaptureFixture) -> None:
    """Opened, then 0.3 s (three watchdog periods) before the first step, as a session's
    first image and controller call may take: the watchdog is armed with the first MOV,
    so it never trips; a trip in motion is counted and warned about."""
    time.sleep(0.3)
    assert not emulator.status().watchdog
    robot.step(np.zeros(6), DT)
    st = emulator.status()
    assert st.servo and not st.watchdog and st.error == 0
    assert robot.watchdog_trips == 0
    time.sleep(0.15)  # a stall of the host in motion: the watchdog trips
    with caplog.at_level("WARNING", logger="hexapod.backends.serial"):
        robot.step(np.zeros(6), DT)
    assert robot.watchdog_trips == robot.watchdog_rearms == 1
    assert "watchdog tripped" in caplog.text and "trip 1" in caplog.text


def test_watchdog_trip_raises_without_rearm(emulator: Emulator) -> None:
    with SerialRobot(emulator.device, watchdog=0.05, rearm_watchdog=False) as r:
        r.reset(Q0)
        time.sleep(0.1)
        with pytest.raises(WatchdogError) as info:
            r.step(np.full(6, 0.01), DT)
        assert info.value.code == 20 and str(info.value.command).startswith("MOV ")
        assert emulator.board.last_command == "HLT"  # halted after the error
        assert r.read_error()[0] == 20  # the latched watchdog is reported first, then cleared
        assert r.read_error()[0] == 0


def test_watchdog_not_explained_by_idle_raises(emulator: Emulator) -> None:
    # a link slower than the watchdog: the MOVs arrive late although the host is on time
    with SerialRobot(emulator.device, watchdog=0.02, timeout=0.5) as r:
        r.reset(Q0)
        emulator.set_faults(FaultConfig(latency=0.03))
        with pytest.raises(WatchdogError):
            for _ in range(5):
                r.step(np.zeros(6), DT)


# ----------------------------------------------------------------------------- faults
def test_survives_garbled_exchanges(geometry: HexapodGeometry) -> None:
    goal = Q0 + np.array([0.003, -0.002, 0.001, 0.0, -0.003, 0.002])
    sim = SimulatedRobot(geometry, Q0)
    with open_emulated_robot(geometry, Q0, faults=FaultConfig(garble_rate=0.15, seed=11),
                             retries=8) as r:
        q = r.measured_lengths()
        q_sim = sim.measured_lengths()
        for _ in range(40):
            q = r.step(5.0 * (goal - q), DT).lengths
            q_sim = sim.step(5.0 * (goal - q_sim), DT).lengths
        assert r.retried > 5
        np.testing.assert_allclose(q, q_sim, atol=1e-5)
        np.testing.assert_allclose(r.emulator.true_lengths(), q, atol=1e-9)


def test_gives_up_after_bounded_retries(robot: SerialRobot, emulator: Emulator) -> None:
    robot.reset(Q0)
    emulator.set_faults(FaultConfig(garble_rate=1.0, seed=2))
    t0 = time.perf_counter()
    with pytest.raises(ProtocolError):
        robot.step(np.zeros(6), DT)
    assert time.perf_counter() - t0 < 0.5
    # 1 + 3 retries of the MOV, then one HLT attempt
    assert emulator.board.commands >= 5
    emulator.set_faults(FaultConfig())
    robot.reset(Q0)  # the link is fine again: usable
    assert robot.step(np.zeros(6), DT).lengths.shape == (6,)


def test_checksum_error_carries_its_evidence(robot: SerialRobot, emulator: Emulator) -> None:
    emulator.set_faults(FaultConfig(garble_rate=1.0, seed=5))
    with pytest.raises(ProtocolError) as info:
        robot.measured_lengths()
    err = info.value
    assert err.command == "POS?"
    if isinstance(err, ChecksumError):
        assert err.expected != err.got


def test_silent_device_times_out_and_halts(robot: SerialRobot, emulator: Emulator) -> None:
    robot.reset(Q0)
    robot.move(Q0 + 0.02, wait=False)
    emulator.set_faults(FaultConfig(silent_after=0))
    t0 = time.perf_counter()
    with pytest.raises(SerialTimeoutError) as info:
        robot.step(np.full(6, 0.01), DT)
    assert time.perf_counter() - t0 < 1.0
    assert info.value.timeout == 0.2 and str(info.value.command).startswith("MOV ")
    assert emulator.board.last_command == "HLT"  # the board heard the HLT
    assert not emulator.status().moving


def test_a_board_silent_at_open_is_sent_hlt_and_the_error_says_so(emulator: Emulator
                                                                 ) -> None:
    """A board that hears but never answers ``*IDN?``: the open fails (timeout) after an
    ``HLT`` the board heard, and the error carries what was done (a servo session
    records it as its ``halt_detail``; it said only "the robot was not connected")."""
    emulator.set_faults(FaultConfig(silent_after=0))
    with pytest.raises(SerialTimeoutError) as info:
        SerialRobot(emulator.device, timeout=0.2, watchdog=0.1)
    assert info.value.command == "*IDN?"
    detail = getattr(info.value, "halt_detail", None)
    assert detail == f"{emulator.device}: HLT sent on the way out, not acknowledged"
    assert emulator.board.last_command == "HLT"


def test_disconnect_raises_and_closes(robot: SerialRobot, emulator: Emulator) -> None:
    robot.reset(Q0)
    emulator.set_faults(FaultConfig(disconnect_after=3))
    with pytest.raises(SerialDisconnectedError):
        for _ in range(5):
            robot.step(np.zeros(6), DT)
    assert not robot.is_open
    with pytest.raises(SerialLinkError, match="closed"):
        robot.measured_lengths()
    robot.close()  # idempotent


def test_dropped_reply_is_retried_when_asked(emulator: Emulator) -> None:
    with SerialRobot(emulator.device, timeout=0.05, timeout_retries=3) as r:
        r.reset(Q0)
        emulator.set_faults(FaultConfig(drop_rate=0.3, seed=1))
        for _ in range(10):
            r.step(np.zeros(6), DT)
        assert r.retried > 0


# ----------------------------------------------------------------------------- halting
def test_leaving_with_halts_and_closes(emulator: Emulator) -> None:
    target = Q0 + 0.03  # 600 ms of travel
    with pytest.raises(RuntimeError, match="boom"), SerialRobot(emulator.device) as r:
        r.move(target, wait=False)
        time.sleep(0.05)
        raise RuntimeError("boom")
    assert not r.is_open
    assert emulator.board.last_command == "HLT"
    st = emulator.status()
    assert not st.moving and st.error == 10
    assert np.all(emulator.true_lengths() < target - 0.02)


def test_ctrl_c_during_an_exchange_halts_and_closes(emulator: Emulator) -> None:
    main = threading.main_thread().ident
    assert threading.current_thread().ident == main
    r = SerialRobot(emulator.device, timeout=2.0)
    r.move(Q0 + 0.03, wait=False)
    emulator.set_faults(FaultConfig(latency=1.0))  # the interrupt lands while waiting
    assert main is not None
    timer = threading.Timer(0.05, signal.pthread_kill, (main, signal.SIGINT))
    timer.start()
    t0 = time.perf_counter()
    try:
        with pytest.raises(KeyboardInterrupt):
            r.step(np.zeros(6), DT)
    finally:
        timer.join()
    assert time.perf_counter() - t0 < 1.0 + 2.5  # HLT waited for its (late) reply at most
    assert not r.is_open
    assert emulator.board.last_command == "HLT"
    assert not emulator.status().moving


# ----------------------------------------------------------------------------- closed loop
def test_closed_loop_reaches_the_same_lengths_as_the_simulated_robot(
        geometry: HexapodGeometry) -> None:
    goal = np.array([0.4075, 0.3995, 0.416, 0.409, 0.4135, 0.431])
    k, n = 5.0, 100

    def run(backend: Backend) -> np.ndarray:
        q = backend.reset(Q0)
        path = []
        for _ in range(n):
            st = backend.step(k * (goal - q), DT)
            q = st.lengths
            path.append(q)
        return np.array(path)

    sim = run(SimulatedRobot(geometry, Q0))
    with open_emulated_robot(geometry, Q0) as robot:
        real = run(robot)
        missed = robot.stats()
    np.testing.assert_allclose(real, sim, atol=2e-4)           # the same trajectory
    np.testing.assert_allclose(real[-1], sim[-1], atol=1e-5)   # the same final lengths
    np.testing.assert_allclose(real[-1], goal, atol=1e-5)
    assert missed["exchanges"] >= 2 * n


def test_tcp_backend(geometry: HexapodGeometry) -> None:
    with open_emulated_robot(geometry, Q0, transport="tcp") as r:
        assert r.url.startswith("socket://127.0.0.1:")
        q = r.measured_lengths()
        for _ in range(5):
            st = r.step(np.full(6, 0.01), DT)
        np.testing.assert_allclose(st.lengths, q + 5 * 0.01 * DT, atol=5e-6)
    assert not r.emulator.running


def test_emulator_stops_with_the_robot() -> None:
    r = open_emulated_robot(deltalab())
    emu = r.emulator
    assert emu.running
    r.close()
    assert not emu.running


@pytest.mark.slow
def test_emulator_in_a_child_process(geometry: HexapodGeometry) -> None:
    faults = FaultConfig(latency=0.002, seed=3)
    with open_emulated_robot(geometry, Q0, faults=faults, process=True, lag=0.001) as r:
        proc = r.emulator
        assert proc.running and r.url.startswith("/dev/")
        np.testing.assert_allclose(r.measured_lengths(), Q0, atol=1e-9)
        q = Q0
        for _ in range(5):
            q = r.step(np.full(6, 0.01), DT).lengths
        assert min(r.exchanges) >= 0.002
        np.testing.assert_allclose(q, Q0 + 5 * 0.01 * DT, atol=5e-6)
    assert not proc.running and proc.proc.returncode == 0


def test_halt_confirmed_reads_back_the_halt_and_the_still_legs(
        robot: SerialRobot, emulator: Emulator) -> None:
    robot.step(np.full(6, 0.01), 0.02)
    report = robot.halt_confirmed(2.0)
    assert report.confirmed, report
    assert "ERR? 10 halted by command" in report.detail and "STA? moving=0" in report.detail
    assert not emulator.status().moving
    sent = emulator.board.commands
    robot.close()  # confirmed and nothing sent since: close() does not halt again
    time.sleep(0.1)  # the emulator's thread would have read an HLT by now
    assert emulator.board.commands == sent and emulator.board.last_command == "STA?"


def test_halt_queued_during_a_stall_is_confirmed_when_it_ends(
        robot: SerialRobot, emulator: Emulator) -> None:
    """The board freezes for 0.6 s: the HLT waits in the link, runs when the stall ends,
    and is confirmed (the replies of the commands before it are read and skipped)."""
    emulator.set_faults(FaultConfig(stall_after=1, stall_s=0.6))
    robot._write("POS?")  # the command that starts the stall
    t0 = time.perf_counter()
    report = robot.halt_confirmed(2.0)
    assert report.confirmed, report
    assert 0.4 < time.perf_counter() - t0 < 1.5


def test_halt_not_confirmed_on_a_silent_board_says_so(
        robot: SerialRobot, emulator: Emulator) -> None:
    emulator.set_faults(FaultConfig(silent_after=0))
    report = robot.halt_confirmed(0.5)
    assert not report.confirmed
    assert "not confirmed by ERR? (error 10) within 0.5 s" in report.detail
    assert 0.45 < report.seconds < 1.0


def test_halt_confirmed_after_the_link_closed_says_so(robot: SerialRobot) -> None:
    robot.close()
    report = robot.halt_confirmed(1.0)
    assert not report.confirmed and "the link is closed" in report.detail


def test_a_drive_fault_of_a_code_the_protocol_does_not_define_is_halted_and_named(
        robot: SerialRobot, emulator: Emulator) -> None:
    """The board latches drive fault 30 (not a protocol code): the MOV is refused with it
    (a RobotFaultError that halts), and the halt is confirmed, naming the fault (it
    was a ValueError that left the halt unconfirmed)."""
    robot.step(np.full(6, 0.01), DT)
    emulator.set_faults(FaultConfig(drive_fault_after=1, drive_fault_code=30))
    with pytest.raises(RobotFaultError, match=r"robot error 30 \(drive fault"):
        robot.step(np.full(6, 0.01), DT)
    report = robot.halt_confirmed(2.0)  # ERR? reads the latched fault first
    assert report.confirmed, report
    # (its watchdog, not fed since the fault, may have stopped the legs first: 20)
    assert re.search(r"ERR\? (10 halted by command|20 watchdog) \(after 30 drive fault "
                     r"\(fault injection\)\), STA\? moving=0", report.detail), report.detail
    assert emulator.board.drive_fault is None and not emulator.status().moving


def test_a_glitching_position_reading_is_refused_before_a_setpoint_is_made_of_it(
        robot: SerialRobot, emulator: Emulator) -> None:
    """After its next command the board reports leg 0 30 mm longer than it is: the
    streaming step refuses the reading (outside the way from its last reading to the
    setpoint sent), halts, and no MOV computed from it reaches the board (a 30 mm setpoint
    jump in one 20 ms period, where 50 mm/s allows 1 mm)."""
    robot.step(np.zeros(6), DT)
    emulator.set_faults(FaultConfig(glitch_after=1, glitch=0.03))
    with pytest.raises(ImplausibleReadingError, match=r"leg 0 at 430\.000 mm, where it can "
                                                      r"only be in \[399\.000, 401\.000\] mm"):
        robot.step(np.zeros(6), DT)  # MOV (command 1), then the glitching POS?
    assert emulator.board.last_command in ("STA?", "ERR?", "HLT")  # halted, no MOV after
    np.testing.assert_allclose(emulator.board.setpoints, Q0, atol=1e-9)
    # a reading outside the stroke is refused as well, naming the board's stroke
    hi = robot.stroke[1]
    emulator.set_faults(FaultConfig(glitch_after=0, glitch=hi - Q0[0] + 0.01))
    with pytest.raises(ImplausibleReadingError, match=r"\(the stroke, within 1 mm\)"):
        robot.measured_lengths()


def test_a_failed_write_says_so_once(robot: SerialRobot, emulator: Emulator) -> None:
    """The pty's other side gone: pyserial's 'write failed: [Errno 5] ...' is the
    message's reason as it is (it read 'write failed: write failed: ...')."""
    emulator.stop()
    with pytest.raises(SerialDisconnectedError) as exc:
        for _ in range(3):
            robot._write("POS?")
    text = str(exc.value)
    assert "write failed: [Errno 5]" in text and text.count("write failed") == 1, text
    robot.close()  # its HLT's flush on the dead terminal: termios.error, which it raised
    assert not robot.is_open


def test_a_fault_latched_before_the_session_connects_is_a_warning(
        emulator: Emulator, caplog: pytest.LogCaptureFixture) -> None:
    """A drive fault left on the board (by an earlier session, a crash) is cleared with
    ERR? when the session connects, and the user is told (it was logged at INFO, which
    the CLI does not show); the last session's HLT (error 10) stays quiet."""
    emulator.board._set_error(protocol.ErrorCode.WATCHDOG, "watchdog (a crashed session)")
    with caplog.at_level("INFO", logger="hexapod.backends.serial"):
        SerialRobot(emulator.device, timeout=0.2, watchdog=0.1).close()
    warned = [r for r in caplog.records if r.levelname == "WARNING"
              and "when the session connected" in r.getMessage()]
    assert len(warned) == 1 and "error 20 (watchdog (a crashed session))" in \
        warned[0].getMessage()
    caplog.clear()
    emulator.board._set_error(protocol.ErrorCode.HALTED)
    with caplog.at_level("INFO", logger="hexapod.backends.serial"):
        SerialRobot(emulator.device, timeout=0.2, watchdog=0.1).close()
    assert not [r for r in caplog.records if r.levelname == "WARNING"], caplog.records
    assert any("cleared a pending error 10" in r.getMessage() for r in caplog.records)


def test_two_lost_mov_replies_in_one_period_are_both_survived(
        emulator: Emulator, monkeypatch: pytest.MonkeyPatch) -> None:
    """The board executes MOV 3 and loses its reply; the host's retry after the timeout
    is refused (watchdog 20), cleared with ERR? and sent again, and that reply is lost
    too: a second re-arm, not the end of the session (it raised WatchdogError)."""
    from hexapod.backends.emulator_server import EmulatorServer

    movs = [0]
    original = EmulatorServer._command

    def dropping(self: EmulatorServer, line: bytes, overlong: bool = False) -> None:
        if line.startswith(b"MOV"):
            movs[0] += 1
            if movs[0] in (3, 5):  # executed, reply lost
                with self._lock:
                    self.board.handle_line(line, time.monotonic())
                return
        original(self, line, overlong)

    monkeypatch.setattr(EmulatorServer, "_command", dropping)
    with SerialRobot(emulator.device, timeout=0.2, watchdog=0.1, timeout_retries=1) as r:
        for _ in range(6):
            r.step(np.full(6, 0.001), DT)
        assert movs[0] >= 8 and r.watchdog_rearms == r.watchdog_trips == 2


def test_a_halt_that_could_not_be_written_is_not_called_sent() -> None:
    """A TCP board busy with another client closes the second connection: its open fails,
    and the HLT on the way out cannot be written (a broken pipe). The error's halt detail
    said "HLT sent on the way out, not acknowledged"; now that it could not be sent."""
    from hexapod.backends.emulator import EmulatorProcess
    from hexapod.link_errors import SerialDisconnectedError

    proc = EmulatorProcess(BoardConfig.from_geometry(deltalab(), Q0), transport="tcp")
    try:
        with SerialRobot(proc.url, timeout=0.2), \
                pytest.raises(SerialDisconnectedError) as info:
            SerialRobot(proc.url, timeout=0.2)
        assert getattr(info.value, "halt_detail", None) == (
            f"{proc.url}: HLT could not be sent on the way out (the link failed)")
        # why, in the words of a busy board (it was a bare 'Connection reset by peer')
        assert "a TCP board serves one client at a time: is another session connected " \
               "to it?" in str(info.value)
    finally:
        proc.stop()


def test_a_serial_spec_takes_its_baud_rate_and_refuses_a_bad_one() -> None:
    """``serial:URL?baud=N`` (a board at another rate could not be used from the command
    line: the whole text was taken as the device's path)."""
    from hexapod.backends.registry import backends, serial_url
    from hexapod.exceptions import BackendError

    assert serial_url("/dev/ttyUSB0") == ("/dev/ttyUSB0", 115200)
    assert serial_url("/dev/ttyUSB0?baud=57600") == ("/dev/ttyUSB0", 57600)
    assert serial_url("socket://h:5?logging=debug&baud=9600") == ("socket://h:5?logging=debug",
                                                                 9600)
    for bad in ("/dev/ttyUSB0?baud=fast", "/dev/ttyUSB0?baud=0", "/dev/x?baud="):
        with pytest.raises(BackendError, match=r"baud: expected a positive integer"):
            backends.check(f"serial:{bad}")  # before anything is opened
    for name in ("sim", "emulator"):
        with pytest.raises(BackendError, match=rf"{name}.*takes no arguments, got 'x'"):
            backends.check(f"{name}:x")


def test_a_board_at_another_baud_rate_is_reached_through_the_spec(emulator: Emulator) -> None:
    from hexapod.backends.registry import open_backend

    robot = open_backend(f"serial:{emulator.device}?baud=57600", deltalab())
    try:
        assert robot._port.baudrate == 57600  # type: ignore[attr-defined]
    finally:
        robot.close()


def _noisy_device(reply: bytes) -> tuple[str, threading.Thread, list[bool]]:
    """A pty whose other end answers every line with ``reply`` (a wrong baud rate or
    another device looks so); returns the port, its thread and a stop flag."""
    import os
    import pty

    master, slave = pty.openpty()
    stop = [False]

    def serve() -> None:
        while not stop[0]:
            try:
                data = os.read(master, 256)
            except OSError:
                return
            if b"\n" in data:
                os.write(master, reply)

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    return os.ttyname(slave), thread, stop


@pytest.mark.parametrize(("reply", "says"), [
    (bytes(range(200, 212)) + b"\n", "a device that does not speak this protocol, or at "
                                     "another baud rate than 115200 (serial:URL?baud=N)?"),
    (bytes(range(200, 212)), "no complete reply within 200.0 ms (received b'\\xc8"),
])
def test_a_device_that_does_not_speak_the_protocol_is_named_with_the_likely_cause(
        reply: bytes, says: str) -> None:
    """Line noise (a wrong baud rate, another device): the error named no port ('missing
    checksum: ...') or said 'no reply' although bytes had come."""
    from hexapod.link_errors import ProtocolError, SerialLinkError

    port, _thread, stop = _noisy_device(reply)
    try:
        with pytest.raises((ProtocolError, SerialLinkError)) as info:
            SerialRobot(port, timeout=0.2)
        assert port in str(info.value) and says in str(info.value), str(info.value)
    finally:
        stop[0] = True


def test_a_reply_longer_than_a_line_is_refused_however_it_arrives() -> None:
    """A well-framed 310-byte reply to *IDN? was accepted when it arrived in one piece and
    refused when it came in pieces (the limit was checked only before the line end)."""
    from hexapod.link_errors import ProtocolError

    payload = "IDN " + "x" * 300
    line = f"{payload}*{protocol.checksum(payload)}\n".encode()
    port, _thread, stop = _noisy_device(line)
    try:
        with pytest.raises(ProtocolError, match="line too long"):
            SerialRobot(port, timeout=0.2)
    finally:
        stop[0] = True
