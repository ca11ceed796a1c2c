"""The real servo session (:func:`servo_loop`): the simulator's closed loop with a batch of
one, a robot behind its backend as the plant (the pose predicted from the measured
lengths), the camera's features, the controller's command, the backend's period; its book
(:class:`ServoBook`), status (one rewritten line on a terminal) and result."""

from __future__ import annotations

import logging
import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import IO, Any

import numpy as np

from benchmarks.exceptions import BenchmarkError
from benchmarks.robot.goals import feature_directions, feature_error, feature_lines
from benchmarks.sim.sensors import camera_batch
from controllers.base import ObservationBatch
from hexapod.exceptions import ForwardKinematicsError
from hexapod.geometry import HexapodGeometry
from vision.feature_cameras import FeatureSensor, sensor_camera

log = logging.getLogger(__name__)

#: Default number of consecutive converged periods before the loop stops.
DEFAULT_SETTLE = 5
#: Default feature-error tolerance (norm of the stacked normal differences) [-].
DEFAULT_FEATURE_TOLERANCE = 2e-3
#: Plain status lines (stdout not a terminal) are printed every this many seconds.
PLAIN_STATUS_PERIOD_S = 1.0


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
    check: Callable[..., Any] | None = None,
) -> ServoResult:
    """Run a reset controller on a connected robot until convergence, ``max_steps`` or Ctrl-C.

    The session is the simulator's closed loop (:func:`benchmarks.sim.loop.closed_loop`)
    with a batch of one: the robot is a :class:`~benchmarks.sim.plant.BackendPlant` (the
    pose is the nominal forward kinematics of the measured lengths), the camera a
    :class:`ServoCamera`, the book a :class:`ServoBook`. The caller halts the robot (use
    it as a context manager); Ctrl-C is caught here and reported as the outcome
    ``"interrupted"``.

    Args:
        robot: A connected backend (``measured_lengths()``, ``apply(v, kind, dt, name)``).
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
        check: Called every period before the command with ``(step, lengths, R, t,
            normals, edge_visible)`` (the camera check,
            :class:`benchmarks.robot.consistency.CameraCheck`); it ends the session by
            raising :class:`~benchmarks.robot.exits.SessionStop`.

    Returns:
        The outcome and the link statistics.
    """
    from benchmarks.sim.loop import closed_loop
    from benchmarks.sim.plant import BackendPlant
    from controllers.base import Controller
    from controllers.batch import ForeignController, actuation_of
    from hexapod.actuation import check_actuation

    name = getattr(controller, "name", "controller")
    declared = check_actuation(actuation_of(controller), robot.actuations,
                               f"the robot {robot.identity or type(robot).__name__!r}", name)
    # already reset: a batch of one (a trial's crash or malformed command in ``crashes``);
    # a per-trial plugin's own reset and step, or a foreign object's, through an adapter
    batch_of_one = isinstance(controller, Controller) and type(controller).step is Controller.step
    one = controller if batch_of_one else ForeignController.adopt(controller)
    camera = ServoCamera(sensor)
    res = ServoResult("max-steps", 0, 0.0)
    t0 = time.perf_counter()
    try:
        q = np.asarray(robot.measured_lengths(), float)[None].copy()
        R, t = np.zeros((1, 3, 3)), np.zeros((1, 3))
        poses = _NominalPoses(geometry, q, R, t)
        plant = BackendPlant([robot], q, R, t, np.zeros((1, 6)), poses)
        plant.use_actuation(declared, name)
        book = ServoBook(plant, camera, goal, tolerance, feature_tolerance, settle, res, t0,
                         declared, name, on_period, on_pose)
        book.check_camera = check
        closed_loop(plant, camera, None, one, book, dt, np.zeros((1, 6)),
                    None if max_steps is None else max_steps - 1)
    except KeyboardInterrupt:
        res.outcome = "interrupted"
    res.wall_s = time.perf_counter() - t0
    res.lost_frames = sensor.lost_frames
    return res


class _NominalPoses:
    """The predicted pose of the robot: the nominal forward kinematics of its measured
    lengths, seeded with the previous pose (a failure keeps the last pose, warned; with
    no pose yet it is a :class:`BenchmarkError`)."""

    def __init__(self, geometry: HexapodGeometry, q: np.ndarray, R: np.ndarray,
                 t: np.ndarray) -> None:
        self.geometry = geometry
        self.q, self.R, self.t = q, R, t
        self.guess: tuple[np.ndarray, np.ndarray] | None = None
        self(np.zeros(1, dtype=int))

    def __call__(self, run: np.ndarray) -> np.ndarray:
        from hexapod.fk import forward_kinematics

        try:
            sol = forward_kinematics(self.geometry, self.q[0], guess=self.guess,
                                     check_stroke=False)
            self.guess = (sol.rotation, sol.translation)
            self.R[0], self.t[0] = sol.rotation, sol.translation
        except ForwardKinematicsError as exc:
            if self.guess is None:
                raise BenchmarkError(f"no platform pose for the measured lengths "
                                     f"{np.round(self.q[0] * 1e3, 3)} mm: {exc}") from None
            log.warning("forward kinematics failed (%s); keeping the last pose", exc)
        return np.zeros(len(run), dtype=bool)


class ServoCamera:
    """The loop's sensor over a :class:`FeatureSensor`: the features of the image at the
    predicted pose as the camera's batch of one (a lost frame: no edge seen, and
    ``features`` None).

    Args:
        sensor: The camera.
    """

    def __init__(self, sensor: FeatureSensor) -> None:
        self.sensor = sensor
        self.camera = sensor_camera(sensor)
        #: This period's features (None: lost frame).
        self.features: Any = None

    def observe(self, rows: np.ndarray, rotations: np.ndarray, translations: np.ndarray
                ) -> ObservationBatch:
        """The image at the pose of the one row."""
        feats = self.sensor.measure(rotations[0], translations[0])
        self.features = feats
        if feats is None:
            return camera_batch(np.full((1, 6, 2, 3), np.nan), None, np.full((1, 6, 3), np.nan),
                                np.zeros((1, 6, 2), dtype=bool), np.zeros((1, 6), dtype=bool))
        directions, both = feature_directions(feats)
        lines = feature_lines(self.camera, feats.normals)
        return camera_batch(np.asarray(feats.normals)[None],
                            None if lines is None else np.asarray(lines)[None],
                            np.asarray(directions)[None], np.asarray(feats.edge_visible)[None],
                            np.asarray(both)[None])


class ServoBook:
    """The servo session's book (:class:`benchmarks.sim.loop.LoopBook`, one row): a lost
    frame or a refused or invalid command moves nothing that period (zeros are sent, so
    the robot's watchdog never trips); the session converges after ``settle`` periods
    within both tolerances, ends with the camera's video; every period gives its
    :class:`PeriodStatus`."""

    def __init__(self, plant: Any, camera: ServoCamera, goal: Any, tolerance: float,
                 feature_tolerance: float, settle: int, result: ServoResult, t0: float,
                 declared: Any, name: str,
                 on_period: Callable[[PeriodStatus], None] | None,
                 on_pose: Callable[[np.ndarray, np.ndarray, np.ndarray | None], None] | None
                 ) -> None:
        self.active = np.ones(1, dtype=bool)
        self.plant, self.camera = plant, camera
        self.q_goal = np.asarray(goal.lengths, float)
        self.n_goal = np.asarray(goal.normals, float)
        self.vis_goal = np.asarray(goal.edge_visible, bool)
        self.tolerance, self.feature_tolerance, self.settle = (tolerance, feature_tolerance,
                                                               settle)
        self.res, self.t0 = result, t0
        self.declared, self.name = declared, name
        self.on_period, self.on_pose = on_period, on_pose
        self.settled = 0
        self.reason: str | None = None
        self.f_err = math.nan
        self.ctrl_err = math.nan
        #: The per-period camera check (``servo_loop``'s ``check``), or None.
        self.check_camera: Callable[..., Any] | None = None

    def check(self, step: int, idx: np.ndarray) -> np.ndarray:
        """Never done before the period (the session ends after a period)."""
        return np.zeros(len(idx), dtype=bool)

    def observed(self, step: int, idx: np.ndarray, obs: ObservationBatch) -> np.ndarray:
        """The feature error of this image; a lost frame (the end of a video ends the
        session)."""
        feats = self.camera.features
        self.ctrl_err = math.nan
        self.plant.use_actuation(self.declared, self.name)
        if feats is None:
            self.reason, self.f_err = "lost camera frame", math.nan
            if getattr(self.camera.sensor, "ended", False):
                self.res.outcome = "camera ended"
                self.active[:] = False
                return np.zeros(1, dtype=bool)
        if self.check_camera is not None:  # before the command; raises SessionStop
            plant = self.plant
            self.check_camera(step, plant.q[0], plant.R[0], plant.t[0],
                              None if feats is None else feats.normals,
                              None if feats is None else feats.edge_visible)
        if feats is None:
            return np.zeros(1, dtype=bool)
        self.reason = None
        self.f_err = feature_error(feats, self.n_goal, self.vis_goal)
        return np.ones(1, dtype=bool)

    def commanded(self, step: int, rows: np.ndarray, commands: Any,
                  seconds: float, crashes: dict[int, BaseException]
                  ) -> tuple[np.ndarray, np.ndarray]:
        """A refused or invalid command (of the wrong shape or kind: a
        :class:`~controllers.exceptions.CommandError`) is replaced by zeros (counted);
        none ends.

        Raises:
            Exception: The controller's own exception (the session stops with it).
        """
        from controllers.exceptions import CommandError

        crash = crashes.get(0)
        if crash is not None and not isinstance(crash, CommandError):
            raise crash
        v = commands.values[0]
        self.plant.use_actuation(commands.actuation, self.name)
        self.ctrl_err = float(commands.error_norm[0])
        self.reason = commands.reasons[0] if crash is None else str(crash)
        if self.reason is None and (v.shape != (6,) or not np.all(np.isfinite(v))):
            self.reason = f"invalid command {v!r}"
        if self.reason is not None:
            self.res.refused += 1
        return np.array([self.reason is None]), np.zeros(1, dtype=bool)

    def stopped(self, step: int, exc: Exception) -> BaseException:
        """The session stops with the controller's exception as it is."""
        return exc

    def period(self, step: int, idx: np.ndarray, done: np.ndarray, obs: ObservationBatch,
               error_norm: np.ndarray, values: np.ndarray) -> None:
        """Show the predicted pose (viewer)."""
        self.values = values[0].copy()
        if self.on_pose is not None and self.active[0]:
            feats = self.camera.features
            self.on_pose(self.plant.R[0], self.plant.t[0],
                         None if feats is None else feats.edge_visible)

    def advanced(self, step: int, run: np.ndarray, failures: dict[int, str]) -> None:
        """The period's status, and the convergence test."""
        res, plant = self.res, self.plant
        bs = plant.last[0]
        q = plant.q[0].copy()
        res.rtts.append(float(bs.round_trip_s))
        res.missed += int(bs.missed_period)
        leg_err = float(np.max(np.abs(q - self.q_goal)))
        ok = (leg_err <= self.tolerance and math.isfinite(self.f_err)
              and self.f_err <= self.feature_tolerance)
        self.settled = self.settled + 1 if ok else 0
        res.lost_frames = self.camera.sensor.lost_frames
        feats = self.camera.features
        status = PeriodStatus(
            step=step, t=time.perf_counter() - self.t0, lengths=q, leg_error=leg_err,
            feature_error=self.f_err, controller_error=self.ctrl_err, velocities=self.values,
            visible_edges=0 if feats is None else feats.visible_count, reason=self.reason,
            lost_frame=feats is None, rtt=float(bs.round_trip_s),
            missed=bool(bs.missed_period), missed_total=res.missed,
            lost_total=res.lost_frames, refused_total=res.refused)
        res.last = status
        res.steps = step + 1
        if self.on_period is not None:
            self.on_period(status)
        if self.settled >= self.settle:
            res.outcome = "converged"
            self.active[:] = False


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
