"""The real servo loop: one controller, a robot over its serial link, a camera.

``hexapod-bench servo --backend serial:URL|emulator --camera sim|video:PATH|device:N
--controller NAME --goal FILE`` runs one controller at the control period until the
robot converges, ``--max-steps`` or Ctrl-C, and always halts the robot (the
backend's context manager sends ``HLT`` and closes the port, whatever happens).

Each period:

1. the lengths measured by the board at the end of the previous period give the
   predicted platform pose (forward kinematics of the nominal model);
2. the camera gives an image (``--camera sim`` renders the legs at that pose, so the
   whole loop can be tried against the emulator); the edge detector, seeded by the
   prediction (and by the last measured normals when every edge was found), gives
   the edge normals;
3. the controller turns the :class:`~controllers.base.Observation` into leg
   velocities; a refused command (``Command.reason``) or a lost frame commands zero;
4. the backend streams the setpoints (``MOV``), waits for the end of the period
   and reads the lengths back (``POS?``).

The goal file (TOML, see ``docs/servo.md``) holds the goal configuration taught on
the robot, ``lengths_mm = [6 values]``; the desired features are then predicted
from the nominal model at the forward kinematics of those lengths, seen by the
(estimated) camera. ``features = "goal.npz"`` (written by ``--teach``) gives the
features measured at the goal instead, which a real camera needs (the model's
prediction carries the calibration errors); ``--teach`` averages them over a burst of
``--teach-frames`` frames of the still robot.

SI units inside (metres, seconds); millimetres at the user's edges (goal file,
status line, log).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import logging
import math
import sys
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any, Protocol

import numpy as np

from benchmarks.exceptions import BenchmarkError
from hexapod.config import check_keys, get_matrix, load_toml
from hexapod.exceptions import ConfigFileError, ForwardKinematicsError
from hexapod.geometry import HexapodGeometry

log = logging.getLogger(__name__)

#: Keys a goal file may have.
GOAL_KEYS = ("lengths_mm", "features", "name")
#: Default number of consecutive converged periods before the loop stops.
DEFAULT_SETTLE = 5
#: Default feature-error tolerance (norm of the stacked normal differences) [-].
DEFAULT_FEATURE_TOLERANCE = 2e-3
#: Default number of frames averaged by ``--teach`` (a burst of 0.2 s at 50 Hz).
DEFAULT_TEACH_FRAMES = 10
#: Plain status lines (stdout not a terminal) are printed every this many seconds.
PLAIN_STATUS_PERIOD_S = 1.0
#: Exit codes of :func:`run`.
EXIT_CONVERGED, EXIT_NOT_CONVERGED, EXIT_INTERRUPTED = 0, 1, 130


# ============================================================================
# Goal file
# ============================================================================
@dataclass(frozen=True)
class Features:
    """Edge features of one image.

    Attributes:
        normals: (6, 2, 3) unit edge normals in the (estimated) camera frame; NaN where
            missing.
        edge_visible: (6, 2) bool, which edges were found.
    """

    normals: np.ndarray
    edge_visible: np.ndarray

    @property
    def visible_count(self) -> int:
        """Number of edges found (0 to 12)."""
        return int(np.count_nonzero(self.edge_visible))


@dataclass(frozen=True)
class ServoGoal:
    """A taught goal.

    Attributes:
        lengths: (6,) goal leg lengths [m].
        features: The features recorded at the goal (``--teach``), or None to predict
            them from the nominal model.
        source: The goal file.
        name: Optional label from the file.
    """

    lengths: np.ndarray
    features: Features | None
    source: str
    name: str = ""


def average_features(frames: list[Features], max_deviation: float | None = None
                     ) -> Features:
    """The features of a burst of frames of a still scene, averaged (``--teach``).

    Each edge normal is the renormalised sum of its sign-aligned unit normals over the
    frames where the edge was found (:func:`vision.estimate.average_normals`); a frame
    farther than ``max_deviation`` [rad] from the median of the frames does not count
    for that edge, and an edge kept in fewer than half of the frames is reported
    missing.

    Raises:
        BenchmarkError: No frame.
    """
    from vision.estimate import average_normals

    if not frames:
        raise BenchmarkError("no frame to average")
    normals, visible = average_normals(np.array([f.normals for f in frames], float),
                                       np.array([f.edge_visible for f in frames], bool),
                                       max_deviation=max_deviation)
    return Features(normals, visible)


def teach_tolerance(sensor: Any) -> float | None:
    """The largest deviation of a frame from the median of a taught burst [rad]: the
    detector's inlier distance (``outlier_px``) seen from the camera
    (:func:`vision.estimate.radians_per_pixel`); None if the sensor has no detector."""
    from vision.estimate import radians_per_pixel

    detector = getattr(getattr(sensor, "sensor", sensor), "detector", None)
    if detector is None or not hasattr(detector, "outlier_px"):
        return None
    return float(detector.outlier_px) * radians_per_pixel(sensor_camera(sensor))


def _load_features(path: Path, goal_file: str) -> Features:
    """Read recorded goal features (``normals`` (6, 2, 3), ``edge_visible`` (6, 2)).

    Raises:
        ConfigFileError: Missing or unreadable file, missing array or bad shape.
    """
    if not path.is_file():
        raise ConfigFileError(goal_file, f"features file {path} not found", key="features")
    try:
        with np.load(path) as data:
            arrays = {k: np.asarray(data[k]) for k in data.files}
    except (OSError, ValueError) as exc:
        raise ConfigFileError(goal_file, f"features file {path} cannot be read: {exc}",
                              key="features") from None
    for name, shape in (("normals", (6, 2, 3)), ("edge_visible", (6, 2))):
        if name not in arrays:
            raise ConfigFileError(goal_file, f"features file {path} has no array '{name}' "
                                             f"(has: {', '.join(sorted(arrays)) or 'none'})",
                                  key="features")
        if arrays[name].shape != shape:
            raise ConfigFileError(goal_file, f"features file {path}: '{name}' has shape "
                                             f"{arrays[name].shape}, expected {shape}",
                                  key="features")
    visible = arrays["edge_visible"].astype(bool)
    normals = arrays["normals"].astype(float)
    if not np.all(np.isfinite(normals[visible])):
        raise ConfigFileError(goal_file, f"features file {path}: a visible normal is not "
                                         "finite", key="features")
    if not visible.any():
        raise ConfigFileError(goal_file, f"features file {path}: no edge was seen at the goal",
                              key="features")
    return Features(np.where(visible[..., None], normals, np.nan), visible)


def load_goal(path: str | Path, geometry: HexapodGeometry) -> ServoGoal:
    """Read a goal file and check it against the stroke (nothing is sent to the robot).

    Args:
        path: The goal TOML file (``lengths_mm``, optional ``features`` and ``name``).
        geometry: The nominal robot (its stroke).

    Returns:
        The goal, lengths in metres.

    Raises:
        ConfigFileError: Missing file, bad TOML, missing or misspelt key, wrong count,
            a length outside the stroke (named by leg), or a bad features file. The
            message names the file and the key.
    """
    src = str(path)
    table = load_toml(path)
    check_keys(table, GOAL_KEYS, src, required=("lengths_mm",))
    q = get_matrix(table, "lengths_mm", (6,), src) * 1e-3
    q_min, q_max = geometry.stroke
    for i, x in enumerate(q):
        if not q_min <= x <= q_max:
            raise ConfigFileError(src, f"leg {i + 1}: {x * 1e3:.3f} mm is outside the stroke "
                                       f"[{q_min * 1e3:.3f}, {q_max * 1e3:.3f}] mm",
                                  key="lengths_mm")
    name = table.get("name", "")
    if not isinstance(name, str):
        raise ConfigFileError(src, f"expected a string, got {name!r}", key="name")
    features = None
    if "features" in table:
        ref = table["features"]
        if not isinstance(ref, str) or not ref:
            raise ConfigFileError(src, f"expected a file name (.npz), got {ref!r}",
                                  key="features")
        fpath = Path(ref) if Path(ref).is_absolute() else Path(path).parent / ref
        features = _load_features(fpath, src)
    return ServoGoal(q, features, src, name)


def save_goal(path: str | Path, lengths: np.ndarray, features: Features,
              name: str = "") -> Path:
    """Write a taught goal: ``path`` (TOML) and its features beside it (``.npz``).

    Args:
        path: The goal TOML file to create.
        lengths: (6,) measured leg lengths at the goal [m].
        features: The features measured at the goal.
        name: Optional label.

    Returns:
        The path of the features file.
    """
    import tomli_w

    p = Path(path)
    npz = p.with_suffix(".features.npz")
    np.savez(npz, normals=np.asarray(features.normals, float),
             edge_visible=np.asarray(features.edge_visible, bool))
    doc: dict[str, Any] = {"lengths_mm": [round(float(x) * 1e3, 4) for x in lengths],
                           "features": npz.name}
    if name:
        doc["name"] = name
    p.write_text("# taught by hexapod-bench servo --teach\n" + tomli_w.dumps(doc))
    return npz


# ============================================================================
# Camera and backend
# ============================================================================
class FeatureSensor(Protocol):
    """A camera that gives the edge features at the current (predicted) pose."""

    lost_frames: int

    def measure(self, rotation: np.ndarray, translation: np.ndarray) -> Features | None:
        """The features of the next image (None for a lost frame)."""

    def close(self) -> None:
        """Release the camera."""


class _TrackingMixin:
    """Keeps the last normals (NaN where an edge was not found) to seed the next
    detection (:meth:`vision.detect.PerspectiveTracker.track`)."""

    previous: np.ndarray | None = None

    def _remember(self, f: Features) -> Features:
        self.previous = np.asarray(f.normals) if bool(np.any(f.edge_visible)) else None
        return f


class SimCamera(_TrackingMixin):
    """``--camera sim``: renders the legs at the given pose and detects their edges.

    The rendered robot and camera are the nominal ones: the pose passed to
    :meth:`measure` (forward kinematics of the measured lengths) is the truth of
    this simulated world.

    Args:
        camera: The camera.
        geometry: The robot.
        seed: Seed of the pixel noise.
        drop_every: Lose one frame in every ``drop_every`` (0: never), to exercise the
            lost-frame path.
    """

    def __init__(self, camera: Any, geometry: HexapodGeometry, seed: int = 0,
                 drop_every: int = 0) -> None:
        from vision.image_sensor import ImageSensor

        self.sensor = ImageSensor(camera, camera, geometry, rng=np.random.default_rng(seed))
        self.drop_every = int(drop_every)
        self.frames = 0
        self.lost_frames = 0

    def measure(self, rotation: np.ndarray, translation: np.ndarray) -> Features | None:
        """Render at ``(rotation, translation)`` (base frame, m) and detect the edges."""
        self.frames += 1
        if self.drop_every and self.frames % self.drop_every == 0:
            self.lost_frames += 1
            return None
        m = self.sensor.measure(rotation, translation, predicted_normals=self.previous)
        return self._remember(Features(np.asarray(m.normals, float),
                                       np.asarray(m.edge_visible, bool)))

    def close(self) -> None:
        """Nothing to release."""


class VideoCamera(_TrackingMixin):
    """``--camera video:PATH`` or ``device:N``: frames through OpenCV, edges detected.

    Args:
        source: Device index or video file path.
        camera: The camera model of the frames (intrinsics, pose).
        geometry: The nominal robot (predictions for the detector).

    Raises:
        SourceOpenError: The device or file cannot be opened.
    """

    def __init__(self, source: int | str, camera: Any, geometry: HexapodGeometry) -> None:
        from vision.detect import OmniDetector, PerspectiveTracker
        from vision.sources import VideoSource

        self.camera = camera
        self.geometry = geometry
        self.source = VideoSource(source, camera)
        self.detector: Any = (PerspectiveTracker(camera) if camera.kind == "perspective"
                              else OmniDetector(camera))
        self.lost_frames = 0
        self.ended = False

    def measure(self, rotation: np.ndarray, translation: np.ndarray) -> Features | None:
        """Read the next frame and detect the edges near their prediction at the pose."""
        from vision.detect import LegPrediction

        dropped = self.source.dropped
        frame = self.source.read()
        self.lost_frames += self.source.dropped - dropped
        if frame is None:
            self.ended = not self.source.is_device
            self.lost_frames += 1
            return None
        pred = LegPrediction.from_pose(self.camera, self.geometry, rotation, translation)
        det = self.detector.track(frame.image, pred, self.previous)
        return self._remember(Features(np.asarray(det.normals, float),
                                       np.asarray(det.edge_visible, bool)))

    def close(self) -> None:
        """Release the capture."""
        self.source.close()


def open_camera(spec: str, camera: Any, geometry: HexapodGeometry,
                seed: int = 0) -> FeatureSensor:
    """The feature sensor of a ``--camera`` spec: ``sim``, ``video:PATH`` or ``device:N``.

    Raises:
        BenchmarkError: Unknown spec or bad device number.
        SourceOpenError: The device or file cannot be opened.
    """
    if spec == "sim":
        return SimCamera(camera, geometry, seed)
    kind, _, arg = spec.partition(":")
    if kind == "video" and arg:
        return VideoCamera(arg, camera, geometry)
    if kind == "device" and arg:
        try:
            index = int(arg)
        except ValueError:
            raise BenchmarkError(f"--camera {spec}: the device must be a number (device:0)"
                                 ) from None
        return VideoCamera(index, camera, geometry)
    raise BenchmarkError(f"--camera: expected sim, video:PATH or device:N, got {spec!r}")


def open_backend(spec: str, geometry: HexapodGeometry,
                 start: np.ndarray | None = None) -> Any:
    """Connect the robot of a ``--backend`` spec (:mod:`hexapod.backends.registry`).

    Args:
        spec: ``emulator``, ``serial:URL``, a plugin's ``NAME[:ARGS]`` or
            ``module:attr[:ARGS]``.
        geometry: The nominal robot (the emulator's stroke and speed limit).
        start: Emulator only: initial leg lengths [m] (mid-stroke if None).

    Returns:
        A connected backend (a context manager that halts the robot and closes it).

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
SIMULATED_BACKENDS = ("emulator", "sim")


# ============================================================================
# Desired features
# ============================================================================
def _directions(f: Features) -> tuple[np.ndarray, np.ndarray]:
    from vision.legs import directions_from_edges

    both = np.all(f.edge_visible, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        u = directions_from_edges(np.where(f.edge_visible[..., None], f.normals, np.nan))
    return np.where(both[:, None], u, np.nan), both


def _lines(camera: Any, normals: np.ndarray) -> np.ndarray | None:
    if getattr(camera, "kind", "") != "perspective":
        return None
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.asarray(camera.normal_to_line(normals), float)


def goal_features(goal: ServoGoal, camera: Any, geometry: HexapodGeometry) -> Any:
    """The controller's :class:`~controllers.base.Goal` of a taught goal.

    The platform pose is the forward kinematics of the goal lengths in the nominal
    model; the desired features are the recorded ones if the goal file has some,
    else what the (estimated) camera sees of the nominal model at that pose.

    Raises:
        BenchmarkError: No pose for these lengths, or no edge visible at the goal.
    """
    from controllers.base import Goal
    from hexapod.fk import forward_kinematics
    from vision.legs import observe_legs

    try:
        sol = forward_kinematics(geometry, goal.lengths)
    except ForwardKinematicsError as exc:
        raise BenchmarkError(f"{goal.source}: key 'lengths_mm': no platform pose for these "
                             f"lengths in the nominal model ({exc})") from None
    feats = goal.features
    if feats is None:
        seen = observe_legs(camera, geometry, sol.rotation, sol.translation)
        visible = np.asarray(seen.edge_visible, bool)
        feats = Features(np.where(visible[..., None], np.asarray(seen.normals, float), np.nan),
                         visible)
    if feats.visible_count == 0:
        raise BenchmarkError(f"{goal.source}: the camera sees no leg edge at the goal")
    directions, _ = _directions(feats)
    return Goal(normals=feats.normals, lines=_lines(camera, feats.normals),
                directions=directions, lengths=goal.lengths.copy(), rotation=sol.rotation,
                translation=sol.translation, edge_visible=feats.edge_visible)


def feature_error(measured: Features, desired_normals: np.ndarray,
                  desired_visible: np.ndarray) -> float:
    """Norm of the stacked normal differences over the edges seen in both [-].

    NaN when no edge is seen in both.
    """
    both = measured.edge_visible & desired_visible
    if not both.any():
        return math.nan
    d = measured.normals[both] - desired_normals[both]
    return float(np.linalg.norm(d))


# ============================================================================
# The loop
# ============================================================================
@dataclass
class PeriodStatus:
    """One period of the loop (what the status line and the log show).

    Attributes:
        step: Period index (from 0).
        t: Loop time at the start of the period [s].
        lengths: (6,) lengths measured at the end of the period [m].
        leg_error: max |q - q*| at the end of the period [m].
        feature_error: Feature error of this period's image (NaN for a lost frame).
        controller_error: The controller's own error norm (NaN if not run).
        velocities: (6,) commanded leg velocities [m/s] (zeros when refused).
        visible_edges: Edges found in this period's image.
        reason: Why the command is zero (refusal, lost frame), or None.
        lost_frame: The camera gave no image this period.
        rtt: Time spent communicating with the robot [s].
        missed: This period was late.
        missed_total: Late periods so far.
        lost_total: Lost frames so far.
        refused_total: Refused commands so far.
    """

    step: int
    t: float
    lengths: np.ndarray
    leg_error: float
    feature_error: float
    controller_error: float
    velocities: np.ndarray
    visible_edges: int
    reason: str | None
    lost_frame: bool
    rtt: float
    missed: bool
    missed_total: int
    lost_total: int
    refused_total: int

    def to_json(self) -> dict[str, Any]:
        """A log line (lengths in mm, velocities in mm/s, times in ms; NaN as null)."""
        def num(x: float, scale: float = 1.0) -> float | None:
            return float(x) * scale if math.isfinite(x) else None

        return {"step": self.step, "t_s": round(self.t, 6),
                "lengths_mm": [round(float(x) * 1e3, 4) for x in self.lengths],
                "leg_error_mm": num(self.leg_error, 1e3),
                "feature_error": num(self.feature_error),
                "controller_error": num(self.controller_error),
                "velocities_mm_s": [round(float(x) * 1e3, 4) for x in self.velocities],
                "visible_edges": self.visible_edges, "reason": self.reason,
                "lost_frame": self.lost_frame, "rtt_ms": num(self.rtt, 1e3),
                "missed": self.missed}

    def line(self) -> str:
        """The status line (mm and ms)."""
        fe = f"{self.feature_error:.2e}" if math.isfinite(self.feature_error) else "   --   "
        s = (f"step {self.step:6d} {self.t:7.2f} s | feature err {fe} | "
             f"max|q-q*| {self.leg_error * 1e3:7.3f} mm | edges {self.visible_edges:2d} | "
             f"RTT {self.rtt * 1e3:5.2f} ms | missed {self.missed_total} | "
             f"lost {self.lost_total}")
        if self.reason:
            s += f"  [{self.reason}]"
        return s


@dataclass
class ServoResult:
    """Outcome of :func:`servo_loop`.

    Attributes:
        outcome: ``"converged"``, ``"max-steps"``, ``"interrupted"`` or ``"camera ended"``.
        steps: Periods run.
        wall_s: Wall time of the loop [s].
        rtts: Round-trip time of each period [s].
        missed: Late periods.
        lost_frames: Lost camera frames.
        refused: Periods with a refused command.
        last: The last period's status, if any.
    """

    outcome: str
    steps: int
    wall_s: float
    rtts: list[float] = field(default_factory=list)
    missed: int = 0
    lost_frames: int = 0
    refused: int = 0
    last: PeriodStatus | None = None

    @property
    def converged(self) -> bool:
        """The loop stopped at convergence."""
        return self.outcome == "converged"

    @property
    def rate_hz(self) -> float:
        """Achieved loop rate [Hz]."""
        return self.steps / self.wall_s if self.wall_s > 0 else math.nan

    def summary(self) -> str:
        """One line for the user (mm, ms, Hz)."""
        rt = np.array(self.rtts) * 1e3 if self.rtts else np.array([math.nan])
        s = (f"{self.outcome} after {self.steps} periods ({self.wall_s:.2f} s, "
             f"{self.rate_hz:.1f} Hz): {self.missed} missed periods, {self.lost_frames} lost "
             f"frames, {self.refused} refused commands; RTT median {np.median(rt):.2f} ms, "
             f"p99 {np.percentile(rt, 99):.2f} ms")
        if self.last is not None:
            s += (f"; final max|q-q*| {self.last.leg_error * 1e3:.3f} mm, feature error "
                  f"{self.last.feature_error:.2e}")
        return s


def servo_loop(
    robot: Any,
    sensor: FeatureSensor,
    controller: Any,
    goal: Any,
    geometry: HexapodGeometry,
    dt: float,
    max_steps: int | None = None,
    tolerance: float = 1e-4,
    feature_tolerance: float = DEFAULT_FEATURE_TOLERANCE,
    settle: int = DEFAULT_SETTLE,
    on_period: Callable[[PeriodStatus], None] | None = None,
    on_pose: Callable[[np.ndarray, np.ndarray, np.ndarray | None], None] | None = None,
) -> ServoResult:
    """Run a reset controller on a connected robot until convergence, ``max_steps`` or Ctrl-C.

    The caller halts the robot (use it as a context manager); Ctrl-C is caught here
    and reported as the outcome ``"interrupted"``.

    Args:
        robot: A connected backend (``measured_lengths()``, ``step(v, dt)``).
        sensor: The camera.
        controller: A controller already reset with its context.
        goal: The controller's :class:`~controllers.base.Goal` (lengths, normals).
        geometry: The nominal robot (forward kinematics).
        dt: Control period [s].
        max_steps: Period budget (None: until convergence or Ctrl-C).
        tolerance: Convergence threshold on max |q - q*| [m].
        feature_tolerance: Convergence threshold on the feature error [-].
        settle: Consecutive periods within both tolerances to stop.
        on_period: Called after every period (status line, log).
        on_pose: Called with the predicted pose and edge visibility (viewer).

    Returns:
        The outcome and the link statistics.
    """
    from controllers.base import Observation
    from hexapod.fk import forward_kinematics

    q_goal = np.asarray(goal.lengths, float)
    n_goal = np.asarray(goal.normals, float)
    vis_goal = np.asarray(goal.edge_visible, bool)
    cam = sensor_camera(sensor)
    res = ServoResult("max-steps", 0, 0.0)
    settled = 0
    guess: tuple[np.ndarray, np.ndarray] | None = None
    t0 = time.perf_counter()
    step = 0
    try:
        q = np.asarray(robot.measured_lengths(), float)
        while max_steps is None or step < max_steps:
            try:
                sol = forward_kinematics(geometry, q, guess=guess, check_stroke=False)
                guess = (sol.rotation, sol.translation)
            except ForwardKinematicsError as exc:
                if guess is None:
                    raise BenchmarkError(f"no platform pose for the measured lengths "
                                         f"{np.round(q * 1e3, 3)} mm: {exc}") from None
                log.warning("forward kinematics failed (%s); keeping the last pose", exc)
            rotation, translation = guess
            feats = sensor.measure(rotation, translation)
            reason: str | None = None
            ctrl_err = math.nan
            if feats is None:
                v = np.zeros(6)
                reason = "lost camera frame"
                f_err = math.nan
                if getattr(sensor, "ended", False):
                    res.outcome = "camera ended"
                    break
            else:
                f_err = feature_error(feats, n_goal, vis_goal)
                directions, both = _directions(feats)
                obs = Observation(
                    t=step * dt, lengths=q.copy(), normals=feats.normals,
                    lines=_lines(cam, feats.normals),
                    directions=directions, edge_visible=feats.edge_visible,
                    direction_visible=both)
                cmd = controller.step(obs)
                v = np.asarray(cmd.velocities, float)
                ctrl_err = float(cmd.error_norm)
                reason = cmd.reason
                if reason is None and (v.shape != (6,) or not np.all(np.isfinite(v))):
                    reason = f"invalid command {v!r}"
                if reason is not None:
                    v = np.zeros(6)
                    res.refused += 1
            if on_pose is not None:
                on_pose(rotation, translation, None if feats is None else feats.edge_visible)
            bs = robot.step(v, dt)
            q = np.asarray(bs.lengths, float)
            res.rtts.append(float(bs.round_trip_s))
            res.missed += int(bs.missed_period)
            leg_err = float(np.max(np.abs(q - q_goal)))
            ok = (leg_err <= tolerance and math.isfinite(f_err) and f_err <= feature_tolerance)
            settled = settled + 1 if ok else 0
            res.lost_frames = sensor.lost_frames
            status = PeriodStatus(
                step=step, t=time.perf_counter() - t0, lengths=q, leg_error=leg_err,
                feature_error=f_err, controller_error=ctrl_err, velocities=v,
                visible_edges=0 if feats is None else feats.visible_count, reason=reason,
                lost_frame=feats is None, rtt=float(bs.round_trip_s),
                missed=bool(bs.missed_period), missed_total=res.missed,
                lost_total=res.lost_frames, refused_total=res.refused)
            res.last = status
            step += 1
            if on_period is not None:
                on_period(status)
            if settled >= settle:
                res.outcome = "converged"
                break
    except KeyboardInterrupt:
        res.outcome = "interrupted"
    res.steps = step
    res.wall_s = time.perf_counter() - t0
    res.lost_frames = sensor.lost_frames
    return res


def sensor_camera(sensor: Any) -> Any:
    """The (estimated) camera model a sensor interprets its images with."""
    if isinstance(sensor, SimCamera):
        return sensor.sensor.estimated_camera
    return sensor.camera


# ============================================================================
# Status line
# ============================================================================
class StatusLine:
    """The live status: one rewritten line on a terminal (rich), plain lines otherwise.

    Args:
        stream: Where to write (default stdout).
        period_s: Plain mode: at most one line every ``period_s`` [s] (the first
            period and the refusals' changes are always shown).
    """

    def __init__(self, stream: IO[str] | None = None,
                 period_s: float = PLAIN_STATUS_PERIOD_S) -> None:
        self.stream = sys.stdout if stream is None else stream
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.period_s = float(period_s)
        self._last_print = -math.inf
        self._last_reason: str | None = None
        self._live: Any = None
        if self.tty:
            from rich.console import Console
            from rich.live import Live
            from rich.text import Text

            self._text = Text
            self._live = Live(Text(""), console=Console(file=self.stream),
                              auto_refresh=False, transient=False)
            self._live.start()

    def __call__(self, status: PeriodStatus) -> None:
        """Show one period."""
        now = time.perf_counter()
        if self._live is not None:
            if now - self._last_print >= 0.05 or status.reason != self._last_reason:
                style = "yellow" if status.reason else ""
                self._live.update(self._line(status, style), refresh=True)
                self._last_print = now
        elif (now - self._last_print >= self.period_s or status.reason != self._last_reason):
            print(status.line(), file=self.stream, flush=True)
            self._last_print = now
        self._last_reason = status.reason

    def _line(self, status: PeriodStatus, style: str = "") -> Any:
        # one terminal line: cropped to the width, never wrapped
        return self._text(status.line(), style=style, no_wrap=True, overflow="ellipsis")

    def final(self, status: PeriodStatus | None) -> None:
        """Show the last period and release the terminal line."""
        if self._live is not None:
            if status is not None:
                self._live.update(self._line(status), refresh=True)
            self._live.stop()
            self._live = None
        elif status is not None:
            print(status.line(), file=self.stream, flush=True)

    def message(self, text: str) -> None:
        """A line of its own."""
        if self._live is not None:
            self._live.console.print(text, markup=False, highlight=False)
        else:
            print(text, file=self.stream, flush=True)


# ============================================================================
# Command line
# ============================================================================
def add_arguments(p: argparse.ArgumentParser) -> None:
    """Add the options of ``hexapod-bench servo`` to a parser."""
    p.add_argument("--backend", required=True,
                   help="emulator (a firmware emulator on a pseudo-terminal), serial:URL "
                        "(a device path, socket://127.0.0.1:PORT, ...), sim, a plugin's "
                        "NAME[:ARGS] or module:attr[:ARGS] (docs/backends.md)")
    p.add_argument("--camera", default="sim",
                   help="sim (render the legs at the pose of the measured lengths), "
                        "video:PATH or device:N (default sim)")
    p.add_argument("--controller", default="leg-edge",
                   help="controller: registry name or module:attr (default leg-edge)")
    p.add_argument("-o", "--option", action="append", default=[], metavar="KEY=VALUE",
                   help="controller option (repeatable; VALUE is a TOML value or a word), "
                        "e.g. -o gain=2")
    p.add_argument("--goal", required=True,
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
                   help="camera model: a camera TOML file (intrinsics and camera_from_base) "
                        "or a preset (front, omni); default front")
    p.add_argument("--geometry", default="deltalab",
                   help="nominal robot: a geometry TOML file or a preset (default deltalab)")
    p.add_argument("--calibration", metavar="FILE",
                   help="calibrated.toml: the controller uses these base points (camera "
                        "frame) instead of the nominal ones")
    p.add_argument("--dt", type=float, default=0.02, help="control period [s] (default 0.02)")
    p.add_argument("--max-steps", type=int,
                   help="stop after N periods (default: until convergence or Ctrl-C)")
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
    p.add_argument("--log", metavar="FILE.jsonl", help="write one JSON line per period")
    p.add_argument("--viz", action="store_true", help="live MeshCat view (loopback server)")


def _geometry(spec: str) -> HexapodGeometry:
    from hexapod.geometry import preset

    if spec.endswith(".toml") or Path(spec).is_file():
        return HexapodGeometry.from_toml(spec)
    return preset(spec)


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
    if not (math.isfinite(args.dt) and args.dt > 0):
        raise BenchmarkError(f"--dt must be a positive period in seconds, got {args.dt}")
    if args.max_steps is not None and args.max_steps < 1:
        raise BenchmarkError(f"--max-steps must be >= 1, got {args.max_steps}")
    if not args.tolerance_mm > 0 or not args.feature_tolerance > 0:
        raise BenchmarkError("--tolerance-mm and --feature-tolerance must be positive")
    if args.settle < 1:
        raise BenchmarkError(f"--settle must be >= 1, got {args.settle}")
    if args.teach_frames < 1:
        raise BenchmarkError(f"--teach-frames must be >= 1, got {args.teach_frames}")


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


def _teach(args: argparse.Namespace, geometry: HexapodGeometry, camera: Any,
           start: np.ndarray | None, status: StatusLine) -> int:
    from hexapod.fk import forward_kinematics

    path = Path(args.goal)
    if path.exists():
        raise BenchmarkError(f"{path}: already exists; delete it or choose another --goal "
                             "(--teach never overwrites a goal)")
    sensor = open_camera(args.camera, camera, geometry, args.seed)
    frames: list[Features] = []
    try:
        with open_backend(args.backend, geometry, start) as robot:
            q = np.asarray(robot.measured_lengths(), float)
        sol = forward_kinematics(geometry, q, check_stroke=False)
        for _ in range(args.teach_frames):  # the robot does not move: a burst of frames
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
    npz = save_goal(path, q, feats)
    status.message(f"taught {path} (lengths {np.round(q * 1e3, 3).tolist()} mm, "
                   f"{feats.visible_count} of 12 edges, normals averaged over {len(frames)} "
                   f"of {args.teach_frames} frames) and {npz}")
    return 0


def run(args: argparse.Namespace) -> int:
    """``hexapod-bench servo``: the loop (or ``--teach``); returns the exit code.

    Exit codes: 0 converged (or taught), 1 stopped at ``--max-steps`` or at the end of
    a video, 130 interrupted by Ctrl-C. Bad inputs raise (the CLI maps them to 2)
    before the robot is touched.
    """
    import controllers  # noqa: F401 - registers the built-ins
    from benchmarks.calibrate import load_calibrated_base_points
    from controllers.base import ControllerContext, registry
    from vision.cameras import load_camera

    _check_args(args)
    from hexapod.backends.registry import backends

    backends.check(args.backend)  # a bad spec is reported before anything is opened
    geometry = _geometry(args.geometry)
    camera = load_camera(args.camera_file, geometry)
    start = None if args.start_mm is None else np.asarray(args.start_mm, float) * 1e-3
    if start is not None:
        bad = [i + 1 for i, x in enumerate(start)
               if not geometry.stroke[0] <= x <= geometry.stroke[1]]
        if bad:
            raise BenchmarkError(f"--start-mm: leg {bad[0]} is outside the stroke "
                                 f"[{geometry.stroke[0] * 1e3:.3f}, "
                                 f"{geometry.stroke[1] * 1e3:.3f}] mm")
    status = StatusLine()
    if args.teach:
        return _teach(args, geometry, camera, start, status)

    # everything the user gave is checked before the robot is touched
    goal_file = load_goal(args.goal, geometry)
    goal = goal_features(goal_file, camera, geometry)
    options = parse_options(args.option)
    try:
        controller = registry.create(args.controller, **options)
    except TypeError as exc:  # an option the factory does not take
        raise BenchmarkError(f"--controller {args.controller}: bad option in "
                             f"{sorted(options)}: {exc}") from None
    base_points = (load_calibrated_base_points(args.calibration) if args.calibration
                   else camera.camera_from_base.apply(geometry.base_points))
    controller.reset(ControllerContext(base_points=base_points, geometry=geometry,
                                       camera=camera, dt=args.dt, goal=goal))
    sensor = open_camera(args.camera, camera, geometry, args.seed)
    logf: IO[str] | None = None
    result: ServoResult | None = None
    try:
        if args.log:
            logf = Path(args.log).open("w")  # noqa: SIM115 - closed in finally
        with _viewer(args.viz, geometry, camera, goal) as viewer, \
                open_backend(args.backend, geometry, start) as robot:
            status.message(f"servo: {args.controller} on {args.backend} ({robot.identity}), "
                           f"camera {args.camera}, goal {goal_file.source}, dt "
                           f"{args.dt * 1e3:g} ms; Ctrl-C halts the robot")

            def on_period(s: PeriodStatus) -> None:
                status(s)
                if logf is not None:
                    logf.write(json.dumps(s.to_json()) + "\n")
                    logf.flush()  # readable live (tail -f), and complete after a crash

            on_pose = None
            if viewer is not None:
                def on_pose(R: np.ndarray, t: np.ndarray, vis: np.ndarray | None) -> None:
                    viewer.display(R, t, vis)

            result = servo_loop(robot, sensor, controller, goal, geometry, args.dt,
                                args.max_steps, args.tolerance_mm * 1e-3,
                                args.feature_tolerance, args.settle, on_period, on_pose)
    finally:
        status.final(result.last if result is not None else None)
        sensor.close()
        if logf is not None:
            logf.close()
    status.message(result.summary() + ("; the robot was halted" if result.outcome
                                       == "interrupted" else ""))
    if result.outcome == "converged":
        return EXIT_CONVERGED
    if result.outcome == "interrupted":
        return EXIT_INTERRUPTED
    return EXIT_NOT_CONVERGED


def build_parser() -> argparse.ArgumentParser:
    """A stand-alone parser (``python -m benchmarks.servo``)."""
    p = argparse.ArgumentParser(prog="hexapod-bench servo", description=__doc__.split("\n")[0])
    add_arguments(p)
    return p


def main(argv: list[str] | None = None) -> int:
    """``python -m benchmarks.servo ...``: :func:`run` with the CLI's error handling (exit 2)."""
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
