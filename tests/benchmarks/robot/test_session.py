"""Every way out of ``hexapod-bench servo`` (benchmarks.robot.session) halts the robot: one
test per exit path, on the emulators (a real pty or TCP port, real processes, signals to
a real process group). Each asserts that the ``HLT`` reached the emulator (its log), the
exit code, and the final record."""

from __future__ import annotations

import logging
import os
import signal
import socket
import time
from pathlib import Path

import numpy as np
import pytest

from benchmarks.robot import servo
from benchmarks.robot.exits import ServoExit
from tests.benchmarks.robot.sessions import (
    GOAL_MM,
    EmulatorProc,
    final,
    finish,
    goal_file,
    periods,
    start_pose_video,
    start_servo,
    wait_periods,
)

#: Wall-clock periods, signals and emulator processes: run alone (`make test`).
pytestmark = [pytest.mark.realtime, pytest.mark.slow]

# deadlines not enforced: these tests are about other exits (the machine may be loaded)
ANY_LATE = ["--max-missed-consecutive", "0", "--max-missed-fraction", "1"]
SLOW = ["-o", "gain=0.2", *ANY_LATE]  # never converges before the signal
FAST = ["-o", "gain=3", "--tolerance-mm", "0.5", "--max-steps", "150", *ANY_LATE]
# the emulators over a pty or TCP are real hardware to servo: the rendered camera by name
REAL_SIM_CAMERA = ["--camera", "sim", "--simulated-camera-on-real-robot"]
HALTED = "HLT: legs halted"  # the board emulator's log line
GCS_HALTED = "HLT: platform halted"


@pytest.mark.parametrize(("sig", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 143),
                                           (signal.SIGHUP, 129)])
def test_a_signal_halts_the_robot_and_exits_with_its_code(
        tmp_path: Path, sig: signal.Signals, code: int) -> None:
    emu = EmulatorProc(tmp_path / "emulator.log", "--pty")
    try:
        out = tmp_path / "session"
        proc = start_servo([*REAL_SIM_CAMERA, "--backend", f"serial:{emu.url}", "--goal",
                            str(goal_file(tmp_path)), *SLOW], out)
        wait_periods(proc, out, 10)
        os.killpg(proc.pid, sig)
        rc, stdout, stderr = finish(proc)
        assert rc == code, (stdout, stderr)
        assert f"stopped: {sig.name} received (exit {code}" in stdout
        assert "robot: halted and confirmed stopped" in stdout
        assert "missed periods" in stdout
        assert "Traceback" not in stderr
        log = emu.log()
        assert HALTED in log
        # the watchdog is armed with the first MOV: it never tripped before the HLT,
        # however long the first period took (it may trip after, the host gone)
        assert "watchdog tripped" not in log[:log.index(HALTED)]
        assert log.count(HALTED) == 1  # confirmed once: closing does not halt again
        assert "board watchdog: never tripped" in stdout
        rec = final(out)
        assert rec["watchdog_trips"] == rec["watchdog_clears"] == 0
        assert rec["exit_code"] == code and rec["reason"] == f"{sig.name} received"
        assert rec["halt_confirmed"] is True and rec["moved"] is True
        assert rec["signals"] == [sig.name]
        assert rec["periods"] == len(periods(out)) >= 10
    finally:
        emu.stop()


@pytest.mark.parametrize("kind", ["serial", "serial-tcp", "gcs"])
def test_the_link_killed_mid_motion_gives_the_link_exit_code_and_a_summary(
        tmp_path: Path, kind: str) -> None:
    """kill -9 of the emulator: exit 4 (not 2, "refused before moving"), the summary,
    and the robot NOT confirmed stopped, with how far the last MOV could take it."""
    options = {"serial": ["--pty"], "serial-tcp": ["--tcp", "127.0.0.1:0"],
               "gcs": ["--gcs", "--tcp", "127.0.0.1:0"]}[kind]
    emu = EmulatorProc(tmp_path / "emulator.log", *options)
    try:
        backend = f"gcs:{emu.url}" if kind == "gcs" else f"serial:{emu.url}"
        out = tmp_path / "session"
        proc = start_servo([*REAL_SIM_CAMERA, "--backend", backend, "--goal",
                            str(goal_file(tmp_path)),
                            *SLOW], out)
        wait_periods(proc, out, 10)
        emu.proc.kill()
        emu.proc.wait()
        rc, stdout, stderr = finish(proc)
        assert rc == ServoExit.LINK == 4, (stdout, stderr)
        assert "stopped: the link to the robot failed during motion" in stdout
        assert "after" in stdout and "missed periods" in stdout  # the summary
        assert "robot: NOT confirmed stopped" in stdout
        assert "the last command asked for at most" in stdout
        stopped = next(line for line in stdout.splitlines() if line.startswith("stopped:"))
        assert stopped.count("read failed") <= 1 and stopped.count(emu.url) <= 1, stopped
        rec = final(out)
        assert rec["exit_code"] == 4 and rec["halt_confirmed"] is False
        assert rec["exception"] is not None and rec["periods"] >= 10
    finally:
        emu.stop()


def test_a_stalled_link_is_a_link_failure_and_the_queued_hlt_is_confirmed(
        tmp_path: Path) -> None:
    """The board freezes for 2 s (stall fault): the exchange times out (exit 4), and the
    HLT queued during the stall runs when it ends: confirmed, not "could not halt"."""
    emu = EmulatorProc(tmp_path / "emulator.log", "--pty", "--stall-after", "40",
                       "--stall-ms", "2000")
    try:
        out = tmp_path / "session"
        proc = start_servo([*REAL_SIM_CAMERA, "--backend", f"serial:{emu.url}", "--goal",
                            str(goal_file(tmp_path)), *SLOW], out)
        rc, stdout, stderr = finish(proc, timeout=60)
        assert rc == 4, (stdout, stderr)
        assert "stopped: the link to the robot failed during motion" in stdout
        assert "robot: halted and confirmed stopped" in stdout
        assert "could not halt" not in stdout + stderr
        log = emu.log()
        assert "stalling for 2000 ms" in log and HALTED in log
        rec = final(out)
        assert rec["exit_code"] == 4 and rec["halt_confirmed"] is True
        assert "no reply" in rec["exception"] or "within" in rec["exception"]
    finally:
        emu.stop()


def test_a_board_that_never_answers_is_sent_hlt_and_the_record_says_so(tmp_path: Path
                                                                        ) -> None:
    """A board that hears but never answers ``*IDN?`` (``--silent-after 0``): the session
    is refused (exit 2), the board was sent ``HLT`` on the way out, and both the
    ``robot:`` line and the record's ``halt_detail`` say so (they said "not connected"
    only, the HLT a warning on stderr)."""
    emu = EmulatorProc(tmp_path / "emulator.log", "--tcp", "127.0.0.1:0", "--silent-after",
                       "0")
    try:
        out = tmp_path / "session"
        proc = start_servo([*REAL_SIM_CAMERA, "--backend", f"serial:{emu.url}", "--goal",
                            str(goal_file(tmp_path)), *SLOW], out)
        rc, stdout, stderr = finish(proc)
        assert rc == ServoExit.REFUSED == 2, (stdout, stderr)
        said = "HLT sent on the way out, not acknowledged"
        assert f"robot: not connected ({emu.url}: {said})" in stdout, stdout
        rec = final(out)
        assert rec["halt_confirmed"] is None and said in rec["halt_detail"]
        assert "HLT" in emu.log()
    finally:
        emu.stop()


def test_a_second_client_is_told_the_controller_is_busy(tmp_path: Path) -> None:
    emu = EmulatorProc(tmp_path / "emulator.log", "--gcs", "--tcp", "127.0.0.1:0")
    host, port = emu.url.removeprefix("tcp://").rsplit(":", 1)
    first = socket.create_connection((host, int(port)))  # another program holds it
    try:
        time.sleep(0.2)
        out = tmp_path / "session"
        proc = start_servo([*REAL_SIM_CAMERA, "--backend", f"gcs:{emu.url}", "--goal",
                            str(goal_file(tmp_path)), *SLOW], out)
        rc, stdout, stderr = finish(proc)
        assert rc == ServoExit.REFUSED == 2, (stdout, stderr)
        assert "busy with another client" in stderr and "refused the connection" in stderr
        # one message, once; no HLT tried on a connection that never came up
        assert (stdout + stderr).count("busy with another client") == 1, (stdout, stderr)
        assert "HLT" not in stderr and "Broken pipe" not in stderr
        assert "robot: not connected" in stdout
        assert "refused a connection" in emu.log()
        rec = final(out)
        assert rec["exit_code"] == 2 and rec["moved"] is False
        assert rec["halt_confirmed"] is None
    finally:
        first.close()
        emu.stop()


@pytest.mark.parametrize(("retries", "code"), [(None, 0), ("0", 4)])
def test_one_dropped_reply_is_survived_by_default(
        tmp_path: Path, retries: str | None, code: int) -> None:
    """Replies dropped (seeded: the first at the 36th command, never two in a row): the
    default --retries 1 converges; --retries 0 ends at the first with the link exit code."""
    emu = EmulatorProc(tmp_path / "emulator.log", "--pty", "--drop", "0.02", "--seed", "0")
    try:
        out = tmp_path / "session"
        extra = [] if retries is None else ["--retries", retries]
        proc = start_servo([*REAL_SIM_CAMERA, "--backend", f"serial:{emu.url}", "--goal",
                            str(goal_file(tmp_path)), *FAST, *extra], out)
        rc, stdout, stderr = finish(proc, timeout=90)
        assert rc == code, (stdout, stderr)
        rec = final(out)
        assert rec["exit_code"] == code
        assert HALTED in emu.log()
        assert rec["halt_confirmed"] is True
        if code == 0:
            assert rec["retries"] >= 1 and "converged after" in stdout
            # each lost reply (a 200 ms wait) tripped the 100 ms watchdog: seen and counted
            trips = rec["watchdog_trips"]
            assert trips == rec["watchdog_clears"] >= 1
            assert stderr.count("the board's watchdog tripped") == trips
            assert f"board watchdog: tripped {trips} time(s) during motion" in stdout
            retried = [line for line in stderr.splitlines() if "retry 1/1" in line]
            assert retried and all(line.count(emu.url) == 1 for line in retried), retried
        else:
            assert "no reply" in rec["exception"] or "within" in rec["exception"]
    finally:
        emu.stop()


# --------------------------------------------------------------- in this process
def _run(tmp_path: Path, caplog: pytest.LogCaptureFixture, *args: str,
         goal: list[float] = GOAL_MM) -> tuple[int, Path]:
    """``servo.main`` against the in-process emulator (its log captured)."""
    out = tmp_path / "session"
    with caplog.at_level(logging.INFO, logger="hexapod.backends.emulator_board"):
        code = servo.main(["--backend", "emulator", "--goal", str(goal_file(tmp_path, goal)),
                           "--out", str(out), *args])
    return code, out


def test_the_end_of_a_recording_halts_with_the_limit_code(
        tmp_path: Path, caplog: pytest.LogCaptureFixture,
        capsys: pytest.CaptureFixture[str]) -> None:
    video = start_pose_video(tmp_path)
    code, out = _run(tmp_path, caplog, "--camera", f"video:{video}", "--max-steps", "50")
    stdout = capsys.readouterr().out
    assert code == ServoExit.LIMIT == 3, stdout
    assert f"stopped: the recording video:{video} ended after 8 periods" in stdout
    assert HALTED in caplog.text
    rec = final(out)
    assert rec["exit_code"] == 3 and rec["halt_confirmed"] is True
    rows = periods(out)
    assert len(rows) == rec["periods"] == 8
    # the end of the file is not a lost frame: the summary agrees with the rows
    assert rec["lost_frames"] == sum(r["lost_frames"] for r in rows) == 0
    assert "0 lost frames" in stdout
    assert "stopped after 8 periods" in stdout  # the summary in user words
    # nor does the camera check call it one (it checked every period with an image)
    assert "lost frame" not in caplog.text and "no camera pose" not in caplog.text
    assert rec["checks"][0].startswith("camera check: 8 periods checked"), rec["checks"]


def test_the_time_limit_halts_with_the_limit_code(
        tmp_path: Path, caplog: pytest.LogCaptureFixture,
        capsys: pytest.CaptureFixture[str]) -> None:
    code, out = _run(tmp_path, caplog, *SLOW, "--max-time-s", "0.5")
    stdout = capsys.readouterr().out
    assert code == 3, stdout
    assert "stopped: --max-time-s 0.5 reached after" in stdout
    assert HALTED in caplog.text
    rec = final(out)
    assert rec["exit_code"] == 3 and rec["reason"].startswith("--max-time-s 0.5 reached")
    assert 0.5 <= periods(out)[-1]["t_s"] < 1.5


def test_the_travel_limit_stops_before_the_command_is_sent(
        tmp_path: Path, caplog: pytest.LogCaptureFixture,
        capsys: pytest.CaptureFixture[str]) -> None:
    """A controller driving away from its goal (negative gain) meets --max-travel-mm 1:
    no leg ever goes farther than 1 mm from its start length."""
    goal = [415.3] * 6
    code, out = _run(tmp_path, caplog, "--controller",
                     "tests.benchmarks.plugins:ProportionalJoints", "-o", "gain=-5",
                     "--max-travel-mm", "1", *ANY_LATE, goal=goal)
    stdout = capsys.readouterr().out
    assert code == 3, stdout
    assert "stopped: --max-travel-mm 1 reached: leg" in stdout
    assert HALTED in caplog.text
    rows = periods(out)
    start = np.array(final(out)["start_lengths_mm"])
    travel = np.max(np.abs(np.array([r["lengths_mm"] for r in rows]) - start))
    assert 0.5 < travel <= 1.0 + 1e-3
    assert final(out)["exit_code"] == 3


def test_a_goal_beyond_the_travel_limit_is_refused_before_moving(
        tmp_path: Path, caplog: pytest.LogCaptureFixture,
        capsys: pytest.CaptureFixture[str]) -> None:
    code, out = _run(tmp_path, caplog, "--max-travel-mm", "1")
    stdout = capsys.readouterr().out
    assert code == 2, stdout
    assert "--max-travel-mm 1: the goal is 2.500 mm away on leg 0" in stdout
    assert "refused before moving" in stdout
    rec = final(out)
    assert rec["exit_code"] == 2 and rec["moved"] is False and periods(out) == []


def test_missed_deadlines_stop_the_session(
        tmp_path: Path, caplog: pytest.LogCaptureFixture,
        capsys: pytest.CaptureFixture[str]) -> None:
    """A 1 ms period no camera and controller can keep: 10 late periods in a row stop it,
    and every row holds the compute and link times that say why."""
    code, out = _run(tmp_path, caplog, "-o", "gain=0.2", "--dt", "0.001")
    stdout = capsys.readouterr().out
    assert code == 3, stdout
    assert "stopped: --max-missed-consecutive 10 reached" in stdout
    assert "warning: " in stdout and "late period" in stdout
    assert HALTED in caplog.text
    rec = final(out)
    rows = periods(out)
    assert rec["missed_periods"] == sum(r["missed"] for r in rows) >= 10
    assert all(r["compute_ms"] > 0 and r["link_ms"] > 0 for r in rows)


def test_an_exception_in_the_controller_halts_with_the_internal_code(
        tmp_path: Path, caplog: pytest.LogCaptureFixture,
        capsys: pytest.CaptureFixture[str]) -> None:
    code, out = _run(tmp_path, caplog, "--controller",
                     "tests.benchmarks.plugins:CrashAtStep", "-o", "crash_step=3",
                     *ANY_LATE)
    captured = capsys.readouterr()
    assert code == ServoExit.INTERNAL == 1, captured.out
    assert "stopped: internal error: RuntimeError: deliberate crash" in captured.out
    assert "robot: halted and confirmed stopped" in captured.out
    assert "Traceback" in captured.err
    assert HALTED in caplog.text
    rec = final(out)
    assert rec["exception"] == "RuntimeError: deliberate crash at call 4"
    assert "deliberate crash" in rec["traceback"] and rec["halt_confirmed"] is True


def test_confirm_refuses_without_a_terminal(
        tmp_path: Path, caplog: pytest.LogCaptureFixture,
        capsys: pytest.CaptureFixture[str]) -> None:
    """Known before anything is opened: refused then, with no record and the robot not
    contacted (the port was opened, the plan printed, then HLT sent)."""
    code, out = _run(tmp_path, caplog, "--confirm")
    captured = capsys.readouterr()
    assert code == 2, captured
    assert "--confirm asks y/N on a terminal and stdin is not one: refused before anything " \
           "is opened" in captured.err
    assert "planned move" not in captured.out and not out.exists()
    assert "HLT" not in caplog.text  # the emulator was never started


def test_the_speed_cap_is_applied_logged_and_the_step_budget_is_a_limit(
        tmp_path: Path, caplog: pytest.LogCaptureFixture,
        capsys: pytest.CaptureFixture[str]) -> None:
    """--max-speed-mm-s 1: the controller's 8 mm/s command is logged as commanded, 1 mm/s
    as applied, the leg flagged clamped; a cap above the robot file's is capped to it."""
    code, out = _run(tmp_path, caplog, *FAST[:2], "--max-speed-mm-s", "1", "--max-steps",
                     "5", *ANY_LATE)
    stdout = capsys.readouterr().out
    assert code == ServoExit.LIMIT, stdout
    assert "stopped: --max-steps 5 reached (exit 3, limit)" in stdout
    assert "speed <= 1 mm/s" in stdout
    assert HALTED in caplog.text
    rows = periods(out)
    assert len(rows) == final(out)["periods"] == 5
    first = rows[0]
    assert max(abs(x) for x in first["commanded_mm_s"]) > 5
    assert max(abs(x) for x in first["applied_mm_s"]) <= 1 + 1e-9
    assert all(c == (abs(v) > 1) for c, v in zip(first["clamped"], first["commanded_mm_s"],
                                                 strict=True))
    (tmp_path / "b").mkdir()
    code, _ = _run(tmp_path / "b", caplog, "--max-speed-mm-s", "500", "--max-steps", "1",
                   *ANY_LATE)
    stdout = capsys.readouterr().out
    assert ("--max-speed-mm-s 500 is above the robot file's max_speed_mm_s 50: capped to 50 "
            "mm/s") in stdout
    assert "speed <= 50 mm/s" in stdout


def test_the_emulator_prints_and_logs_the_same_url(tmp_path: Path) -> None:
    for options in (["--pty"], ["--gcs", "--tcp", "127.0.0.1:0"], ["--tcp", "127.0.0.1:0"]):
        emu = EmulatorProc(tmp_path / "emulator.log", *options)
        try:
            time.sleep(0.1)
            assert f"emulator serving on {emu.url}\n" in emu.log()
        finally:
            emu.stop()


def test_a_period_check_ends_the_session_with_its_code(
        tmp_path: Path, caplog: pytest.LogCaptureFixture, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The seam of the safety checks (camera consistency, blind camera): a PeriodCheck
    called each period with the measured lengths and the features, raising
    SessionStop(SAFETY, reason), ends the session through the shutdown with exit 5."""
    from benchmarks.robot import session
    from benchmarks.robot.exits import SessionStop

    seen: list[tuple[int, np.ndarray, object]] = []

    def check(step: int, lengths: np.ndarray, features: object) -> None:
        seen.append((step, lengths, features))
        if step == 4:
            raise SessionStop(ServoExit.SAFETY, "the camera disagrees with the encoders")

    def run_session(*args: object, checks: tuple[object, ...] = (), **kw: object) -> int:
        return session.run_session(*args, checks=[check, *checks], **kw)  # type: ignore

    monkeypatch.setattr(servo, "run_session", run_session)
    code, out = _run(tmp_path, caplog, *SLOW)
    stdout = capsys.readouterr().out
    assert code == ServoExit.SAFETY == 5, stdout
    assert "stopped: the camera disagrees with the encoders (exit 5, safety)" in stdout
    assert HALTED in caplog.text
    assert [s for s, _, _ in seen] == [0, 1, 2, 3, 4]
    assert seen[0][1].shape == (6,) and seen[0][2] is not None
    rec = final(out)
    assert rec["exit_code"] == 5 and rec["halt_confirmed"] is True
    assert len(periods(out)) == 4  # the command of period 4 was never sent


def _on_a_terminal(args: list[str], answer: bytes | signal.Signals, out: Path,
                   raw: bool = False) -> tuple[int, str]:
    """``servo ARGS --out OUT`` with a pseudo-terminal as stdin and stdout: wait for the
    --confirm question, answer (or send the signal to its process group), and return the
    exit code and everything shown (its lines unwrapped, or ``raw``)."""
    import pty
    import select
    import subprocess
    import sys

    from tests.benchmarks.robot.sessions import ENV, ROOT

    master, slave = pty.openpty()
    proc = subprocess.Popen([sys.executable, "-m", "benchmarks.robot.servo", *args, "--out",
                             str(out)], stdin=slave, stdout=slave, stderr=slave, cwd=ROOT,
                            env=ENV, start_new_session=True)
    os.close(slave)
    shown = b""
    answered = False
    deadline = time.monotonic() + 60
    try:
        while time.monotonic() < deadline:
            ready, _, _ = select.select([master], [], [], 0.1)
            if ready:
                try:
                    chunk = os.read(master, 4096)
                except OSError:  # the child closed the terminal
                    break
                if not chunk:
                    break
                shown += chunk
            if not answered and b"move the robot? [y/N]" in shown:
                if isinstance(answer, signal.Signals):
                    os.killpg(proc.pid, answer)
                else:
                    os.write(master, answer)
                answered = True
            if proc.poll() is not None and not ready:
                break
        code = proc.wait(30)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
        os.close(master)
    text = shown.decode(errors="replace")
    assert answered, text
    if raw:
        return code, text
    return code, " ".join(text.split())  # the lines the terminal's width wrapped, unwrapped


def test_ctrl_c_at_the_confirm_question_stops_on_a_line_of_its_own(tmp_path: Path) -> None:
    """(It printed 'move the robot? [y/N] stopped: ...' on one line.)"""
    out = tmp_path / "session"
    rc, shown = _on_a_terminal(["--backend", "emulator", "--goal", str(goal_file(tmp_path)),
                                "--confirm", *FAST], signal.SIGINT, out, raw=True)
    assert rc == 130, shown
    assert "move the robot? [y/N] \r\nstopped: SIGINT received" in shown, repr(shown)
    assert final(out)["moved"] is False


@pytest.mark.parametrize(("answer", "code"), [(b"y\n", 0), (b"n\n", 2)])
def test_confirm_on_a_terminal_moves_only_after_yes(
        tmp_path: Path, answer: bytes, code: int) -> None:
    out = tmp_path / "session"
    rc, shown = _on_a_terminal(["--backend", "emulator", "--goal", str(goal_file(tmp_path)),
                                "--confirm", *FAST], answer, out)
    assert rc == code, shown
    assert "largest leg travel 2.500 mm (leg 0)" in shown
    rec = final(out)
    assert rec["exit_code"] == code
    if code == 0:
        assert rec["moved"] is True and "converged after" in shown
    else:
        assert rec["moved"] is False and periods(out) == []
        assert "the planned move was not confirmed" in shown


def test_a_goal_outside_the_boards_own_stroke_is_refused_before_moving(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The board's LIM? says [400, 430] mm where the robot file says [345, 485]: the
    difference is warned of, and a goal with a leg at 435 mm (inside the file's stroke) is
    refused before any MOV (it held the leg at its end stop until the time limit)."""
    from hexapod import deltalab
    from hexapod.backends.emulator import BoardConfig, Emulator

    emu = Emulator(BoardConfig.from_geometry(deltalab(), np.full(6, 0.415),
                                             stroke=(0.400, 0.430))).start()
    try:
        goal = [435.0, 411.0, 419.0, 412.0, 418.0, 410.0]
        code = servo.main([*REAL_SIM_CAMERA, "--backend", f"serial:{emu.device}", "--goal",
                           str(goal_file(tmp_path, goal)), "--out", str(tmp_path / "s"),
                           *ANY_LATE])
        stdout = capsys.readouterr().out
        assert code == ServoExit.REFUSED == 2, stdout
        assert ("the robot's controller reports the stroke [400.000, 430.000] mm, the robot "
                "file [345.000, 485.000] mm") in stdout
        assert ("the goal's leg 0 at 435.000 mm is outside the stroke the robot's controller "
                "reports, [400.000, 430.000] mm: refused before moving") in stdout
        assert final(tmp_path / "s")["moved"] is False
        assert "MOV" not in emu.board.last_command
        np.testing.assert_allclose(emu.board.lengths, 0.415)
    finally:
        emu.stop()


def test_a_signal_during_the_start_up_is_not_lost_and_moves_nothing(
        tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    """SIGINT arrives while the goal's features are computed (compiled code, where a
    KeyboardInterrupt was once swallowed and the session then ran to its end with exit
    0): it is held, taken at the next stage, and the run ends with 130 before the robot
    is opened; the handlers in place before are back."""
    from benchmarks.robot import goals

    real = goals.goal_features

    def signalled(*args: object, **kwargs: object) -> object:
        os.kill(os.getpid(), signal.SIGINT)  # delivered now, inside the stage
        return real(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(servo, "goal_features", signalled)
    before = signal.getsignal(signal.SIGINT)
    code = servo.main(["--backend", "emulator", "--goal", str(goal_file(tmp_path)),
                       "--out", str(tmp_path / "s")])
    out = capsys.readouterr().out
    assert code == ServoExit.INTERRUPTED == 130, out
    assert ("stopped: SIGINT received before the session began: the robot was not moved "
            "(exit 130, interrupted)") in out
    assert not (tmp_path / "s").exists()  # nothing opened, no record
    assert signal.getsignal(signal.SIGINT) is before


def test_an_unconfirmed_halt_after_force_commands_does_not_claim_a_travel() -> None:
    """The halt's line gave the last command's travel as its velocities times the period;
    after leg forces (no velocities: zeros) it said '0.000 mm of leg travel'."""
    from benchmarks.robot.limits import LimitedRobot, SessionLimits
    from benchmarks.robot.session import _last_move
    from hexapod.actuation import Actuation

    robot = LimitedRobot(object(), SessionLimits(0.05, None), np.full(6, 0.4))
    assert _last_move(robot) == "no motion was commanded"
    robot.moved, robot.last_dt = True, 0.02
    robot.last_applied = np.array([0.0, 0.003, 0.0, 0.0, -0.001, 0.0])
    assert _last_move(robot).startswith("the last command asked for at most 0.060 mm")
    robot.last_actuation = Actuation.FORCE
    assert "leg forces" in _last_move(robot) and " mm" not in _last_move(robot)
