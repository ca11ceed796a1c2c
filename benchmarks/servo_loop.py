"""The real servo loop: one controller, a robot over its serial link, a camera.

``hexapod-bench servo --backend serial:URL|emulator --camera sim|video:PATH|device:N
--controller NAME --goal FILE`` runs at the control period until the robot
reaches the goal, ``--max-steps`` or Ctrl-C, and always halts the robot.

Each period: the measured leg lengths (from the board) give a predicted pose
(forward kinematics of the nominal model) that seeds the edge tracker; the
camera image gives the edge normals; the controller turns them into leg
velocities; the backend streams the setpoints (``MOV``) and reads the lengths
back (``POS?``). With ``--camera sim`` the image is rendered from the pose of
the MEASURED leg lengths, so the loop can be tried against the emulator.

The goal file (TOML, millimetres) gives the goal configuration taught on the
robot::

    lengths_mm = [415.0, 415.0, 430.0, 415.0, 415.0, 430.0]

The desired features are the edges the (estimated) camera sees of the nominal
model at that configuration.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.exceptions import BenchmarkError
from hexapod.config import check_keys, get_matrix, load_toml
from hexapod.geometry import HexapodGeometry
from hexapod.geometry import preset as geometry_preset

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ServoGoal:
    """A taught goal: leg lengths [m] (and the file it came from)."""

    lengths: np.ndarray
    source: str


def load_goal(path: str | Path, geometry: HexapodGeometry) -> ServoGoal:
    """Read a goal file and check it against the stroke.

    Raises:
        ConfigFileError: Missing file, bad TOML, missing/misspelt key, wrong count, or a
            length outside the stroke (named by leg).
    """
    from hexapod.exceptions import ConfigFileError

    table = load_toml(path)
    check_keys(table, ("lengths_mm", "name"), str(path), required=("lengths_mm",))
    q = get_matrix(table, "lengths_mm", (6,), str(path)) * 1e-3
    for i, x in enumerate(q):
        if not geometry.q_min <= x <= geometry.q_max:
            raise ConfigFileError(str(path), f"leg {i}: {x * 1e3:.3f} mm is outside the stroke "
                                  f"[{geometry.q_min * 1e3:.1f}, {geometry.q_max * 1e3:.1f}] mm",
                                  key="lengths_mm")
    return ServoGoal(q, str(path))


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``hexapod-bench servo``."""
    p.add_argument("--backend", required=True,
                   help="emulator (a firmware emulator on a pty) or serial:URL")
    p.add_argument("--camera", default="sim",
                   help="sim (render from the measured lengths), video:PATH or device:N")
    p.add_argument("--controller", required=True, help="registry name or module:attr")
    p.add_argument("--goal", required=True, help="goal TOML file (lengths_mm)")
    p.add_argument("--camera-model", default="front",
                   help="camera preset (front, omni) or a camera TOML file")
    p.add_argument("--geometry", default="deltalab", help="preset or geometry TOML file")
    p.add_argument("--calibration", help="calibrated.toml (base points in the camera frame)")
    p.add_argument("--start-mm", type=float, nargs=6,
                   help="emulator only: initial leg lengths [mm] (default mid-stroke)")
    p.add_argument("--dt", type=float, default=0.02, help="control period [s]")
    p.add_argument("--max-steps", type=int, default=3000)
    p.add_argument("--tolerance-mm", type=float, default=0.5,
                   help="converged when every leg is this close to the goal [mm]...")
    p.add_argument("--settle", type=int, default=5, help="...for this many periods")
    p.add_argument("--log", help="write one JSON line per period to this file")
    p.add_argument("--viz", action="store_true", help="live MeshCat view (loopback)")


def _geometry(spec: str) -> HexapodGeometry:
    if spec.endswith(".toml"):
        return HexapodGeometry.from_toml(spec)
    return geometry_preset(spec)


def _camera(spec: str, geometry: HexapodGeometry) -> Any:
    from vision.cameras import camera_preset, load_camera

    if spec.endswith(".toml"):
        return load_camera(spec)
    return camera_preset(spec, geometry)


def _open_backend(spec: str, geometry: HexapodGeometry, start: np.ndarray | None) -> Any:
    from hexapod.backends.serial import SerialRobot, open_emulated_robot

    if spec == "emulator":
        return open_emulated_robot(geometry, start)
    if spec.startswith("serial:") and len(spec) > 7:
        return SerialRobot(spec[7:])
    raise BenchmarkError(f"--backend: expected emulator or serial:URL, got {spec!r}")


class _Sensor:
    """Images -> edge normals, from the renderer (sim) or a real camera source."""

    def __init__(self, spec: str, camera: Any, geometry: HexapodGeometry) -> None:
        self.camera = camera
        self.geometry = geometry
        self.sim = None
        self.source = None
        self.previous: np.ndarray | None = None
        self.dropped = 0
        if spec == "sim":
            from vision.image_sensor import ImageSensor

            self.sim = ImageSensor(camera, camera, geometry, rng=np.random.default_rng(0))
        elif spec.startswith(("video:", "device:")):
            from vision.detect import OmniDetector, PerspectiveTracker
            from vision.sources import VideoSource

            kind, _, arg = spec.partition(":")
            self.source = VideoSource(int(arg) if kind == "device" else arg, camera)
            self.detector: Any = (PerspectiveTracker(camera) if camera.kind == "perspective"
                                  else OmniDetector(camera))
        else:
            raise BenchmarkError(f"--camera: expected sim, video:PATH or device:N, got {spec!r}")

    def measure(self, rotation: np.ndarray, translation: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray] | None:
        """Edge normals (6, 2, 3) and visibility (6, 2), or None for a lost frame."""
        if self.sim is not None:
            m = self.sim.measure(rotation, translation, predicted_normals=self.previous)
            normals, visible = np.asarray(m.normals), np.asarray(m.edge_visible)
        else:
            from vision.detect import LegPrediction

            frame = self.source.read() if self.source is not None else None
            if frame is None:
                self.dropped += 1
                return None
            pred = LegPrediction.from_pose(self.camera, self.geometry, rotation, translation)
            if self.previous is not None:
                pred = pred.with_normals(self.previous)
            det = self.detector.detect(frame.image, pred)
            normals, visible = np.asarray(det.normals), np.asarray(det.edge_visible)
        self.previous = normals if np.all(visible) else None
        return normals, visible

    def close(self) -> None:
        if self.source is not None:
            self.source.close()


def run(args: argparse.Namespace) -> int:
    """The loop of ``hexapod-bench servo`` (returns the exit code)."""
    import controllers  # noqa: F401 - registers the built-ins
    from benchmarks.calibrate import load_calibrated_base_points
    from controllers.base import ControllerContext, Goal, Observation, registry
    from hexapod.fk import forward_kinematics
    from vision.legs import directions_from_edges, observe_legs

    if args.dt <= 0 or args.max_steps < 1:
        raise BenchmarkError("--dt must be positive and --max-steps >= 1")
    geometry = _geometry(args.geometry)
    camera = _camera(args.camera_model, geometry)
    goal = load_goal(args.goal, geometry)
    controller = registry.create(args.controller)
    g_sol = forward_kinematics(geometry, goal.lengths)
    desired = observe_legs(camera, geometry, g_sol.rotation, g_sol.translation)
    lines = desired.lines if desired.lines is not None else None
    base_points = (load_calibrated_base_points(args.calibration) if args.calibration
                   else camera.camera_from_base.apply(geometry.base_points))
    ctx = ControllerContext(
        base_points=base_points, geometry=geometry, camera=camera, dt=args.dt,
        goal=Goal(normals=desired.normals, lines=lines, directions=desired.directions,
                  lengths=goal.lengths, rotation=g_sol.rotation,
                  translation=g_sol.translation, edge_visible=desired.edge_visible))
    controller.reset(ctx)
    start = None if args.start_mm is None else np.asarray(args.start_mm) * 1e-3
    sensor = _Sensor(args.camera, camera, geometry)
    viewer = None
    if args.viz:
        from hexapod.visualize import HexapodViewer

        viewer = HexapodViewer(geometry)
        viewer.show_camera(camera.camera_from_base.as_matrix(), camera.K, camera.width,
                           camera.height, camera.kind)
        viewer.show_goal(g_sol.rotation, g_sol.translation)
        print(f"MeshCat viewer: {viewer.url()}")
    logf = Path(args.log).open("w") if args.log else None  # noqa: SIM115 - closed below
    tty = sys.stdout.isatty()
    settled = 0
    converged = False
    rtts: list[float] = []
    missed = 0
    step = 0
    t0 = time.perf_counter()
    guess = None
    try:
        with _open_backend(args.backend, geometry, start) as robot:
            q = robot.measured_lengths()
            for step in range(args.max_steps):
                sol = forward_kinematics(geometry, q, guess=guess, check_stroke=False)
                guess = (sol.rotation, sol.translation)
                meas = sensor.measure(sol.rotation, sol.translation)
                if meas is None:
                    v = np.zeros(6)
                    reason: str | None = "lost camera frame"
                    err = float("nan")
                else:
                    normals, visible = meas
                    both = np.all(visible, axis=-1)
                    with np.errstate(invalid="ignore"):
                        dirs = directions_from_edges(normals)
                    obs = Observation(
                        t=step * args.dt, lengths=q, normals=normals,
                        lines=camera.normal_to_line(normals) if camera.kind == "perspective"
                        else None,
                        directions=np.where(both[:, None], dirs, np.nan),
                        edge_visible=visible, direction_visible=both)
                    cmd = controller.step(obs)
                    v, reason, err = cmd.velocities, cmd.reason, cmd.error_norm
                bs = robot.step(v, args.dt)
                q = bs.lengths
                rtts.append(bs.round_trip_s)
                missed += int(bs.missed_period)
                dq = float(np.max(np.abs(q - goal.lengths)) * 1e3)
                settled = settled + 1 if dq < args.tolerance_mm else 0
                if viewer is not None:
                    viewer.display(sol.rotation, sol.translation,
                                   None if meas is None else meas[1])
                if logf is not None:
                    logf.write(json.dumps({"step": step, "t": step * args.dt,
                                           "lengths_mm": (q * 1e3).tolist(),
                                           "error_norm": None if not np.isfinite(err) else err,
                                           "max_leg_error_mm": dq, "reason": reason,
                                           "rtt_ms": bs.round_trip_s * 1e3,
                                           "missed": bool(bs.missed_period)}) + "\n")
                line = (f"step {step:5d}  feature error {err:9.2e}  max |q - q*| {dq:8.3f} mm  "
                        f"RTT {bs.round_trip_s * 1e3:6.2f} ms  missed {missed}"
                        + (f"  [{reason}]" if reason else ""))
                if tty:
                    print("\r" + line, end="", flush=True)
                elif step % 25 == 0:
                    print(line, flush=True)
                if settled >= args.settle:
                    converged = True
                    break
    except KeyboardInterrupt:
        print("\ninterrupted: the robot was halted")
    finally:
        sensor.close()
        if logf is not None:
            logf.close()
        if viewer is not None:
            viewer.close()
    wall = time.perf_counter() - t0
    rate = (step + 1) / wall if wall > 0 else float("nan")
    rt = np.array(rtts) * 1e3 if rtts else np.array([np.nan])
    print(("\n" if tty else "") + f"{'converged' if converged else 'stopped'} after "
          f"{step + 1} periods ({wall:.1f} s, {rate:.1f} Hz, {missed} missed, "
          f"{sensor.dropped} lost frames); RTT median {np.median(rt):.2f} ms, "
          f"p99 {np.percentile(rt, 99):.2f} ms")
    return 0 if converged else 1
