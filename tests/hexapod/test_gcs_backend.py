"""The GCS backend (GcsHexapod) against the emulated controller, over real TCP on 127.0.0.1.

Connect, every command it uses, one period's exchange, the nominal vs the true model,
out-of-range targets, VMO? at the workspace edge, timeouts, a dropped connection, a
killed emulator process, the conformance check, the registry specs, a serial link.
"""

from __future__ import annotations

import signal
import threading
import time
from collections.abc import Iterator

import numpy as np
import pytest

from hexapod import HexapodGeometry, deltalab
from hexapod.backends import gcs_protocol as gp
from hexapod.backends.conformance import check_backend
from hexapod.backends.emulator_server import FaultConfig
from hexapod.backends.gcs import GcsHexapod
from hexapod.backends.gcs_config import GcsOptions, platform_velocity
from hexapod.backends.gcs_emulated import open_emulated_gcs
from hexapod.backends.gcs_emulator import GcsConfig, GcsEmulator
from hexapod.backends.gcs_pose import PoseConvention
from hexapod.backends.registry import backends, open_backend
from hexapod.exceptions import BackendError, BackendPluginError, StrokeLimitError
from hexapod.kinematics import inverse_kinematics
from hexapod.link_errors import (
    GcsControllerError,
    GcsDisconnectedError,
    GcsLinkError,
    GcsOutOfLimitsError,
    GcsTimeoutError,
    ImplausibleReadingError,
)

DT = 0.01
Q0 = np.array([0.41, 0.42, 0.41, 0.42, 0.41, 0.42])


def _wiggle(k: int, amplitude: float = 0.02) -> np.ndarray:
    return amplitude * np.sin(np.arange(6) + k / 5)


@pytest.fixture
def emulator(geometry: HexapodGeometry) -> Iterator[GcsEmulator]:
    with GcsEmulator(GcsConfig(geometry, lengths=tuple(Q0))) as emu:
        yield emu


@pytest.fixture
def robot(emulator: GcsEmulator, geometry: HexapodGeometry) -> Iterator[GcsHexapod]:
    r = GcsHexapod(emulator.url, geometry)
    yield r
    r.close()


def _settled(r: GcsHexapod) -> np.ndarray:
    """The measured lengths once the platform stands still (no timing race)."""
    while r.emulator.moving():
        time.sleep(0.005)
    return r.measured_lengths()


def _moving_after(emu: GcsEmulator, wait: float = 0.1) -> bool:
    c0 = emu.coords()
    time.sleep(wait)
    return bool(np.any(emu.coords() != c0))


# ----------------------------------------------------------------------------- connect
def test_connect_reads_identity_pivot_and_sets_the_velocity(
        emulator: GcsEmulator, geometry: HexapodGeometry) -> None:
    emulator.board.error = 7  # a stale error from a previous session
    r = GcsHexapod(emulator.url, geometry)
    try:
        assert r.identity == "hexapod-vs, GCS hexapod emulator, 0, 0.1.0"
        assert emulator.board.error == 0  # cleared at connect
        expected = platform_velocity(geometry, r.convention, np.zeros(6))
        assert 1.0 <= r.velocity / expected < 1.01  # rounded up to a whole mm/s
        assert emulator.board.velocity == pytest.approx(r.velocity)
        assert np.allclose(r.measured_lengths(), Q0, atol=1e-8)
        assert emulator.history()[:6] == ["*IDN?", "ERR?", "SPI?", "ERR?", "POS?", "ERR?"]
        assert emulator.history()[6].startswith("VLS ")
    finally:
        r.close()
    assert "HLT" in emulator.history()  # close halts


def test_connection_refused_is_a_link_error(geometry: HexapodGeometry) -> None:
    with GcsEmulator(GcsConfig(geometry)) as emu:
        url = emu.url
    with pytest.raises(GcsLinkError, match="cannot connect"):
        GcsHexapod(url, geometry)


def test_pivot_option_sets_spi(geometry: HexapodGeometry) -> None:
    # the pivot can be set only with U = V = W = 0: start with every leg at 420 mm
    r = open_emulated_gcs(geometry, np.full(6, 0.42),
                          options=GcsOptions(pivot=(0.0, 0.01, 0.03)))
    try:
        assert np.allclose(r.emulator.board.convention.pivot, [0.0, 0.01, 0.03])
        assert np.allclose(r.convention.pivot, [0.0, 0.01, 0.03])
        for k in range(5):
            r.step(_wiggle(k), DT)
        assert np.allclose(_settled(r), r.emulator.true_lengths(), atol=1e-8)
    finally:
        r.close()


# ----------------------------------------------------------------------------- periods
@pytest.mark.realtime  # (the motion must end, and the round trip fit, within the period)
def test_one_period_is_mov_err_then_pos_err(robot: GcsHexapod, emulator: GcsEmulator) -> None:
    robot.transcript = []
    n = len(emulator.history())
    v = np.array([0.01, -0.01, 0.005, 0.0, -0.005, 0.01])
    dt = 0.05  # the motion (10 ms) ends 40 ms before POS?, even on a loaded machine
    bs = robot.step(v, dt)
    sent = emulator.history()[n:]
    assert [c.split()[0] for c in sent] == ["MOV", "ERR?", "POS?", "ERR?"]
    assert sent[0].split()[1::2] == list(gp.AXES)
    assert robot.transcript[:2] == [f"> {sent[0]}", "> ERR?"]
    assert robot.transcript[2] == "< 0"
    assert np.allclose(bs.lengths, Q0 + v * dt, atol=1e-8)  # the nominal IK of POS?
    assert np.allclose(bs.lengths, emulator.true_lengths(), atol=1e-8)
    assert np.array_equal(bs.applied_velocities, v) and not bs.clamped.any()
    assert 0 < bs.round_trip_s < dt and not bs.missed_period
    assert bs.extras["vmo_rtt_s"] == 0.0  # far from the stroke ends: no VMO?


@pytest.mark.realtime
def test_steps_keep_the_period(robot: GcsHexapod) -> None:
    t0 = time.perf_counter()
    for k in range(20):
        robot.step(_wiggle(k), DT)
    assert 20 * DT * 0.95 < time.perf_counter() - t0 < 20 * DT + 0.5


def test_the_controller_realises_the_pose_with_its_own_model(geometry: HexapodGeometry
                                                             ) -> None:
    rng = np.random.default_rng(7)
    true = geometry.replace(base_points=geometry.base_points + rng.normal(0, 1e-3, (6, 3)))
    r = open_emulated_gcs(true, Q0, nominal=geometry)
    try:
        for k in range(10):
            r.step(_wiggle(k), DT)
        q = _settled(r)
        conv = PoseConvention.for_geometry(geometry)
        # the pose the controller reports, in the NOMINAL model's legs: what controllers see
        nominal_legs = inverse_kinematics(geometry, *conv.pose(r.emulator.coords()))
        assert np.allclose(q, nominal_legs, atol=1e-8)
        # the legs the robot really has differ by its calibration (about a millimetre)
        assert 1e-4 < np.max(np.abs(q - r.emulator.true_lengths())) < 5e-3
    finally:
        r.close()


@pytest.mark.realtime
@pytest.mark.slow
def test_conformance_against_the_simulator(geometry: HexapodGeometry) -> None:
    # 50 ms periods: a period's motion (0.4 of the speed limit) ends 30 ms before POS?,
    # so that a loaded machine's scheduling stalls do not show as a lagging platform
    report = check_backend(lambda g, q: open_backend("gcs-emulator", g, q), geometry,
                           dt=0.05, tolerance=1e-7)
    assert report.ok, report.problems
    assert report.max_deviation < 1e-7  # POS? carries 1 nm and 1 micro-degree


# ----------------------------------------------------------------------------- limits
def test_out_of_range_mov_is_refused_with_error_7_and_nothing_moves(
        robot: GcsHexapod, emulator: GcsEmulator) -> None:
    c0 = emulator.coords()
    with pytest.raises(GcsOutOfLimitsError) as exc:
        robot.command("MOV Z 100")
    assert (exc.value.code, exc.value.text) == (7, "Position out of limits")
    assert exc.value.command == "MOV Z 100" and exc.value.url == emulator.url
    assert np.array_equal(emulator.coords(), c0) and not emulator.moving()
    assert emulator.history()[-2:] == ["HLT", "ERR?"]  # halted after the error
    assert robot.command("POS? Z") == [f"Z={gp.format_answer_number(c0[2] * 1e3)}"]


def test_other_controller_errors_carry_pi_numbers_and_texts(robot: GcsHexapod) -> None:
    with pytest.raises(GcsControllerError) as exc:
        robot.command("VLS 0")
    assert (exc.value.code, exc.value.text) == (17, "Parameter out of range")
    with pytest.raises(GcsControllerError, match=r"error 2 \(Unknown command\)"):
        robot.command("FRF X")


def test_move_outside_the_true_stroke_is_refused_by_vmo(geometry: HexapodGeometry) -> None:
    true = geometry.replace(stroke=(geometry.q_min, 0.43))  # shorter than the nominal
    r = open_emulated_gcs(true, Q0, nominal=geometry)
    try:
        q_before = r.emulator.true_lengths()
        with pytest.raises(GcsOutOfLimitsError, match="VMO"):
            r.move(np.full(6, 0.45))  # inside the nominal stroke, not the true one
        assert np.array_equal(r.emulator.true_lengths(), q_before)
        with pytest.raises(StrokeLimitError):
            r.move(np.full(6, 0.50))  # outside the nominal stroke: nothing is sent
    finally:
        r.close()


def test_at_the_edge_vmo_refusal_holds_the_robot(geometry: HexapodGeometry) -> None:
    top = geometry.q_max - 1e-3  # the true stroke ends 1 mm before the nominal one
    true = geometry.replace(stroke=(geometry.q_min, top))
    start = np.full(6, geometry.q_max - 1.8e-3)  # within the 2 mm band of the nominal end
    r = open_emulated_gcs(true, start, nominal=geometry)
    try:
        refused = []
        for _ in range(10):
            bs = r.step(np.full(6, geometry.max_speed), DT)  # up into the true stroke end
            refused.append(bs.extras["vmo_refused"])
            assert bs.extras["vmo_rtt_s"] > 0  # near the nominal edge: VMO? every period
        assert refused[0] == 0.0 and refused[-1] == 1.0
        assert np.all(bs.applied_velocities == 0) and bs.clamped.all()
        assert np.all(r.emulator.true_lengths() <= top + 1e-8)
        assert r.vmo_refusals >= 1 and r.emulator.board.error == 0  # no MOV was refused
    finally:
        r.close()


def test_reset_moves_and_waits_on_target(robot: GcsHexapod, emulator: GcsEmulator) -> None:
    target = Q0 + np.array([0.004, -0.003, 0.002, 0.0, 0.001, -0.002])
    q = robot.reset(target)
    assert np.allclose(q, target, atol=1e-8) and not emulator.moving()
    assert any(c.startswith("ONT?") for c in emulator.history())


# ----------------------------------------------------------------------------- failures
def test_silent_controller_times_out_and_is_halted(
        robot: GcsHexapod, emulator: GcsEmulator) -> None:
    robot.timeout = robot._link.timeout = 0.1
    emulator.set_faults(FaultConfig(silent_after=0))
    with pytest.raises(GcsTimeoutError) as exc:
        robot.step(_wiggle(0), DT)
    assert exc.value.command is not None and exc.value.timeout == 0.1
    assert "HLT" in emulator.history()[-3:]  # it still hears the HLT


def test_a_controller_silent_at_open_is_sent_hlt_and_the_error_says_so(
        emulator: GcsEmulator, geometry: HexapodGeometry) -> None:
    """A controller that never answers ``*IDN?``: the open times out after an ``HLT`` it
    heard, and the error carries what was done (a servo session's ``halt_detail``)."""
    emulator.set_faults(FaultConfig(silent_after=0))
    with pytest.raises(GcsTimeoutError) as info:
        GcsHexapod(emulator.url, geometry, GcsOptions(timeout=0.1))
    assert info.value.command == "*IDN?"
    assert getattr(info.value, "halt_detail", None) == (
        f"{emulator.url}: HLT sent on the way out, not acknowledged")
    assert "HLT" in emulator.history()


def test_dropped_connection_raises_and_closes(robot: GcsHexapod, emulator: GcsEmulator
                                              ) -> None:
    emulator.set_faults(FaultConfig(disconnect_after=9))
    with pytest.raises(GcsDisconnectedError, match="closed the connection"):
        for k in range(10):
            robot.step(_wiggle(k), DT)
    assert not robot.is_open
    assert not _moving_after(emulator)  # the last MOV was one period's worth
    robot.close()  # idempotent


@pytest.mark.realtime
def test_killed_emulator_process_mid_run(geometry: HexapodGeometry) -> None:
    r = open_emulated_gcs(geometry, Q0, process=True)
    try:
        for k in range(5):
            r.step(_wiggle(k), DT)
        r.emulator.proc.kill()
        with pytest.raises(GcsDisconnectedError) as exc:
            for k in range(50):
                r.step(_wiggle(k), DT)
        assert exc.value.url == r.url and not r.is_open
    finally:
        r.close()


@pytest.mark.realtime
def test_ctrl_c_during_an_exchange_halts_and_closes(
        robot: GcsHexapod, emulator: GcsEmulator) -> None:
    main = threading.main_thread().ident
    assert main is not None and threading.current_thread().ident == main
    robot.command("VLS 1")  # the platform lags: each MOV takes longer than a period
    for _ in range(3):
        robot.step(np.full(6, 0.04), DT)
    emulator.set_faults(FaultConfig(latency=1.0))  # the interrupt lands while waiting
    timer = threading.Timer(0.05, signal.pthread_kill, (main, signal.SIGINT))
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            robot.step(np.full(6, 0.04), DT)
    finally:
        timer.join()
    assert not robot.is_open
    assert "HLT" in emulator.history()[-3:]
    assert not _moving_after(emulator)


# ----------------------------------------------------------------------------- specs
def test_registry_specs(geometry: HexapodGeometry) -> None:
    assert {"gcs", "gcs-emulator"} <= set(backends.names())
    with pytest.raises(BackendPluginError, match="gcs:tcp://HOST:PORT"):
        backends.check("gcs")
    with pytest.raises(BackendError, match="vmo"):
        open_backend("gcs:tcp://127.0.0.1:1?vmo=sometimes", geometry)
    with pytest.raises(BackendError, match="KEY=VALUE"):
        open_backend("gcs:tcp://127.0.0.1:1?colour=red", geometry)
    with pytest.raises(GcsLinkError, match="tcp://HOST:PORT or serial:URL"):
        open_backend("gcs:http://127.0.0.1:1", geometry)
    with pytest.raises(BackendError, match="expected KEY=VALUE"):
        open_backend("gcs-emulator:process", geometry)
    url, opts = GcsOptions.parse("tcp://h:1?vmo=always&pivot_mm=0,0,10&velocity=20&baud=9600")
    assert url == "tcp://h:1" and opts.vmo == "always" and opts.baudrate == 9600
    assert opts.pivot == pytest.approx((0, 0, 0.01)) and opts.velocity == pytest.approx(0.02)


def test_spec_with_options_drives_a_real_controller(emulator: GcsEmulator,
                                                    geometry: HexapodGeometry) -> None:
    with open_backend(f"gcs:{emulator.url}?vmo=always&velocity=150", geometry, Q0) as r:
        r.step(_wiggle(0), DT)
        assert r.vmo_checks >= 2 and emulator.board.velocity == pytest.approx(0.15)
        assert any(c.startswith("VMO?") for c in emulator.history())


def test_over_a_serial_link(geometry: HexapodGeometry) -> None:
    r = open_emulated_gcs(geometry, Q0, transport="pty")
    try:
        assert r.url.startswith("serial:/dev/")
        for k in range(5):
            r.step(_wiggle(k), DT)
        assert np.allclose(_settled(r), r.emulator.true_lengths(), atol=1e-8)
    finally:
        r.close()
    with pytest.raises(GcsLinkError, match="cannot open"):
        GcsHexapod("serial:/nonexistent/port", deltalab())


@pytest.mark.realtime
def test_halt_confirmed_reads_error_10(robot: GcsHexapod, emulator: GcsEmulator) -> None:
    robot.step(np.full(6, 0.005), 0.02)
    report = robot.halt_confirmed(2.0)
    assert report.confirmed and "ERR? answered 10" in report.detail, report
    assert not emulator.moving()
    robot.close()  # confirmed and nothing sent since: close() does not halt again
    assert emulator.history().count("HLT") == 1, emulator.history()


@pytest.mark.realtime
def test_halt_queued_during_a_stall_is_confirmed(robot: GcsHexapod,
                                                 emulator: GcsEmulator) -> None:
    emulator.set_faults(FaultConfig(stall_after=1, stall_s=0.6))
    robot._link.write(gp.encode("POS?"), "POS?")  # the command that starts the stall
    report = robot.halt_confirmed(2.0)
    assert report.confirmed, report
    assert 0.4 < report.seconds < 1.5


@pytest.mark.realtime
def test_a_second_client_is_told_the_controller_is_busy(
        robot: GcsHexapod, emulator: GcsEmulator, geometry: HexapodGeometry,
        caplog: pytest.LogCaptureFixture) -> None:
    t0 = time.perf_counter()
    with caplog.at_level("WARNING", logger="hexapod.backends.gcs"), \
            pytest.raises(GcsDisconnectedError, match="busy with another client"):
        GcsHexapod(emulator.url, geometry)
    # the connection never came up: no HLT tried on it (no broken pipe, no 0.5 s wait)
    assert "HLT" not in caplog.text and time.perf_counter() - t0 < 0.4
    assert robot.measured_lengths().shape == (6,)  # the first client is still served


def test_a_glitching_pose_reading_is_refused_and_the_robot_halted(
        robot: GcsHexapod, emulator: GcsEmulator) -> None:
    """The controller reports the platform 30 mm further along X than it is: the period's
    reading is refused (its legs off the way from the last reading to the target), the
    robot halted, and no MOV is computed from it."""
    robot.step(np.zeros(6), DT)
    emulator.set_faults(FaultConfig(glitch_after=1, glitch=0.03))
    with pytest.raises(ImplausibleReadingError, match=r"implausible position reading: leg "
                                                      r"\d at .* \(between its last reading"):
        robot.step(np.zeros(6), DT)
    recent = emulator.history()[-4:]
    assert "HLT" in recent and not any(c.startswith("MOV") for c in recent[recent.index(
        "HLT"):]), recent
