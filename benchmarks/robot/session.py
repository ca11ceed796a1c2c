"""One servo session from the connection to the final record, with one way out.

:func:`run_session` opens the camera and the robot, shows the banner (and with
``--confirm`` the planned move), runs :func:`~benchmarks.robot.loop.servo_loop` under the
session's limits and signal handlers, and whatever ends it (convergence, a limit, the end
of a recording, a signal, a lost link, an exception anywhere) goes through the same
shutdown: the robot's stop commanded and its confirmation awaited
(:meth:`~hexapod.backends.base.Backend.halt_confirmed`, ``--halt-timeout-s``), the link
closed, what happened and whether the robot is confirmed stopped printed, the final
record written, and the exit code (:class:`~benchmarks.robot.exits.ServoExit`) returned.
"""

from __future__ import annotations

import argparse
import contextlib
import datetime as dt
import signal
import sys
import traceback
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from benchmarks.exceptions import BenchmarkError
from benchmarks.robot.exits import ServoExit, SessionStop, SignalGuard, exit_for_signal
from benchmarks.robot.limits import LimitedRobot, SessionLimits
from benchmarks.robot.loop import PeriodCheck, servo_loop
from benchmarks.robot.models import check_option, describe_camera
from benchmarks.robot.records import SessionLog, mm_list, session_path
from benchmarks.robot.status import PeriodStatus, ServoResult, StatusLine
from hexapod.actuation import Actuation
from hexapod.backends.base import HaltReport
from hexapod.exceptions import BackendError
from hexapod.geometry import HexapodGeometry
from hexapod.link_errors import LinkError, ProtocolError, RobotFaultError

#: Default ``--halt-timeout-s`` [s]: how long the shutdown waits for the robot to
#: confirm its stop (longer than a 2 s stall of the link plus the time to detect it).
DEFAULT_HALT_TIMEOUT_S = 3.0
#: Default ``--retries``: an exchange whose reply is lost is sent again this many times.
DEFAULT_RETRIES = 1


@dataclass
class SessionInputs:
    """What :func:`run_session` needs, checked before anything is opened: the nominal
    robot, the camera model, the goal file (:class:`~benchmarks.robot.goals.ServoGoal`),
    the controller's goal, the reset controller and (a simulated robot only) the
    initial leg lengths [m]."""

    geometry: HexapodGeometry
    camera: Any
    goal_file: Any
    goal: Any
    controller: Any
    start: np.ndarray | None


def session_limits(args: argparse.Namespace, geometry: HexapodGeometry,
                   warn: Any) -> SessionLimits:
    """The limits of the command line, the robot file's speed limit as the ceiling (a
    ``--max-speed-mm-s`` above it is capped, with a ``warn``-ing).

    Raises:
        BenchmarkError: A limit that is not a positive number.
    """
    for flag, value in (("--max-speed-mm-s", args.max_speed_mm_s),
                        ("--max-travel-mm", args.max_travel_mm),
                        ("--max-time-s", args.max_time_s)):
        check_option(flag, value)
    check_option("--max-missed-consecutive", args.max_missed_consecutive, strict=False,
                 note=" (0: never)")
    if not 0 <= args.max_missed_fraction <= 1:
        raise BenchmarkError(f"--max-missed-fraction must be in [0, 1] (1: never), got "
                             f"{args.max_missed_fraction}")
    check_option("--halt-timeout-s", args.halt_timeout_s, finite=True)
    check_option("--retries", args.retries, strict=False)
    ceiling = cap = geometry.max_speed
    if args.max_speed_mm_s is not None and args.max_speed_mm_s * 1e-3 > ceiling:
        warn(f"warning: --max-speed-mm-s {args.max_speed_mm_s:g} is above the robot file's "
             f"max_speed_mm_s {ceiling * 1e3:g}: capped to {ceiling * 1e3:g} mm/s")
    elif args.max_speed_mm_s is not None:
        cap = args.max_speed_mm_s * 1e-3
    return SessionLimits(
        max_speed=cap,
        max_travel=None if args.max_travel_mm is None else args.max_travel_mm * 1e-3,
        max_time=float(args.max_time_s), max_steps=args.max_steps,
        max_missed_consecutive=args.max_missed_consecutive,
        max_missed_fraction=float(args.max_missed_fraction))


def _header(args: argparse.Namespace, inputs: SessionInputs,
            limits: SessionLimits) -> dict[str, Any]:
    return {"started": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
            "argv": sys.argv[1:], "backend": args.backend, "camera": args.camera,
            "camera_file": args.camera_file, "camera_pose": args.camera_pose,
            "controller": args.controller, "options": list(args.option),
            "goal": str(inputs.goal_file.source),
            "goal_lengths_mm": mm_list(inputs.goal_file.lengths),
            "geometry": args.geometry, "dt_s": args.dt, "limits": limits.to_json(),
            "halt_timeout_s": args.halt_timeout_s, "retries": args.retries}


def _plan(args: argparse.Namespace, q0: np.ndarray, goal_q: np.ndarray,
          limits: SessionLimits, say: Any) -> None:
    """The travel limit against the goal, and ``--confirm``.

    Raises:
        SessionStop: Refused before moving (exit 2).
    """
    travel = np.abs(goal_q - q0)
    leg = int(np.argmax(travel))
    if limits.max_travel is not None and travel[leg] > limits.max_travel:
        raise SessionStop(ServoExit.REFUSED, (
            f"--max-travel-mm {limits.max_travel * 1e3:g}: the goal is {travel[leg] * 1e3:.3f} "
            f"mm away on leg {leg} ({q0[leg] * 1e3:.3f} -> {goal_q[leg] * 1e3:.3f} mm); "
            "refused before moving"))
    if not args.confirm:
        return
    mm = np.round(q0 * 1e3, 3).tolist()
    gmm = np.round(goal_q * 1e3, 3).tolist()
    cap = limits.max_speed
    say(f"planned move: start {mm} mm -> goal {gmm} mm; largest leg travel "
        f"{travel[leg] * 1e3:.3f} mm (leg {leg}), at least {travel[leg] / cap:.2f} s at "
        f"{cap * 1e3:g} mm/s; limits: travel "
        f"{'none' if limits.max_travel is None else f'{limits.max_travel * 1e3:g} mm'}, "
        f"time {limits.max_time:g} s")
    if not sys.stdin.isatty():
        raise SessionStop(ServoExit.REFUSED, "--confirm asks y/N on a terminal and stdin is "
                                             "not one: refused before moving")
    try:
        answer = _ask("move the robot? [y/N] ")
    except SessionStop:  # Ctrl-C at the question: the stop's line on a line of its own
        print(flush=True)
        raise
    if answer.strip().lower() not in ("y", "yes"):
        raise SessionStop(ServoExit.REFUSED, "the planned move was not confirmed: refused "
                                             "before moving")


def _ask(prompt: str) -> str:
    """A line typed on the terminal ("" at its end), waited for in short selects: a
    signal then runs its handler within 0.2 s even when the kernel gave it to another
    thread (an in-process emulator's), where a blocking ``input()`` kept reading."""
    import select

    print(prompt, end="", flush=True)
    while True:
        ready, _, _ = select.select([sys.stdin], [], [], 0.2)
        if ready:
            return sys.stdin.readline()


def _start_reading(robot: Any, geometry: Any) -> np.ndarray:
    """The robot's first reading, checked before anything uses it (the goal and travel
    checks, the record): five values crashed the session with a traceback, None lost
    its final record.

    Raises:
        SessionStop: ``SAFETY``: not six plausible leg lengths (the robot is halted by
            the session's shutdown).
    """
    from hexapod.plausible import reading_problem

    raw = robot.measured_lengths()
    problem = reading_problem(raw, geometry.stroke)
    if problem is not None:
        raise SessionStop(ServoExit.SAFETY, f"at the start: {problem}")
    return np.asarray(raw, float).copy()


def _check_board(robot: Any, geometry: HexapodGeometry, goal_q: np.ndarray,
                 say: Any) -> None:
    """The robot file against what the controller says of itself (``stroke``,
    ``max_speed``, e.g. a serial board's ``LIM?``): a difference is warned of, and a goal
    outside the controller's own stroke refused (it would hold a leg at its end stop
    until a time limit).

    Raises:
        SessionStop: The goal outside the controller's stroke (exit 2, before moving).
    """
    stroke = getattr(robot, "stroke", None)
    if stroke is None:
        return
    lo, hi = (float(x) for x in stroke)
    file_lo, file_hi = geometry.stroke
    if abs(lo - file_lo) > 1e-6 or abs(hi - file_hi) > 1e-6:
        say(f"warning: the robot's controller reports the stroke [{lo * 1e3:.3f}, "
            f"{hi * 1e3:.3f}] mm, the robot file [{file_lo * 1e3:.3f}, {file_hi * 1e3:.3f}] "
            "mm: the controller's holds (check the robot file)")
    speed = getattr(robot, "max_speed", None)
    if speed is not None and abs(float(speed) - geometry.max_speed) > 1e-6:
        say(f"warning: the robot's controller reports the speed limit "
            f"{float(speed) * 1e3:g} mm/s, the robot file {geometry.max_speed * 1e3:g} mm/s")
    outside = np.flatnonzero((goal_q < lo - 1e-9) | (goal_q > hi + 1e-9))
    if outside.size:
        leg = int(outside[0])
        raise SessionStop(ServoExit.REFUSED, (
            f"the goal's leg {leg} at {goal_q[leg] * 1e3:.3f} mm is outside the stroke the "
            f"robot's controller reports, [{lo * 1e3:.3f}, {hi * 1e3:.3f}] mm: refused "
            "before moving"))


def _classify(exc: BaseException, moved: bool) -> tuple[ServoExit, str]:
    """The exit code and reason of what ended the session."""
    from controllers.exceptions import ControllerError
    from hexapod.exceptions import HexapodError
    from vision.exceptions import VisionError

    if isinstance(exc, SessionStop):
        return exc.code, exc.reason
    if isinstance(exc, KeyboardInterrupt):
        return ServoExit.INTERRUPTED, "SIGINT received"
    if isinstance(exc, LinkError | ProtocolError | RobotFaultError):
        if moved:
            return ServoExit.LINK, f"the link to the robot failed during motion: {exc}"
        return ServoExit.REFUSED, str(exc)
    if isinstance(exc, BenchmarkError | HexapodError | ControllerError | VisionError):
        if not moved:
            return ServoExit.REFUSED, str(exc)
        if isinstance(exc, BackendError):
            return ServoExit.LINK, f"the robot failed during motion: {exc}"
    return ServoExit.INTERNAL, f"internal error: {type(exc).__name__}: {exc}"


def _halt(robot: Any, timeout_s: float) -> HaltReport:
    """The robot's stop and its confirmation; a plugin without
    :meth:`~hexapod.backends.base.Backend.halt_confirmed`, or one that raises, is
    reported, never raised."""
    confirm = getattr(robot, "halt_confirmed", None)
    try:
        if confirm is not None:
            report: HaltReport = confirm(timeout_s)
            return report
        robot.halt()
        return HaltReport(False, "halt() returned; this backend does not report whether the "
                                 "robot stopped")
    except Exception as exc:
        return HaltReport(False, f"halting failed: {type(exc).__name__}: {exc}")


def _last_move(limited: LimitedRobot | None) -> str:
    if limited is None or not limited.moved:
        return "no motion was commanded"
    if limited.last_actuation is not Actuation.VELOCITY:
        return ("the last command was leg forces: how far they can still move the legs is "
                "not known here")
    v = float(np.max(np.abs(limited.last_applied)))
    return (f"the last command asked for at most {v * limited.last_dt * 1e3:.3f} mm of leg travel "
            f"beyond the lengths measured before it ({v * 1e3:.1f} mm/s over one "
            f"{limited.last_dt * 1e3:g} ms period)")


def _figures(result: ServoResult) -> dict[str, Any]:
    def pct(values: list[float], q: float) -> float | None:
        return float(np.percentile(np.array(values) * 1e3, q)) if values else None

    last: PeriodStatus | None = result.last
    return {"periods": result.steps, "missed_periods": result.missed,
            "lost_frames": result.lost_frames, "refused_commands": result.refused,
            "wall_s": round(result.wall_s, 6),
            "rtt_median_ms": pct(result.rtts, 50), "rtt_p99_ms": pct(result.rtts, 99),
            "compute_median_ms": pct(result.compute, 50),
            "compute_p99_ms": pct(result.compute, 99),
            "final_lengths_mm": None if last is None else mm_list(last.lengths),
            "final_leg_error_mm": None if last is None else last.leg_error * 1e3,
            "final_feature_error": None if last is None else last.feature_error}


def _outcome(result: ServoResult, args: argparse.Namespace) -> tuple[ServoExit, str]:
    if result.outcome == "converged":
        return ServoExit.CONVERGED, "converged"
    if result.outcome == "camera ended":
        return ServoExit.LIMIT, f"the recording {args.camera} ended after {result.steps} periods"
    if result.outcome == "interrupted":
        return ServoExit.INTERRUPTED, "SIGINT received"
    if result.stop is not None:
        return result.stop.code, result.stop.reason
    return ServoExit.LIMIT, f"--max-steps {args.max_steps} reached"


def run_session(args: argparse.Namespace, inputs: SessionInputs, status: StatusLine,
                on_pose: Any = None, checks: Sequence[PeriodCheck] = (),
                guard: SignalGuard | None = None) -> int:
    """Run one session (see the module docstring); returns the exit code.

    Args:
        args: The parsed options of ``hexapod-bench servo``.
        inputs: What was checked before anything is opened.
        status: The status line.
        on_pose: The viewer's hook (``--viz``), or None.
        checks: Per-period safety checks (:class:`~benchmarks.robot.loop.PeriodCheck`),
            after the signal check: the camera check. A check with a ``summary()`` method
            has its line printed after the session's summary and in the final record.
        guard: The caller's signal guard, already entered (``servo`` installs it
            before its start-up, so that a signal then is not lost): a signal it holds
            ends the session before anything is opened. None: the session's own.

    Raises:
        OutputError: The record cannot be placed (``--out``, ``--log``), before anything
            is opened.
        BenchmarkError: A bad limit, before anything is opened.
    """
    from benchmarks.robot.servo import open_backend
    from vision.feature_cameras import open_camera

    limits = session_limits(args, inputs.geometry, status.message)
    log = SessionLog(session_path(args.out, args.log, args.controller))
    result = ServoResult("not started", 0, 0.0)
    robot: Any = None
    limited: LimitedRobot | None = None
    q0: np.ndarray | None = None  # the lengths read at the start (also of a refused move)
    sensor: Any = None
    ended: BaseException | None = None
    own = guard is None
    guard = SignalGuard(status.message) if guard is None else guard
    guard.say = status.message
    guard.in_loop = False  # until the loop, a signal stops the session at once

    def on_period(s: PeriodStatus) -> None:  # the status line and the log line
        status(s)
        log.write(s.to_json())

    with guard if own else contextlib.nullcontext(guard):
        try:
            log.open(_header(args, inputs, limits))
            guard.check()  # a signal the start-up held: stop before anything is opened
            sensor = open_camera(args.camera, inputs.camera, inputs.geometry, args.seed)
            robot = open_backend(args.backend, inputs.geometry, inputs.start)
            if hasattr(robot, "timeout_retries"):
                robot.timeout_retries = args.retries
            seen_by = describe_camera(args.camera, args.camera_file, args.camera_pose,
                                      inputs.camera)
            status.message(
                f"servo: {args.controller} on {args.backend}"
                f"{f' ({robot.identity})' if robot.identity else ''}, {seen_by}, "
                f"goal {inputs.goal_file.source}, dt {args.dt * 1e3:g} ms; speed <= "
                f"{limits.max_speed * 1e3:g} mm/s, time <= {limits.max_time:g} s; record "
                f"{log.path}; Ctrl-C, SIGTERM or SIGHUP halt the robot")
            q0 = _start_reading(robot, inputs.geometry)
            goal_q = np.asarray(inputs.goal_file.lengths, float)
            _check_board(robot, inputs.geometry, goal_q, status.message)
            _plan(args, q0, goal_q, limits, status.message)
            # a robot that sends and returns: the session keeps its control period
            pace = not (getattr(robot, "simulated", False)
                        or getattr(robot, "paces_periods", False))
            if pace:
                status.message(f"servo: {args.backend} does not wait out its periods: the "
                               f"session does ({args.dt * 1e3:g} ms)")
            limited = LimitedRobot(robot, limits, q0, pace=pace,
                                   check_pacing=not getattr(robot, "simulated", False),
                                   warn=status.message)
            guard.in_loop = True  # from here the first signal waits for the next period
            servo_loop(limited, sensor, inputs.controller, inputs.goal, inputs.geometry,
                       args.dt, args.max_steps, args.tolerance_mm * 1e-3,
                       args.feature_tolerance, args.settle, on_period,
                       on_pose, limits=limits, checks=[guard, *checks],
                       warn=status.message, result=result)
        except BaseException as exc:  # every way out goes through the shutdown below
            guard.shutting_down = True
            ended = exc
        guard.shutting_down = True
        moved = limited is not None and limited.moved
        if ended is not None:
            code, reason = _classify(ended, moved)
            if guard.pending is not None and not isinstance(ended, SessionStop):
                # e.g. SIGHUP, then the closed terminal failing a print: the signal first
                code, reason = exit_for_signal(guard.pending), (
                    f"{signal.Signals(guard.pending).name} received (then {reason})")
        else:
            code, reason = _outcome(result, args)
        halt = None if robot is None else _halt(robot, args.halt_timeout_s)
        closing: list[str] = []  # (said on the console too: it was in the record only)
        for what, opened in (("robot", robot), ("camera", sensor)):
            if opened is not None:
                try:
                    opened.close()
                except Exception as exc:
                    closing.append(f"closing the {what} failed: {exc}")
                    reason += f"; {closing[-1]}"
        failed = ended is not None and not isinstance(ended, SessionStop)
        log.final({"exit_code": int(code), "exit": code.name.lower(), "reason": reason,
                   "exception": f"{type(ended).__name__}: {ended}" if failed else None,
                   "traceback": "".join(traceback.format_exception(ended))
                   if failed and ended is not None else None,
                   "moved": moved, "identity": getattr(robot, "identity", None),
                   "start_lengths_mm": (mm_list(limited.start) if limited is not None
                                        else None if q0 is None else mm_list(q0)),
                   "halt_confirmed": None if halt is None else halt.confirmed,
                   "halt_detail": _not_connected(ended) if halt is None else halt.detail,
                   "halt_s": None if halt is None else round(halt.seconds, 6),
                   "retries": getattr(robot, "retried", None),
                   "watchdog_trips": getattr(robot, "watchdog_trips", None),
                   "watchdog_clears": getattr(robot, "watchdog_rearms", None),
                   "signals": list(guard.received), "checks": _check_summaries(checks),
                   **_figures(result)})
        try:  # the record is written: a closed terminal (SIGHUP) cannot lose it
            status.final(result.last)
            _report(status, code, reason, result, halt, limited, moved, log, ended,
                    [*_check_summaries(checks), *_watchdog_line(robot, moved)])
            for text in closing:
                status.message(f"warning: {text}")
            if ended is not None and code == ServoExit.INTERNAL:
                traceback.print_exception(ended, file=sys.stderr)
        except (OSError, ValueError):
            pass
    return int(code)


def _not_connected(ended: BaseException | None) -> str:
    """The record's ``halt_detail`` of a session whose robot never connected: what the
    backend did on the way out when it says (an ``HLT`` sent, acknowledged or not)."""
    detail = getattr(ended, "halt_detail", None)
    return "the robot was not connected" + (f"; {detail}" if detail else "")


def _watchdog_line(robot: Any, moved: bool) -> list[str]:
    """The summary's line on the board's watchdog (a backend that counts its trips: the
    serial board), for a session that moved the robot; none otherwise."""
    trips = getattr(robot, "watchdog_trips", None)
    if not moved or not isinstance(trips, int):
        return []
    if trips == 0:
        return ["board watchdog: never tripped"]
    cleared = getattr(robot, "watchdog_rearms", 0)
    return [f"board watchdog: tripped {trips} time(s) during motion (the legs held each "
            f"time; {cleared} cleared with ERR? and the MOV sent again)"]


def _check_summaries(checks: Sequence[PeriodCheck]) -> list[str]:
    """The one-line summaries of the checks that give one (``summary()``: the camera
    check's periods checked and largest disagreement)."""
    lines = []
    for check in checks:
        summary = getattr(check, "summary", None)
        if callable(summary):
            try:
                lines.append(str(summary()))
            except Exception as exc:  # a summary never hides the shutdown's report
                lines.append(f"{type(check).__name__}: no summary ({exc})")
    return lines


def _report(status: StatusLine, code: ServoExit, reason: str, result: ServoResult,
            halt: HaltReport | None, limited: LimitedRobot | None, moved: bool,
            log: SessionLog, ended: BaseException | None, summaries: Sequence[str] = ()
            ) -> None:
    """What happened, the figures, whether the robot is confirmed stopped, the record."""
    say = status.message
    if code == ServoExit.REFUSED and not moved and ended is not None and not isinstance(
            ended, SessionStop):
        # refused before moving: one message, on stderr like every refusal of bad input
        print(f"hexapod-bench servo: error: {reason} (exit {int(code)}, refused)",
              file=sys.stderr)
    elif code != ServoExit.CONVERGED:
        say(f"stopped: {reason} (exit {int(code)}, {code.name.lower()})")
    if result.steps or moved or code == ServoExit.CONVERGED:
        say(result.summary())
    for line in summaries:  # (a stop before the first period: what the checks saw)
        say(line)
    if halt is None:
        detail = getattr(ended, "halt_detail", None)
        say("robot: not connected" + (f" ({detail})" if detail else ""))
    elif halt.confirmed:
        say(f"robot: halted and confirmed stopped ({halt.detail}, {halt.seconds:.2f} s)")
    else:
        say(f"robot: NOT confirmed stopped: {halt.detail}; {_last_move(limited)}. Check the "
            "robot before anyone approaches it.")
    say(f"record: {log.path}")
