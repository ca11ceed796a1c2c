"""The real servo loop: one controller, a robot over its serial link, a camera.

``hexapod-bench servo --backend SPEC --camera SPEC --controller NAME --goal FILE`` runs one
controller at the control period until the robot converges, a limit is reached, the
recording ends, the camera disagrees with the encoders or stays blind
(:mod:`benchmarks.robot.consistency`), a signal or a failure; every way out goes through
the session's one shutdown (:mod:`benchmarks.robot.session`: ``HLT``, its confirmation, a
summary, the final record, an exit code of :class:`~benchmarks.robot.exits.ServoExit`).
Each period (:mod:`benchmarks.robot.loop`): the measured lengths give the predicted pose,
the camera an image and its edges, the controller leg velocities (zero when refused or
without an image), the backend streams them and reads the lengths back.

The goal file (TOML) holds the goal configuration taught on the robot,
``lengths_mm = [6 values]``, and optionally ``features = "goal.npz"`` (written by
``--teach``, averaged over ``--teach-frames`` frames of the still robot); without them
the desired features are predicted from the nominal model (``docs/servo.md``). SI units
inside; millimetres at the user's edges.
"""

from __future__ import annotations

import argparse
import contextlib
import copy
import logging
import math
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.exceptions import BenchmarkError
from benchmarks.robot.consistency import (
    DEFAULT_BLIND_TIMEOUT_S,
    DEFAULT_CONSISTENCY_DEG,
    DEFAULT_CONSISTENCY_MM,
    CameraCheck,
)
from benchmarks.robot.exits import SessionStop, SignalGuard
from benchmarks.robot.goals import (
    DEFAULT_TEACH_FRAMES,
    average_features,
    goal_features,
    load_goal,
    save_goal,
    teach_tolerance,
)
from benchmarks.robot.limits import (
    DEFAULT_MAX_MISSED_CONSECUTIVE,
    DEFAULT_MAX_MISSED_FRACTION,
    DEFAULT_MAX_TIME_S,
    MISSED_WINDOW,
)
from benchmarks.robot.loop import DEFAULT_FEATURE_TOLERANCE, DEFAULT_SETTLE
from benchmarks.robot.models import (
    add_robot_arguments,
    camera_model,
    check_dt,
    check_option,
    choose_camera,
    robot_geometry,
)
from benchmarks.robot.records import LOG_NAME, SESSIONS_DIR, session_path
from benchmarks.robot.session import (
    DEFAULT_HALT_TIMEOUT_S,
    DEFAULT_RETRIES,
    SessionInputs,
    run_session,
    session_limits,
)
from benchmarks.robot.status import StatusLine
from benchmarks.study.outdir import OutputDir, OutputFile
from hexapod.geometry import HexapodGeometry
from vision.feature_cameras import Features, check_camera_spec, open_camera

log = logging.getLogger(__name__)


def open_backend(spec: str, geometry: HexapodGeometry,
                 start: np.ndarray | None = None) -> Any:
    """Connect the robot of a ``--backend`` spec (:meth:`hexapod.backends.registry.
    BackendRegistry.open`; a context manager that halts the robot and closes it), the
    simulated ones at the initial leg lengths ``start`` [m] (None: mid-stroke).

    Raises:
        BenchmarkError: ``start`` given for a real robot.
        UnknownBackendError, BackendPluginError: A bad spec.
        SerialLinkError: The port cannot be opened or the board does not answer.
    """
    from hexapod.backends.registry import backends

    name = backends.check(spec)
    if start is not None and name not in SIMULATED_BACKENDS:
        raise BenchmarkError(f"--start-mm only applies to a simulated robot "
                             f"({', '.join(SIMULATED_BACKENDS)}): a real robot starts where "
                             "it is")
    return backends.open(spec, geometry, start)


#: Backends whose robot is simulated: ``--start-mm`` sets where it starts.
SIMULATED_BACKENDS = ("emulator", "gcs-emulator", "sim")


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Add the options of ``hexapod-bench servo`` to a parser."""
    p.add_argument("--backend", required=True,
                   help="emulator (a firmware emulator on a pseudo-terminal), serial:URL "
                        "(a device path, socket://127.0.0.1:PORT, ...), gcs:tcp://HOST:PORT "
                        "or gcs:serial:URL (a PI GCS hexapod controller), gcs-emulator, sim, "
                        "a plugin's NAME[:ARGS] or module:attr[:ARGS] (docs/backends.md)")
    p.add_argument("--camera",
                   help="device:N (a camera), video:PATH (a recording: used only if it agrees "
                        "with the encoders at start) or sim (render the legs at the pose of "
                        "the measured lengths); required with real hardware (serial:, gcs:, "
                        "plugins), default sim with a simulated robot (sim, emulator, "
                        "gcs-emulator)")
    p.add_argument("--simulated-camera-on-real-robot", action="store_true",
                   help="allow --camera sim with real hardware (the loop then closes on "
                        "rendered images of the measured pose, not on what the robot does)")
    p.add_argument("--consistency-mm", type=float, default=DEFAULT_CONSISTENCY_MM,
                   metavar="MM",
                   help="halt (exit 5) when the platform pose seen by the camera and the one "
                        "from the encoders are further apart than this [mm] (default "
                        f"{DEFAULT_CONSISTENCY_MM:g}) ...")
    p.add_argument("--consistency-deg", type=float, default=DEFAULT_CONSISTENCY_DEG,
                   metavar="DEG",
                   help=f"... or turned by more than this [deg] (default "
                        f"{DEFAULT_CONSISTENCY_DEG:g})")
    p.add_argument("--blind-timeout-s", type=float, default=DEFAULT_BLIND_TIMEOUT_S,
                   metavar="S",
                   help="halt (exit 5) when the camera has given no platform pose (lost "
                        "frames, fewer than 3 legs seen) for this long [s] (default "
                        f"{DEFAULT_BLIND_TIMEOUT_S:g})")
    p.add_argument("--controller", default="leg-edge",
                   help="controller: registry name or module:attr (default leg-edge)")
    p.add_argument("-o", "--option", action="append", default=[], metavar="KEY=VALUE",
                   help="controller option (repeatable; VALUE is a TOML value or a word), "
                        "e.g. -o gain=2")
    p.add_argument("--goal", required=True, action=OutputFile,
                   help="goal TOML file: lengths_mm = [6 values] (and optionally features = "
                        "'goal.npz'); with --teach, the file to write")
    p.add_argument("--teach", action="store_true",
                   help="do not move: record the current lengths and image features as the "
                        "goal (writes --goal and its .features.npz)")
    p.add_argument("--teach-frames", type=int, default=DEFAULT_TEACH_FRAMES, metavar="N",
                   help=f"--teach: average the edge normals of N frames (default "
                        f"{DEFAULT_TEACH_FRAMES}; the pixel noise of the taught features "
                        f"drops as 1/sqrt(N))")
    p.add_argument("--camera-file", default="front",
                   help="camera model: a camera TOML file (intrinsics or opencv = FILE, and "
                        "camera_from_base), a calibration file (OpenCV FileStorage, fisheye "
                        "included; ROS camera_info; Kalibr camchain: .yml, .yaml, .xml, "
                        ".json; with --camera-pose) or a preset (front, omni, fisheye); "
                        "default front")
    p.add_argument("--camera-pose", metavar="PRESET|TOML",
                   help="with a calibration file: the camera's pose, a preset's placement "
                        "(front, omni, fisheye) or a camera TOML file's camera_from_base")
    add_robot_arguments(p)
    p.add_argument("--calibration", metavar="FILE",
                   help="calibrated.toml: the controller uses these base points (camera "
                        "frame) instead of the nominal ones")
    p.add_argument("--allow-foreign-calibration", action="store_true",
                   help="use a --calibration made with another robot or camera (warned)")
    lim = p.add_argument_group("limits (reaching one halts the robot, exit 3)")
    lim.add_argument("--max-steps", type=int,
                     help="stop after N periods (default: no period budget)")
    lim.add_argument("--max-time-s", type=float, default=DEFAULT_MAX_TIME_S, metavar="S",
                     help=f"stop after S seconds of motion (default {DEFAULT_MAX_TIME_S:g})")
    lim.add_argument("--max-speed-mm-s", type=float, metavar="MM_S",
                     help="cap every leg's commanded speed [mm/s] (default and ceiling: the "
                          "robot file's max_speed_mm_s)")
    lim.add_argument("--max-travel-mm", type=float, metavar="MM",
                     help="largest travel of any leg from its start length [mm]: a goal "
                          "farther is refused before moving, a command beyond it stops the "
                          "session before it is sent (default: the stroke)")
    lim.add_argument("--max-missed-consecutive", type=int,
                     default=DEFAULT_MAX_MISSED_CONSECUTIVE, metavar="N",
                     help=f"stop after N late periods in a row (default "
                          f"{DEFAULT_MAX_MISSED_CONSECUTIVE}; 0: never)")
    lim.add_argument("--max-missed-fraction", type=float, default=DEFAULT_MAX_MISSED_FRACTION,
                     metavar="F",
                     help=f"stop when more than F of the last {MISSED_WINDOW} periods were late "
                          f"(default {DEFAULT_MAX_MISSED_FRACTION:g}; 1: never)")
    lim.add_argument("--confirm", action="store_true",
                     help="show the planned move (start, goal, largest leg travel) and ask "
                          "y/N on the terminal before the first command (refused without a "
                          "terminal)")
    lim.add_argument("--halt-timeout-s", type=float, default=DEFAULT_HALT_TIMEOUT_S,
                     metavar="S",
                     help=f"at the end, wait up to S seconds for the robot to confirm its "
                          f"stop (default {DEFAULT_HALT_TIMEOUT_S:g})")
    lim.add_argument("--retries", type=int, default=DEFAULT_RETRIES, metavar="N",
                     help=f"serial backends: send an exchange whose reply was lost again up "
                          f"to N times (default {DEFAULT_RETRIES}: one dropped reply is "
                          f"survived)")
    p.add_argument("--tolerance-mm", type=float, default=0.1,
                   help="converged when max |q - q*| <= this [mm] (default 0.1) ...")
    p.add_argument("--feature-tolerance", type=float, default=DEFAULT_FEATURE_TOLERANCE,
                   help=f"... and the feature error <= this (default "
                        f"{DEFAULT_FEATURE_TOLERANCE}) ...")
    p.add_argument("--settle", type=int, default=DEFAULT_SETTLE,
                   help=f"... for this many periods (default {DEFAULT_SETTLE})")
    p.add_argument("--start-mm", type=float, nargs=6, metavar="L",
                   help="emulator only: initial leg lengths [mm] (default mid-stroke)")
    p.add_argument("--seed", type=int, default=0, help="pixel noise of --camera sim")
    p.add_argument("--out", metavar="DIR", action=OutputDir,
                   help=f"the session directory (new or empty; default "
                        f"{SESSIONS_DIR}/<UTC time>-<controller>/): {LOG_NAME} holds a header, "
                        f"one JSON line per period and the final record")
    p.add_argument("--log", metavar="FILE.jsonl", action=OutputFile,
                   help="write the session record to this file instead of a session "
                        "directory (an earlier servo log is replaced, any other file refused)")
    p.add_argument("--viz", action="store_true", help="live MeshCat view (loopback server)")


def parse_options(items: list[str]) -> dict[str, Any]:
    """Controller options from ``KEY=VALUE`` strings (VALUE read as TOML, else a string).

    Raises:
        BenchmarkError: An item without ``=`` or with an empty key.
    """
    import tomllib

    options: dict[str, Any] = {}
    for item in items:
        key, sep, text = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise BenchmarkError(f"--option {item!r}: expected KEY=VALUE (e.g. gain=2)")
        try:
            options[key] = tomllib.loads(f"v = {text.strip()}")["v"]
        except tomllib.TOMLDecodeError:
            options[key] = text.strip()
    return options


def _check_args(args: argparse.Namespace) -> None:
    check_dt(args.dt)
    check_option("--max-steps", args.max_steps, 1, strict=False)
    check_option("--tolerance-mm", args.tolerance_mm, finite=True)
    check_option("--feature-tolerance", args.feature_tolerance, finite=True)
    if getattr(args, "confirm", False) and not sys.stdin.isatty():
        raise BenchmarkError("--confirm asks y/N on a terminal and stdin is not one: refused "
                             "before anything is opened")
    check_option("--settle", args.settle, 1, strict=False)
    check_option("--teach-frames", args.teach_frames, 1, strict=False)
    check_option("--seed", args.seed, 0, strict=False)


@contextlib.contextmanager
def _viewer(enabled: bool, geometry: HexapodGeometry, camera: Any, goal: Any
            ) -> Iterator[Any]:
    if not enabled:
        yield None
        return
    try:
        from hexapod.visualize import HexapodViewer
    except ImportError as exc:
        raise BenchmarkError(f"--viz needs the MeshCat viewer (hexapod.visualize), which "
                             f"cannot be imported: {exc}") from None
    viewer = HexapodViewer(geometry)
    try:
        viewer.show_camera(camera.camera_from_base.as_matrix(), camera.K, camera.width,
                           camera.height, camera.kind)
        if goal is not None:
            viewer.show_goal(goal.rotation, goal.translation)
        print(f"MeshCat viewer: {viewer.url()}", flush=True)
        yield viewer
    finally:
        viewer.close()


def _base_points(args: argparse.Namespace, geometry: HexapodGeometry, camera: Any
                 ) -> np.ndarray:
    """The base points in the camera frame [m] the controller and the camera check use:
    ``--calibration``'s (its provenance checked, warnings on stderr), else the nominal
    ones seen through the camera file's pose."""
    from benchmarks.study.calibration import read_calibrated_file
    from benchmarks.study.provenance import check_calibration

    if not args.calibration:
        return np.asarray(camera.camera_from_base.apply(geometry.base_points), float)
    base_points, recorded = read_calibrated_file(args.calibration)
    for text in check_calibration(args.calibration, base_points, recorded,
                                  Path(args.geometry).name, geometry,
                                  Path(args.camera_file).name, camera,
                                  getattr(args, "allow_foreign_calibration", False)):
        print(f"warning: {text}", file=sys.stderr)
    return np.asarray(base_points, float)


def _warm_up(controller: Any, goal: Any) -> None:
    """One step of a copy of the reset controller on the goal's own features, before the
    robot is opened: its compiled kernels are built (a cold cache) or loaded now, not in
    the session's first period (5 s there on a cold cache). The controller itself is not
    stepped; a failure of the copy's step is the session's to meet (logged here)."""
    from controllers.base import Observation

    edges = np.asarray(goal.edge_visible, dtype=bool)
    obs = Observation(0.0, np.asarray(goal.lengths, float), normals=goal.normals,
                      lines=goal.lines, directions=goal.directions, edge_visible=edges,
                      direction_visible=np.all(edges, axis=1), q_dot=np.zeros(6))
    try:
        copy.deepcopy(controller).step(obs)
    except Exception as exc:  # (the real step meets it, with the session's handling)
        log.debug("warm-up step of %s: %s: %s", type(controller).__name__,
                  type(exc).__name__, exc)


def _robot_file_slips(geometry: Any, spec: str) -> None:
    """What ``check`` says of a robot file's unit slips, before anything is opened:
    warnings on stderr, and a refusal for joints no leg can reach.

    Raises:
        BenchmarkError: Joints within 2 mm of their centre (points in metres).
    """
    from benchmarks.study.setup_check import Where, unit_slips

    for problem in unit_slips(geometry, Where(strokes=f"stroke_mm in {spec}")):
        if problem.severity == "error":
            raise BenchmarkError(f"--geometry {spec}: {problem.text}")
        print(f"warning: {problem.text}", file=sys.stderr)


def _teach(args: argparse.Namespace, geometry: HexapodGeometry, camera: Any,
           start: np.ndarray | None, status: StatusLine, guard: SignalGuard) -> int:
    from hexapod.fk import forward_kinematics

    path = Path(args.goal)
    for taught in (path, path.with_suffix(".features.npz")):
        if taught.exists():
            raise BenchmarkError(f"{taught}: already exists; delete it or choose another "
                                 "--goal (--teach never overwrites a goal or its features)")
    sensor = open_camera(args.camera, camera, geometry, args.seed)
    frames: list[Features] = []
    try:
        with open_backend(args.backend, geometry, start) as robot:
            q = np.asarray(robot.measured_lengths(), float)
        sol = forward_kinematics(geometry, q, check_stroke=False)
        for _ in range(args.teach_frames):  # the robot does not move: a burst of frames
            guard.check()  # Ctrl-C: the camera closed, nothing written
            f = sensor.measure(sol.rotation, sol.translation)
            if f is not None:
                frames.append(f)
            elif getattr(sensor, "ended", False):
                break
    finally:
        sensor.close()
    if not frames:
        raise BenchmarkError(f"--teach: the camera {args.camera} gave no frame")
    feats = average_features(frames, teach_tolerance(sensor))
    if feats.visible_count == 0:
        raise BenchmarkError(f"--teach: no leg edge found in the images of {args.camera}")
    # the session's start check: features of another pose than the encoders' would be a
    # goal every later session drives towards
    check = CameraCheck(geometry, _base_points(args, geometry, camera),
                        args.consistency_mm * 1e-3, math.radians(args.consistency_deg),
                        args.blind_timeout_s, args.camera,
                        must_agree_at_start=args.camera.startswith("video:"))
    try:
        check.compare(0, q, sol.rotation, sol.translation, feats.normals, feats.edge_visible)
    except SessionStop as stop:
        raise SessionStop(stop.code, f"{stop.reason}; nothing taught ({path} not "
                          "written)") from None
    npz = save_goal(path, q, feats)
    status.message(f"taught {path} (lengths {np.round(q * 1e3, 3).tolist()} mm, "
                   f"{feats.visible_count} of 12 edges, normals averaged over {len(frames)} "
                   f"of {args.teach_frames} frames) and {npz}")
    return 0


def run(args: argparse.Namespace) -> int:
    """``hexapod-bench servo``: the session (or ``--teach``); returns the exit code
    (:class:`~benchmarks.robot.exits.ServoExit`). Bad inputs found before anything is
    opened raise (the CLI maps them to 2); from the session record's creation on, every
    way out goes through :func:`~benchmarks.robot.session.run_session`'s shutdown.

    The session's signals (SIGINT, SIGTERM, SIGHUP) are caught from the start: during
    the start-up (the goal, the controller and its compiled kernels, ``--teach``'s
    frames) the first one is taken at the next stage (raised there, it could be lost in
    a compiled library's code) and a second one at once; nothing has moved, and the exit
    code is the signal's (130 for Ctrl-C).
    """
    guard = SignalGuard()
    guard.in_loop = True  # the first signal waits for the next stage of the start-up
    try:
        with guard:
            return _run(args, guard)
    except SessionStop as stop:
        print(f"stopped: {stop.reason} before the session began: the robot was not moved "
              f"(exit {int(stop.code)}, {stop.code.name.lower()})", flush=True)
        return int(stop.code)


def _run(args: argparse.Namespace, guard: SignalGuard) -> int:
    """:func:`run` under its signal guard (``guard.check()`` between the stages)."""
    import controllers  # noqa: F401 - registers the built-ins
    from controllers.base import ControllerContext, registry

    _check_args(args)
    from hexapod.backends.registry import backends

    backends.check(args.backend)  # a bad spec is reported before anything is opened
    args.camera = choose_camera(args.backend, args.camera,
                                getattr(args, "simulated_camera_on_real_robot", False))
    check_camera_spec(args.camera)
    geometry = robot_geometry(args.geometry)
    _robot_file_slips(geometry, args.geometry)
    camera = camera_model(args.camera_file, args.camera_pose, geometry)
    start = None if args.start_mm is None else np.asarray(args.start_mm, float) * 1e-3
    if start is not None:
        bad = [i for i, x in enumerate(start)
               if not geometry.stroke[0] <= x <= geometry.stroke[1]]
        if bad:
            i = bad[0]
            what = ("is not a number" if not np.isfinite(start[i]) else
                    f"{start[i] * 1e3:.3f} mm is outside the stroke "
                    f"[{geometry.stroke[0] * 1e3:.3f}, {geometry.stroke[1] * 1e3:.3f}] mm")
            raise BenchmarkError(f"--start-mm: leg {i}: {what}")
    status = StatusLine()
    guard.check()
    if args.teach:
        return _teach(args, geometry, camera, start, status, guard)

    # everything the user gave is checked before the robot is touched
    session_path(args.out, args.log, args.controller)  # the record's place, checked
    session_limits(args, geometry, lambda text: None)
    goal_file = load_goal(args.goal, geometry)
    goal = goal_features(goal_file, camera, geometry)
    guard.check()
    options = parse_options(args.option)
    try:
        controller = registry.create(args.controller, **options)
    except TypeError as exc:  # an option the factory does not take
        raise BenchmarkError(f"--controller {args.controller}: bad option in "
                             f"{sorted(options)}: {exc}") from None
    base_points = _base_points(args, geometry, camera)
    controller.reset(ControllerContext(base_points=base_points, geometry=geometry,
                                       camera=camera, dt=args.dt, goal=goal))
    _warm_up(controller, goal)
    guard.check()
    check = CameraCheck(geometry, base_points,
                        args.consistency_mm * 1e-3, math.radians(args.consistency_deg),
                        args.blind_timeout_s, args.camera,
                        must_agree_at_start=args.camera.startswith("video:"))
    inputs = SessionInputs(geometry, camera, goal_file, goal, controller, start)
    with _viewer(args.viz, geometry, camera, goal) as viewer:
        guard.check()
        return run_session(args, inputs, status, None if viewer is None else viewer.display,
                           checks=[check], guard=guard)


def build_parser() -> argparse.ArgumentParser:
    """A stand-alone parser (``python -m benchmarks.robot.servo``)."""
    p = argparse.ArgumentParser(prog="hexapod-bench servo", description=__doc__.split("\n")[0])
    add_arguments(p)
    return p


def main(argv: list[str] | None = None) -> int:
    """``python -m benchmarks.robot.servo ...``: :func:`run`, the CLI's error handling (exit 2
    for a bad input found before anything is opened)."""
    from controllers.exceptions import ControllerError
    from hexapod.exceptions import HexapodError
    from vision.exceptions import VisionError

    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    try:
        return run(args)
    except (BenchmarkError, HexapodError, ControllerError, VisionError) as exc:
        print(f"hexapod-bench servo: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
