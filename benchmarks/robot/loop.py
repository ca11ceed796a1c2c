"""The real servo session (:func:`servo_loop`): the simulator's closed loop with a batch of
one, a robot behind its backend as the plant (the pose predicted from the measured
lengths), the camera's features, the controller's command, the backend's period; its book
(:class:`ServoBook`), status (one rewritten line on a terminal) and result."""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Sequence
from typing import Any, Protocol

import numpy as np

from benchmarks.robot.exits import ServoExit, SessionStop
from benchmarks.robot.goals import feature_error
from benchmarks.robot.limits import DeadlinePolicy, SessionLimits
from benchmarks.robot.models import EncoderPose
from benchmarks.robot.status import PeriodStatus, ServoResult
from benchmarks.sim.sensors import edge_batch, seen_edges
from controllers.base import ObservationBatch
from hexapod.geometry import HexapodGeometry
from vision.feature_cameras import FeatureSensor, sensor_camera

log = logging.getLogger(__name__)

#: Default number of consecutive converged periods before the loop stops.
DEFAULT_SETTLE = 5
#: Default feature-error tolerance (norm of the stacked normal differences) [-].
DEFAULT_FEATURE_TOLERANCE = 2e-3


class PeriodCheck(Protocol):
    """A per-period safety check of a session (the camera check, the signals), called
    every period right after the image, before the controller runs (not in the period
    where the camera reports its end if its ``needs_image`` attribute is true)."""

    def __call__(self, step: int, lengths: np.ndarray, features: Any) -> None:
        """Check period ``step`` (from 0): ``lengths`` (6,) measured when the image was
        taken [m], ``features`` its :class:`~vision.feature_cameras.Features` (None: no
        image).

        Raises:
            SessionStop: End the session (through its one shutdown).
        """
        ...


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
    *,
    limits: SessionLimits | None = None,
    checks: Sequence[PeriodCheck] = (),
    warn: Callable[[str], None] | None = None,
    result: ServoResult | None = None,
) -> ServoResult:
    """Run a reset controller on a connected robot (the plant a
    :class:`~benchmarks.sim.plant.BackendPlant`, the camera a :class:`ServoCamera`, the
    book a :class:`ServoBook`) until convergence, a limit, a stop request (outcome
    ``"stopped"``, ``result.stop``) or Ctrl-C (``"interrupted"``); any other exception
    propagates. The caller halts the robot.

    Args:
        robot: A connected backend (a :class:`~benchmarks.robot.limits.LimitedRobot` when
            ``limits`` are given).
        sensor: The camera.
        controller: A controller already reset with its context.
        goal: The controller's :class:`~controllers.base.Goal` (lengths, normals).
        geometry: The nominal robot (forward kinematics).
        dt: Control period [s].
        max_steps: Period budget (None: none).
        tolerance: Convergence threshold on max |q - q*| [m].
        feature_tolerance: Convergence threshold on the feature error [-].
        settle: Consecutive periods within both tolerances to stop.
        on_period: Called after every period (status line, log).
        on_pose: Called with the predicted pose and edge visibility (viewer).
        limits: The session's time and missed-deadline limits (None: none).
        checks: Per-period checks (:class:`PeriodCheck`), in order.
        warn: Shows a warning line (missed deadlines; default: the log).
        result: The result to fill (kept by the caller if the loop raises).

    Returns:
        The outcome and the link statistics.
    """
    from benchmarks.sim.loop import closed_loop
    from benchmarks.sim.plant import BackendPlant, reading_problem
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
    res = result if result is not None else ServoResult("max-steps", 0, 0.0)
    res.outcome = "max-steps"
    t0 = time.perf_counter()
    try:
        q = np.asarray(robot.measured_lengths(), float)[None].copy()
        problem = reading_problem(q[0], geometry.stroke)
        if problem is not None:  # before the first command
            raise SessionStop(ServoExit.SAFETY, f"at the start: {problem}")
        deadlines = None if limits is None else DeadlinePolicy(
            limits, dt, warn if warn is not None else log.warning)
        R, t = np.zeros((1, 3, 3)), np.zeros((1, 3))
        encoder_pose = EncoderPose(geometry)

        def poses(run: np.ndarray) -> np.ndarray:  # the encoder pose of the lengths
            R[0], t[0] = encoder_pose(q[0])
            return np.zeros(len(run), dtype=bool)

        poses(np.zeros(1, dtype=int))
        plant = BackendPlant([robot], q, R, t, np.zeros((1, 6)), poses, geometry.stroke)
        plant.use_actuation(declared, name)
        book = ServoBook(plant, camera, goal, tolerance, feature_tolerance, settle, res, t0,
                         declared, name, on_period, on_pose, checks=checks, limits=limits,
                         deadlines=deadlines)
        closed_loop(plant, camera, None, one, book, dt, np.zeros((1, 6)),
                    None if max_steps is None else max_steps - 1)
    except KeyboardInterrupt:
        res.outcome = "interrupted"
    except SessionStop as stop:
        res.outcome, res.stop = "stopped", stop
    finally:
        res.wall_s = time.perf_counter() - t0
    return res


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
        #: Time spent getting this period's image and its edges [s].
        self.seconds = 0.0

    def observe(self, rows: np.ndarray, rotations: np.ndarray, translations: np.ndarray
                ) -> ObservationBatch:
        """The image at the pose of the one row."""
        t0 = time.perf_counter()
        feats = self.sensor.measure(rotations[0], translations[0])
        self.seconds = time.perf_counter() - t0
        self.features = feats
        if feats is None:
            return edge_batch(np.full((1, 6, 2, 3), np.nan), None,
                              np.zeros((1, 6, 2), dtype=bool))
        return seen_edges(self.camera, np.asarray(feats.normals, float)[None],
                          np.asarray(feats.edge_visible, bool)[None])


class ServoBook:
    """The servo session's book (:class:`benchmarks.sim.loop.LoopBook`, one row): a lost
    frame or a refused or invalid command sends zeros (the robot's watchdog stays fed);
    the session converges after ``settle`` periods within both tolerances or ends with
    the camera's video. The ``checks`` run after each image, the time limit and the
    deadline policy after each period."""

    def __init__(self, plant: Any, camera: ServoCamera, goal: Any, tolerance: float,
                 feature_tolerance: float, settle: int, result: ServoResult, t0: float,
                 declared: Any, name: str,
                 on_period: Callable[[PeriodStatus], None] | None,
                 on_pose: Callable[[np.ndarray, np.ndarray, np.ndarray | None], None] | None,
                 *, checks: Sequence[PeriodCheck] = (), limits: SessionLimits | None = None,
                 deadlines: DeadlinePolicy | None = None) -> None:
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
        self.checks, self.limits, self.deadlines = tuple(checks), limits, deadlines
        self.controller_s = 0.0
        self._lost_seen = camera.sensor.lost_frames

    def check(self, step: int, idx: np.ndarray) -> np.ndarray:
        """Never done before the period (the session ends after a period)."""
        return np.zeros(len(idx), dtype=bool)

    def observed(self, step: int, idx: np.ndarray, obs: ObservationBatch) -> np.ndarray:
        """The feature error of this image; a lost frame (the end of a video ends the
        session)."""
        feats = self.camera.features
        self.ctrl_err = math.nan
        self.controller_s = 0.0
        self.plant.use_actuation(self.declared, self.name)
        ended = feats is None and bool(getattr(self.camera.sensor, "ended", False))
        for check in self.checks:
            if not (ended and getattr(check, "needs_image", False)):
                check(step, self.plant.q[0].copy(), feats)
        if feats is None:
            self.reason, self.f_err = "lost camera frame", math.nan
            if ended:
                self.res.outcome = "camera ended"
                self.active[:] = False
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
        self.controller_s = float(seconds)
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
        """The period's status, and the convergence test.

        Raises:
            SessionStop: ``SAFETY``: the robot's reading cannot be its legs (not a number,
                millimetres for metres: :func:`benchmarks.sim.plant.reading_problem`).
        """
        if failures:
            raise SessionStop(ServoExit.SAFETY, f"period {step}: {failures[0]}")
        res, plant = self.res, self.plant
        bs = plant.last[0]
        q = plant.q[0].copy()
        link_s = float(bs.round_trip_s)
        compute_s = self.camera.seconds + self.controller_s
        res.rtts.append(link_s)
        res.compute.append(compute_s)
        res.missed += int(bs.missed_period)
        leg_err = float(np.max(np.abs(q - self.q_goal)))
        ok = (leg_err <= self.tolerance and math.isfinite(self.f_err)
              and self.f_err <= self.feature_tolerance)
        self.settled = self.settled + 1 if ok else 0
        lost_now = self.camera.sensor.lost_frames
        lost = lost_now - self._lost_seen
        self._lost_seen = lost_now
        res.lost_frames += lost
        feats = self.camera.features
        status = PeriodStatus(
            step=step, t=time.perf_counter() - self.t0, lengths=q, leg_error=leg_err,
            feature_error=self.f_err, controller_error=self.ctrl_err, velocities=self.values,
            visible_edges=0 if feats is None else feats.visible_count, reason=self.reason,
            lost_frame=feats is None, rtt=link_s,
            missed=bool(bs.missed_period), missed_total=res.missed,
            lost_total=res.lost_frames, refused_total=res.refused,
            applied=np.asarray(bs.applied_velocities, float).copy(),
            clamped=np.asarray(bs.clamped, bool).copy(), camera_s=self.camera.seconds,
            controller_s=self.controller_s, lost_frames=lost)
        res.last = status
        res.steps = step + 1
        if self.on_period is not None:
            self.on_period(status)
        if self.settled >= self.settle:
            res.outcome = "converged"
            self.active[:] = False
            return
        if self.deadlines is not None:
            self.deadlines.update(step, bool(bs.missed_period), compute_s, link_s)
        limit = None if self.limits is None else self.limits.max_time
        if limit is not None and status.t >= limit:
            raise SessionStop(ServoExit.LIMIT, f"--max-time-s {limit:g} reached after "
                                               f"{res.steps} periods ({status.t:.2f} s)")
