"""hexapod-emulator --dynamics: the board's axes move as the robot with mass and drives.

The board driven with explicit clock times (deterministic): the legs lag the kinematic
board, a low force limit slows them, they settle on the setpoint; then through the real
emulator on a pseudo-terminal with pyserial, and the console script's option."""

from __future__ import annotations

import subprocess
import sys
import time

import numpy as np
import pytest
import serial

from hexapod.backends import protocol
from hexapod.backends.emulator import BoardConfig, Emulator
from hexapod.backends.emulator_board import Board
from hexapod.exceptions import BackendError
from hexapod.geometry import deltalab

#: Wall-clock periods against real emulator processes: run alone (`make test`).
pytestmark = pytest.mark.realtime

Q0 = np.full(6, 0.40)
STEP = 0.003  # m: every leg 3 mm longer


def _board(dynamics: bool, **drives: float) -> Board:
    g = deltalab()
    if drives:
        g = g.replace(drives=g.drives.replace(**drives))
    cfg = BoardConfig.from_geometry(g, Q0, watchdog=1.0, dynamics=g if dynamics else None)
    board = Board(cfg, 0.0)
    assert board.handle("SVO 1", 0.0) == "OK"
    target = " ".join(protocol.format_mm(x) for x in Q0 + STEP)
    assert board.handle(f"MOV {target}", 0.0) == "OK"
    return board


def _arrival(board: Board, tol: float = 1e-4, until: float = 2.0) -> float:
    """First time [s] every leg is within ``tol`` of its setpoint (1 ms samples)."""
    for k in range(1, int(until * 1000)):
        board.advance(k * 1e-3)
        if np.all(np.abs(board.setpoints - board.lengths) < tol):
            return k * 1e-3
    return np.inf


def test_the_dynamic_axes_lag_the_kinematic_ones_and_settle() -> None:
    kin, dyn = _board(False), _board(True)
    for board in (kin, dyn):
        board.advance(0.02)
    # 20 ms after the MOV: the kinematic legs moved 1 mm at 50 mm/s; the dynamic ones,
    # accelerating their 2.5 kg rotors and the platform under the position loop, less
    assert np.allclose(kin.lengths - Q0, 0.001)
    moved = dyn.lengths - Q0
    assert np.all((moved > 1e-4) & (moved < 0.0009)), moved
    t_kin, t_dyn = _arrival(_board(False)), _arrival(_board(True))
    assert t_kin == pytest.approx(0.058, abs=2e-3)
    assert t_kin < t_dyn < 0.3
    # then the integral action hunts against the Coulomb friction a while (measured:
    # within 10 um after 0.3 s, within 2 um after 1.7 s), and rests
    dyn.advance(0.5)
    assert np.all(np.abs(dyn.lengths - (Q0 + STEP)) < 1.5e-5)
    dyn.advance(3.0)
    assert np.all(np.abs(dyn.lengths - (Q0 + STEP)) < 2e-6)
    assert not dyn.moving


def test_a_low_force_limit_saturates_the_drives_and_slows_the_move() -> None:
    """12 N drives (the platform's weight takes 6.5 N of each, Coulomb friction 5 N): the
    move takes several times longer, the drives at their limit most of the way."""
    fast, slow = _board(True), _board(True, force_limit=12.0)
    slow.advance(0.01)
    forces = slow._axes.robots.forces[0]
    assert np.all(np.abs(forces) >= 12.0 - 1e-9), forces
    t_fast, t_slow = _arrival(fast), _arrival(slow)
    assert t_slow > 3 * t_fast
    assert slow._axes.robots.saturated_time[0] > 0.8 * t_slow


def test_force_mode_drives_are_refused() -> None:
    g = deltalab()
    g = g.replace(drives=g.drives.replace(mode="force"))
    with pytest.raises(BackendError, match="velocity mode"):
        Board(BoardConfig.from_geometry(g, Q0, dynamics=g), 0.0)


def test_through_the_real_emulator() -> None:
    """On a real pseudo-terminal with pyserial: the MOV is executed by the dynamic robot
    (not yet there after 20 ms, moving; there within 15 um after 0.5 s)."""
    g = deltalab()
    emu = Emulator(BoardConfig.from_geometry(g, Q0, watchdog=1.0, dynamics=g)).start()
    try:
        port = serial.serial_for_url(emu.url, baudrate=115200, timeout=1.0)

        def send(payload: str) -> str:
            port.write(protocol.frame(payload))
            return protocol.unframe(port.readline())

        assert send("SVO 1") == "OK"
        target = Q0 + STEP
        assert send("MOV " + " ".join(protocol.format_mm(x) for x in target)) == "OK"
        time.sleep(0.02)
        early = protocol.parse_pos(send("POS?"))
        assert protocol.parse_sta(send("STA?")).moving
        assert np.all(early - Q0 < 0.0015), early  # the kinematic board: 1 mm + the latency
        time.sleep(0.5)
        final = protocol.parse_pos(send("POS?"))
        np.testing.assert_allclose(final, target, atol=1.5e-5)
        port.close()
    finally:
        emu.stop()


@pytest.mark.slow
def test_the_console_script_takes_dynamics() -> None:
    proc = subprocess.Popen([sys.executable, "-m", "hexapod.backends.emulator", "--pty",
                             "--dynamics", "--physics-dt", "0.5"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        url = proc.stdout.readline().strip()
        port = serial.serial_for_url(url, baudrate=115200, timeout=2.0)
        port.write(protocol.frame("POS?"))
        assert protocol.unframe(port.readline()).startswith("POS ")
        port.close()
    finally:
        proc.terminate()
        proc.wait(10)
    bad = subprocess.run([sys.executable, "-m", "hexapod.backends.emulator", "--pty",
                          "--dynamics", "--physics-dt", "50"], capture_output=True, text=True,
                         timeout=60)
    assert bad.returncode == 2 and "--physics-dt must be in" in bad.stderr


# ----------------------------------------------------------------------------- GCS


def _gcs(dynamics: bool):
    from hexapod.backends.gcs_emulator import GcsConfig, GcsController

    ctrl = GcsController(GcsConfig(deltalab(), velocity=0.02, dynamics=dynamics), 0.0)
    ctrl.handle_line(b"MOV Z 2\n", 0.0)  # 2 mm up at 20 mm/s: 0.1 s on the line
    return ctrl


@pytest.mark.slow
def test_the_gcs_platform_follows_its_line_through_the_dynamic_robot() -> None:
    """The commanded straight line becomes the legs' position setpoints: the true pose
    lags it, POS? answers the true pose, ONT? says 0 until the legs have arrived and
    stopped, then the platform rests at the target (within 2 um)."""
    kin, dyn = _gcs(False), _gcs(True)
    for c in (kin, dyn):
        c.advance(0.05)
    assert kin.coords[2] == pytest.approx(0.001, abs=1e-9)  # half-way on the line
    z = dyn.coords[2]
    assert 0.0002 < z < 0.00099, z
    answer = dyn.handle_line(b"POS? Z\n", 0.05)
    assert float(answer.split("=")[1]) == pytest.approx(z * 1e3, abs=1e-6)
    dyn.advance(0.2)
    assert dyn.handle_line(b"ONT? Z\n", 0.2).strip() == "Z=0"
    dyn.advance(5.0)  # the integral action hunts against friction: settled after ~4 s
    assert dyn.coords[2] == pytest.approx(0.002, abs=2e-6)
    assert np.abs(dyn.coords[[0, 1, 3, 4, 5]]).max() < 1e-5
    assert dyn.handle_line(b"ONT? Z\n", 5.0).strip() == "Z=1"


@pytest.mark.slow
def test_the_gcs_console_script_takes_dynamics() -> None:
    import socket

    proc = subprocess.Popen([sys.executable, "-m", "hexapod.backends.emulator", "--gcs",
                             "--tcp", "127.0.0.1:0", "--dynamics"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        url = proc.stdout.readline().strip()
        host, _, port = url.removeprefix("tcp://").rpartition(":")
        sock = socket.create_connection((host, int(port)), timeout=5.0)
        sock.sendall(b"MOV Z 3\n")  # 3 mm at 10 mm/s: 0.3 s on the way
        time.sleep(0.03)
        sock.sendall(b"POS? Z\n")
        early = float(sock.recv(256).decode().split("=")[1])
        assert 0.0 < early < 2.9, early  # on its way, well short of the target
        deadline = time.monotonic() + 20.0  # on target by ~0.5 s; margin for a loaded CI
        while True:
            sock.sendall(b"ONT? Z\n")
            if sock.recv(256).decode().strip() == "Z=1" or time.monotonic() > deadline:
                break
            time.sleep(0.05)
        sock.sendall(b"POS? Z\n")
        late = float(sock.recv(256).decode().split("=")[1])
        assert late == pytest.approx(3.0, abs=0.02)
        sock.close()
    finally:
        proc.terminate()
        proc.wait(10)


@pytest.mark.slow
def test_the_axes_come_to_rest_and_an_idle_emulator_integrates_nothing() -> None:
    """Held at its setpoints, the robot comes to rest (the drives' integral action done)
    and the physics steps stop until the setpoints change (an idle emulator costs no
    CPU); the rest is within half a micrometre of the setpoints."""
    from hexapod.backends import emulator_dynamics as ed

    axes = ed.DynamicAxes(deltalab(), Q0)
    target = Q0 + STEP
    assert axes._resting, "at rest where it starts"
    axes.move(target, 0.05, 0.05)
    t = 0.05
    while not axes._resting and t < 10.0:
        axes.move(target, 0.05, 0.05)
        t += 0.05
    assert axes._resting and 1.0 < t < 10.0, t
    assert np.abs(axes.lengths - target).max() <= ed.REST_ERROR
    table, lengths = axes.robots.table.copy(), axes.lengths.copy()
    for _ in range(100):  # 5 s idle: not one physics step (the state's bits unchanged)
        axes.move(target, 0.05, 0.05)
    assert np.array_equal(axes.robots.table, table)
    assert np.array_equal(axes.lengths, lengths)
    axes.move(target + 0.001, 0.05, 0.05)  # a new setpoint wakes it
    assert not axes._resting and np.all(axes.lengths > lengths)
    assert not np.array_equal(axes.robots.table, table)


@pytest.mark.slow
def test_the_gcs_platform_at_rest_integrates_nothing() -> None:
    ctrl = _gcs(True)
    ctrl.advance(6.0)  # the line (0.1 s), then the hunting of the integral action
    for k in range(1, 30):
        ctrl.advance(6.0 + 0.05 * k)
    assert ctrl._axes is not None and ctrl._axes._resting
    z = ctrl.coords[2]
    assert z == pytest.approx(0.002, abs=2e-6)
    ctrl.advance(20.0)
    assert ctrl.coords[2] == z


def test_the_lean_physics_steps_give_the_same_bits_as_the_general_path() -> None:
    """:meth:`DynamicAxes._steps` (the row kept in the compiled table) against
    :meth:`DynamicAxes.step` one call a step: the same lengths, table and pose, bit for
    bit, over a wandering setpoint."""
    from hexapod.backends import emulator_dynamics as ed

    def run(lean: bool) -> tuple[np.ndarray, ...]:
        axes = ed.DynamicAxes(deltalab(), Q0)
        if not lean:
            def general(setpoints: np.ndarray, speed: float, n: int) -> None:
                for _ in range(n):
                    axes.step(setpoints, speed)

            axes._steps = general  # type: ignore[method-assign]
        out = [axes.move(Q0 + 0.003 * np.sin(0.05 * k + np.arange(6)), 0.05,
                         0.02 + 0.001 * (k % 3)) for k in range(60)]
        r = axes.robots
        return np.array(out), r.table.copy(), r.R.copy(), r.t.copy(), r.track_count.copy()

    for a, b in zip(run(False), run(True), strict=True):
        assert np.array_equal(a, b)


def _halt_after_motion(speed: float) -> tuple[Board, float]:
    """A dynamic board driven 0.6 s at ``speed`` [m/s] in 20 ms MOVs (legs alternately
    lengthening and shortening), then halted; returns it and the time of the HLT [s]."""
    g = deltalab()
    q = np.full(6, 0.4157)
    board = Board(BoardConfig.from_geometry(g, q, watchdog=1.0, dynamics=g), 0.0)
    assert board.handle("SVO 1", 0.0) == "OK"
    t = 0.0
    for _ in range(30):
        q = q + np.array([1, -1, 1, -1, 1, -1]) * speed * 0.02
        assert board.handle("MOV " + " ".join(protocol.format_mm(x) for x in q), t) == "OK"
        t += 0.02
        board.advance(t)
    assert board.moving
    assert board.handle("HLT", t) == "OK"
    return board, t


@pytest.mark.parametrize("speed", [0.005, 0.05])
def test_a_halted_dynamic_axis_reports_stopped_within_the_halt_band(speed: float) -> None:
    """After HLT the position loop's creep (micrometres, for seconds) is not motion: STA?
    answers moving=0 once every leg is within HALTED_ERROR of the halt position and slower
    than HALTED_SPEED, which took 0.01-0.17 s here (1.1-2.9 s with the arrival band of a
    MOV, ARRIVED and 1 um/s); it stays 0, and the next MOV uses the strict band again."""
    from hexapod.backends.emulator_board import HALTED_ERROR, HALTED_SPEED

    board, t_hlt = _halt_after_motion(speed)
    halted_at = board.setpoints.copy()
    t, stopped_at = t_hlt, None
    while t < t_hlt + 3.0:
        t += 0.002
        board.advance(t)
        sta = protocol.parse_sta(board.handle("STA?", t))
        if stopped_at is None and not sta.moving:
            stopped_at = t - t_hlt
            assert np.abs(board.lengths - halted_at).max() <= HALTED_ERROR
            assert np.abs(board._axes.leg_velocities()).max() <= HALTED_SPEED  # type: ignore[union-attr]
        elif stopped_at is not None:
            assert not sta.moving, f"moving again {t - t_hlt:.3f} s after the HLT"
    assert stopped_at is not None and stopped_at < 0.5, stopped_at
    # a new MOV, 1 um away: moving until it has arrived within ARRIVED (not the halt band)
    target = board.lengths + 1e-6
    board.handle("ERR?", t)  # the 1 s watchdog tripped meanwhile (STA? does not feed it)
    assert board.handle("MOV " + " ".join(protocol.format_mm(x) for x in target), t) == "OK"
    assert protocol.parse_sta(board.handle("STA?", t)).moving
