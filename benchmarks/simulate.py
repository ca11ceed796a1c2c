"""Closed-loop trials: true world -> sensor -> controller -> backend -> true world.

One trial (ARCHITECTURE.md, "one control step, as data"): the true world (true
geometry, true camera, true pose) produces observations through :mod:`vision`
(geometric features + noise, or rendered images + detection); the controller,
built from the ESTIMATED parameters, returns leg velocities; the backend clamps
them to the stroke and speed limits and applies them for ``dt``; the new true
pose is the forward kinematics of the TRUE geometry, warm-started.

Trials that share one true world (no calibration error) are stepped together,
vectorised over a leading axis; each trial has its own random streams seeded
from ``(scenario seed, trial index)``, so a trial's result does not depend on
which other trials run beside it (nor on the executor or the chunking).
"""

from __future__ import annotations

import logging
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from benchmarks.scenario import Scenario
from controllers.base import Command, ControllerContext, Goal, Observation, registry
from hexapod import HexapodGeometry, Transform, forward_kinematics_batch
from hexapod.backends.base import Backend, clamp_velocities
from hexapod.exceptions import HexapodError
from hexapod.geometry import preset as geometry_preset
from hexapod.kinematics import inverse_kinematics
from hexapod.se3 import exp_so3, pose_error
from hexapod.workspace import sample_poses
from vision.cameras import Camera, camera_preset
from vision.exceptions import VisionError
from vision.legs import directions_from_edges, observe_legs

log = logging.getLogger(__name__)

#: Consecutive refused steps after which a trial is declared failed.
MAX_REFUSED_STEPS = 25


def load_geometry(scenario: Scenario) -> HexapodGeometry:
    """The nominal geometry of a scenario."""
    if scenario.robot_geometry is not None:
        return HexapodGeometry.from_toml(scenario.robot_geometry)
    return geometry_preset(scenario.robot_preset or "deltalab")


def load_camera(scenario: Scenario, geometry: HexapodGeometry) -> Camera:
    """The nominal camera of a scenario."""
    if scenario.camera_file is not None:
        from vision.cameras import load_camera as _load

        return _load(scenario.camera_file)
    return camera_preset(scenario.camera_preset or "front", geometry)


@dataclass
class World:
    """The truth of one trial (never shown to the controller).

    Attributes:
        geometry: True geometry.
        camera: True camera (intrinsics and pose).
        joint_offsets: (6,) encoder offsets [m]: measured = true + offset.
    """

    geometry: HexapodGeometry
    camera: Camera
    joint_offsets: np.ndarray

    @property
    def shared_key(self) -> tuple[int, int] | None:
        """Identity of a world shared by several trials (None when it is trial-specific)."""
        return None


@dataclass
class TrialSetup:
    """Everything one trial needs, drawn from its seed.

    Attributes:
        trial: Trial index.
        world: The truth.
        nominal_geometry: What the user believes the robot is.
        estimated_camera: What the user believes the camera is.
        base_points: (6, 3) estimated base points in the camera frame [m].
        start_rotation, start_translation: True start pose (base frame).
        goal_rotation, goal_translation: True goal pose (base frame).
        start_lengths: (6,) true start leg lengths [m].
        shared: True when the world is the nominal one (trials can be batched).
        calibration: Calibration summary when the scenario calibrates first.
    """

    trial: int
    world: World
    nominal_geometry: HexapodGeometry
    estimated_camera: Camera
    base_points: np.ndarray
    start_rotation: np.ndarray
    start_translation: np.ndarray
    goal_rotation: np.ndarray
    goal_translation: np.ndarray
    start_lengths: np.ndarray
    shared: bool
    calibration: dict[str, float] = field(default_factory=dict)


def trial_rng(seed: int, trial: int, stream: int) -> np.random.Generator:
    """The random stream ``stream`` of trial ``trial`` (0: world, 1: sensor, 2: goal image)."""
    return np.random.default_rng([int(seed), int(trial), int(stream)])


def _perturb_camera(camera: Camera, z_rot: np.ndarray, z_pos: np.ndarray, z_k: np.ndarray,
                    ce: Any) -> Camera:
    T = camera.camera_from_base
    dR = exp_so3(np.deg2rad(ce.camera_pose_deg) * z_rot)
    dp = 1e-3 * ce.camera_pose_mm * z_pos
    new_T = Transform(dR @ T.rotation, dR @ T.translation + dp)
    K = camera.K.copy()
    s = 1e-2 * ce.intrinsics_percent
    K[0, 0] *= 1 + s * z_k[0]
    K[1, 1] *= 1 + s * z_k[1]
    K[0, 2] *= 1 + s * z_k[2]
    K[1, 2] *= 1 + s * z_k[3]
    return camera.replace(K=K, camera_from_base=new_T)


def make_trial(sc: Scenario, trial: int, nominal: HexapodGeometry, camera: Camera,
               calibrate: Callable[[World, np.random.Generator], tuple[np.ndarray,
                                                                       dict[str, float]]]
               | None = None) -> TrialSetup:
    """Draw the truth, start and goal of one trial from ``(seed, trial)``.

    The standard-normal draws are made in a fixed order whatever the scenario's
    error magnitudes, so trials are paired across the points of a sweep.
    """
    rng = trial_rng(sc.seed, trial, 0)
    z_base = rng.standard_normal((6, 3))
    z_plat = rng.standard_normal((6, 3))
    z_off = rng.standard_normal(6)
    z_rot = rng.standard_normal(3)
    z_pos = rng.standard_normal(3)
    z_k = rng.standard_normal(4)
    z_r = rng.standard_normal()
    ce = sc.calibration_error
    ce = type(ce)(**{k: (getattr(ce, k) * ce.scale if k != "scale" else 1.0)
                     for k in ce.__dataclass_fields__})
    shared = all(getattr(ce, k) == 0.0 for k in ce.__dataclass_fields__ if k != "scale")
    if shared:
        true_geometry, true_camera, offsets = nominal, camera, np.zeros(6)
    else:
        true_geometry = nominal.replace(
            base_points=nominal.base_points + 1e-3 * ce.base_points_mm * z_base,
            platform_points=nominal.platform_points + 1e-3 * ce.platform_points_mm * z_plat,
            leg_radius=nominal.leg_radius * (1 + 1e-2 * ce.leg_radius_percent * z_r),
        )
        true_camera = _perturb_camera(camera, z_rot, z_pos, z_k, ce)
        offsets = 1e-3 * ce.joint_offsets_mm * z_off
    world = World(true_geometry, true_camera, offsets)

    task = sc.task
    if task.kind == "fixed":
        q_start = np.asarray(task.start_mm, float) * 1e-3
        q_goal = np.asarray(task.goal_mm, float) * 1e-3
        sol = forward_kinematics_batch(true_geometry, np.stack([q_start, q_goal]))
        if not np.all(sol.converged):
            raise ValueError(f"{sc.source}: task start/goal leg lengths have no pose")
        R_s, R_g = sol.rotations
        t_s, t_g = sol.translations
    else:
        R, t = sample_poses(true_geometry, 2, rng=rng,
                            max_translation=1e-3 * task.max_translation_mm,
                            max_angle=np.deg2rad(task.max_angle_deg),
                            margin=1e-3 * task.margin_mm)
        R_s, R_g = R
        t_s, t_g = t
    q_s = inverse_kinematics(true_geometry, R_s, t_s)
    base_points = camera.camera_from_base.apply(nominal.base_points)
    calibration: dict[str, float] = {}
    if calibrate is not None:
        base_points, calibration = calibrate(world, trial_rng(sc.seed, trial, 3))
    return TrialSetup(trial, world, nominal, camera, base_points, R_s, t_s, R_g, t_g, q_s,
                      shared, calibration)


class GeometricSensor:
    """Features from the true geometry plus the scenario's noise model.

    Rotation noise perturbs each true edge normal; the perspective image lines
    follow from the noisy normals through the TRUE camera, and the normals the
    controller receives are recomputed from those lines with the ESTIMATED
    intrinsics (so an intrinsics error reaches the controller as it would).
    Pixel noise samples points along each visible edge, perturbs them and fits
    the normal on the points lifted with the estimated camera.
    """

    def __init__(self, sc: Scenario, world: World, estimated_camera: Camera) -> None:
        self.sc = sc
        self.world = world
        self.est: Any = estimated_camera  # a PerspectiveCamera when ``perspective``
        self.perspective = world.camera.kind == "perspective"

    def measure(self, rotations: np.ndarray, translations: np.ndarray,
                rngs: list[np.random.Generator], apply_noise: bool = True
                ) -> dict[str, Any]:
        """Batched measurement at true poses (N, 3, 3), (N, 3); one generator per item."""
        w = self.world
        lo = observe_legs(w.camera, w.geometry, rotations, translations)
        normals = np.array(lo.normals, dtype=float)
        visible = np.array(lo.edge_visible, dtype=bool)
        noise = self.sc.noise
        n = len(rngs)
        if apply_noise and noise.model == "rotation" and noise.amplitude_deg > 0:
            from vision.noise import rotation_noise

            a = np.deg2rad(noise.amplitude_deg)
            for k in range(n):
                normals[k] = rotation_noise(normals[k], a, rngs[k])
        elif apply_noise and noise.model == "pixel":
            normals, visible = self._pixel_noise(lo, normals, visible, rngs)
        if apply_noise and noise.dropout_probability > 0:
            for k in range(n):
                visible[k] &= rngs[k].uniform(size=(6, 2)) >= noise.dropout_probability
        normals = np.where(visible[..., None], normals, np.nan)
        lines = None
        if self.perspective:
            if noise.model == "pixel" and apply_noise:
                # fitted with the estimated camera already; the image line is the true one
                lines = self.est.normal_to_line(normals)
            else:
                true_camera: Any = w.camera
                lines = true_camera.normal_to_line(normals)
                normals = self.est.line_to_normal(lines)
        both = np.asarray(visible.all(axis=-1))
        with np.errstate(invalid="ignore"):
            directions = directions_from_edges(normals)
        directions = np.where(both[..., None], directions, np.nan)
        return {"normals": normals, "lines": lines, "directions": directions,
                "edge_visible": visible, "direction_visible": both}

    def measure_goal(self, rotation: np.ndarray, translation: np.ndarray,
                     rng: np.random.Generator, frames: int = 1, apply_noise: bool = True
                     ) -> dict[str, Any]:
        """The desired features: ``frames`` measurements at one true pose, averaged.

        Args:
            rotation: (3, 3) true goal orientation (base frame).
            translation: (3,) true goal position (base frame) [m].
            rng: Generator of the noise of the goal measurements.
            frames: Measurements averaged (:func:`vision.estimate.average_normals`).
            apply_noise: Whether the scenario's noise applies (``[noise] on_goal``).

        Returns:
            The batched measurement dictionary of :meth:`measure`, batch of one.
        """
        R = np.repeat(np.asarray(rotation, float)[None], frames, axis=0)
        t = np.repeat(np.asarray(translation, float)[None], frames, axis=0)
        m = self.measure(R, t, [rng] * frames, apply_noise=apply_noise)
        return _average_frames(m, self.est if self.perspective else None)

    def _pixel_noise(self, lo: Any, normals: np.ndarray, visible: np.ndarray,
                     rngs: list[np.random.Generator]) -> tuple[np.ndarray, np.ndarray]:
        from vision.pixel_measure import normals_from_noisy_pixels

        noise = self.sc.noise
        out = normals.copy()
        vis = visible.copy()
        for k in range(len(rngs)):  # one generator per trial: results do not depend on batching
            sub = _take(lo, k)
            n_k, v_k = normals_from_noisy_pixels(self.world.camera, self.est, sub,
                                                 noise.pixel_sigma_px,
                                                 max(int(noise.points_per_edge), 2), rngs[k],
                                                 noise.outlier_fraction)
            out[k] = n_k
            vis[k] = v_k
        return out, vis


def _take(lo: Any, k: int) -> Any:
    """Item ``k`` of a batched :class:`vision.legs.LegObservation`."""
    from dataclasses import fields as dc_fields
    from dataclasses import replace as dc_replace

    changes = {}
    for f in dc_fields(lo):
        value = getattr(lo, f.name)
        if isinstance(value, np.ndarray) and value.ndim >= 1:
            changes[f.name] = value[k]
    return dc_replace(lo, **changes)


def _average_frames(m: dict[str, Any], perspective_camera: Any | None,
                    max_deviation: float | None = None) -> dict[str, Any]:
    """Average K measurements of one static pose (leading axis K) into a batch of one.

    Normals: :func:`vision.estimate.average_normals` (frames farther than
    ``max_deviation`` [rad] from the median do not count; an edge kept in fewer than
    half of the frames is missing); lines: the averaged normals seen by the estimated
    perspective camera (``perspective_camera``, None for a unified camera). One frame
    is returned unchanged.
    """
    from vision.estimate import average_normals

    if len(m["normals"]) == 1:
        return m
    normals, visible = average_normals(m["normals"], m["edge_visible"],
                                       max_deviation=max_deviation)
    lines = None
    if perspective_camera is not None:
        with np.errstate(invalid="ignore"):
            lines = perspective_camera.normal_to_line(normals)[None]
    both = np.asarray(visible.all(axis=-1))
    with np.errstate(invalid="ignore"):
        directions = directions_from_edges(normals)
    return {"normals": normals[None], "lines": lines,
            "directions": np.where(both[..., None], directions, np.nan)[None],
            "edge_visible": visible[None], "direction_visible": both[None]}


@dataclass
class TrialResult:
    """Outcome of one trial (one row of ``results.jsonl``) and its time series."""

    row: dict[str, Any]
    series: dict[str, np.ndarray] | None = None


def trial_goal(sensor: GeometricSensor | Any, setup: TrialSetup, sc: Scenario) -> Goal:
    """What the controllers are told about the goal of a trial.

    The desired features are taught by showing: the sensor measures the TRUE goal pose
    ``sc.teach_frames`` times (with the scenario's noise when ``[noise] on_goal``; an
    image sensor renders and detects each frame) and the normals are averaged
    (:func:`vision.estimate.average_normals`). The pose and its nominal inverse
    kinematics are for the model-based and joint-space baselines.

    Args:
        sensor: The trial's sensor (:func:`make_sensor`).
        setup: The trial.
        sc: The scenario (``teach_frames``, ``noise.on_goal``).

    Returns:
        The :class:`~controllers.base.Goal`.
    """
    rng = trial_rng(sc.seed, setup.trial, 2)
    m = sensor.measure_goal(setup.goal_rotation, setup.goal_translation, rng,
                            frames=sc.teach_frames, apply_noise=sc.noise.on_goal)
    nominal_lengths = inverse_kinematics(setup.nominal_geometry, setup.goal_rotation,
                                         setup.goal_translation)
    return Goal(
        normals=m["normals"][0],
        lines=None if m["lines"] is None else m["lines"][0],
        directions=m["directions"][0],
        lengths=nominal_lengths,
        rotation=setup.goal_rotation,
        translation=setup.goal_translation,
        edge_visible=m["edge_visible"][0],
    )


def make_sensor(sc: Scenario, setup: TrialSetup) -> Any:
    """The sensor of a trial: a :class:`GeometricSensor`, or rendered images through
    :class:`vision.image_sensor.ImageSensor` (``[sensor] kind = "image"``; pixel noise
    from the trial's stream 4)."""
    if sc.sensor == "image":
        from vision.image_sensor import ImageSensor

        return _ImageSensorAdapter(ImageSensor(
            setup.world.camera, setup.estimated_camera, setup.world.geometry,
            rng=trial_rng(sc.seed, setup.trial, 4), background=sc.image.background,
            blur_px=sc.image.blur_px, noise_std=sc.image.noise_std,
            estimated_geometry=setup.nominal_geometry))
    return GeometricSensor(sc, setup.world, setup.estimated_camera)


class _ImageSensorAdapter:
    """Adapts :class:`vision.image_sensor.ImageSensor` to the batched sensor interface.

    During a run each trial's detector tracks the edges found in that trial's last
    measurement (the others come from the aligned model prediction), keyed by the
    trial's sensor generator (alive for the whole run). The goal frames are detected
    from the model's prediction and never seed the tracking.
    """

    def __init__(self, sensor: Any) -> None:
        self.sensor = sensor
        self.detect_times: list[float] = []
        self._previous: dict[int, np.ndarray] = {}  # last normals per trial (tracking)

    def measure_goal(self, rotation: np.ndarray, translation: np.ndarray,
                     rng: np.random.Generator, frames: int = 1, apply_noise: bool = True
                     ) -> dict[str, Any]:
        """``frames`` rendered images of the goal pose, each detected from the model's
        prediction (wide search, then refine), their normals averaged. A frame whose
        edge is farther from the median of the frames than the detector's inlier
        distance (``outlier_px``, turned into an angle by
        :func:`vision.estimate.radians_per_pixel`) does not count for that edge: the
        detector locked onto something else in that frame.

        ``rng`` and ``apply_noise`` are unused: the pixel noise is the renderer's.
        """
        from vision.estimate import radians_per_pixel

        normals, visible = [], []
        for _ in range(frames):
            m = self.sensor.measure(rotation, translation)
            normals.append(np.asarray(m.normals, float))
            visible.append(np.asarray(m.edge_visible, bool))
        n = np.array(normals)
        vis = np.array(visible)
        est = self.sensor.estimated_camera
        lines = None
        if est.kind == "perspective":
            with np.errstate(invalid="ignore"):
                lines = est.normal_to_line(n)
        both = np.asarray(vis.all(axis=-1))
        with np.errstate(invalid="ignore"):
            directions = directions_from_edges(n)
        m_all = {"normals": n, "lines": lines,
                 "directions": np.where(both[..., None], directions, np.nan),
                 "edge_visible": vis, "direction_visible": both}
        tolerance = self.sensor.detector.outlier_px * radians_per_pixel(est)
        return _average_frames(m_all, est if est.kind == "perspective" else None, tolerance)

    def measure(self, rotations: np.ndarray, translations: np.ndarray,
                rngs: list[np.random.Generator], apply_noise: bool = True
                ) -> dict[str, Any]:
        out: dict[str, list[Any]] = {"normals": [], "lines": [], "edge_visible": []}
        for k in range(len(rotations)):
            key = id(rngs[k])
            prev = self._previous.get(key) if apply_noise else None
            m = self.sensor.measure(rotations[k], translations[k], predicted_normals=prev)
            if apply_noise and np.any(np.asarray(m.edge_visible)):
                self._previous[key] = np.asarray(m.normals)  # NaN where not found
            else:
                self._previous.pop(key, None)
            self.detect_times.append(float(m.detect_time_s))
            out["normals"].append(m.normals)
            out["lines"].append(m.lines)
            out["edge_visible"].append(m.edge_visible)
        normals = np.array(out["normals"], float)
        visible = np.array(out["edge_visible"], bool)
        both = np.asarray(visible.all(axis=-1))
        with np.errstate(invalid="ignore"):
            directions = directions_from_edges(normals)
        lines = None if out["lines"][0] is None else np.array(out["lines"], float)
        return {"normals": normals, "lines": lines,
                "directions": np.where(both[..., None], directions, np.nan),
                "edge_visible": visible, "direction_visible": both}


def run_trials(
    sc: Scenario,
    controller_index: int,
    trials: list[int],
    record_trials: int = 0,
    backend_factory: Callable[[HexapodGeometry, np.ndarray], Backend] | None = None,
    calibrate: Callable[[World, np.random.Generator], tuple[np.ndarray, dict[str, float]]]
    | None = None,
    on_step: Callable[[int, np.ndarray, np.ndarray, np.ndarray], None] | None = None,
    sensor_factory: Callable[[Scenario, TrialSetup], Any] | None = None,
) -> list[TrialResult]:
    """Run trials of one scenario point with one controller.

    Trials whose world is the nominal one are stepped together (vectorised);
    the others one by one. A crash in a trial is recorded as its failure.

    Args:
        sc: An expanded scenario (one sweep point).
        controller_index: Index into ``sc.controllers``.
        trials: Trial indices.
        record_trials: Trials with an index below this keep their time series.
        backend_factory: Builds a backend for a trial from the true geometry and
            start lengths (default: exact integration of the clamped command).
        calibrate: Optional calibration run per trial (returns estimated base points).
        on_step: Callback ``(trial, rotation, translation, edge_visible)`` for a live view.
        sensor_factory: Builds the sensor of a group of trials from the scenario and its
            first trial (default :func:`make_sensor`; studies swap sensors with it). The
            sensor has ``measure`` and ``measure_goal`` like :class:`GeometricSensor`.

    Returns:
        One :class:`TrialResult` per trial, in the order of ``trials``.
    """
    spec = sc.controllers[controller_index]
    nominal = load_geometry(sc)
    camera = load_camera(sc, nominal)
    results: dict[int, TrialResult] = {}
    setups: list[TrialSetup] = []
    for k in trials:
        try:
            setups.append(make_trial(sc, k, nominal, camera, calibrate))
        except Exception as exc:  # a crash in one trial is that trial's failure
            results[k] = TrialResult(_failure_row(sc, spec, k, exc))
    shared = [s for s in setups if s.shared and backend_factory is None]
    single = [s for s in setups if not (s.shared and backend_factory is None)]
    groups = ([shared] if shared else []) + [[s] for s in single]
    for group in groups:
        opened: list[Backend] = []
        try:
            for res in _run_group(sc, controller_index, group, record_trials, backend_factory,
                                  on_step, opened, sensor_factory):
                results[res.row["trial"]] = res
        except Exception as exc:
            if len(group) == 1:
                results[group[0].trial] = TrialResult(_failure_row(sc, spec, group[0].trial,
                                                                   exc))
            else:  # isolate the failing trial(s): run them one by one
                for s in group:
                    single_opened: list[Backend] = []
                    try:
                        res = _run_group(sc, controller_index, [s], record_trials,
                                         backend_factory, on_step, single_opened,
                                         sensor_factory)[0]
                    except Exception as exc2:
                        res = TrialResult(_failure_row(sc, spec, s.trial, exc2))
                    finally:
                        _close_all(single_opened)
                    results[s.trial] = res
        finally:
            _close_all(opened)
    return [results[k] for k in trials]


def _close_all(backends: list[Backend]) -> None:
    """Halt and close backends, whatever happened (a robot is never left moving)."""
    for b in backends:
        try:
            b.halt()
        except Exception as exc:  # already failing: report and go on closing
            log.warning("halting a backend failed: %s", exc)
        finally:
            b.close()


def _base_row(sc: Scenario, spec: Any, trial: int) -> dict[str, Any]:
    info = None
    try:
        info = registry.source(spec.name)
    except Exception:  # reported as the trial failure below
        info = None
    row: dict[str, Any] = {
        "scenario": sc.name,
        "controller": spec.label,
        "controller_name": spec.name,
        "controller_package": info.package if info else None,
        "controller_version": info.version if info else None,
        "trial": int(trial),
    }
    for key, value in sc.sweep.items():
        row[key.replace(".", "_").replace("calibration_error_", "calib_")] = value
    return row


def _failure_row(sc: Scenario, spec: Any, trial: int, exc: BaseException) -> dict[str, Any]:
    row = _base_row(sc, spec, trial)
    row.update({
        "converged": False, "steps": 0, "final_position_error_mm": None,
        "final_orientation_error_deg": None, "stroke_violations": 0, "step_time_us": None,
        "failure": f"{type(exc).__name__}: {exc}",
    })
    if isinstance(exc, HexapodError | VisionError):  # the user's data: the message says it
        log.warning("trial %s/%s/%d failed: %s", sc.name, spec.label, trial, exc)
    else:
        log.warning("trial %s/%s/%d failed: %s\n%s", sc.name, spec.label, trial, exc,
                    traceback.format_exc())
    return row


def _run_group(sc: Scenario, controller_index: int, group: list[TrialSetup],
               record_trials: int,
               backend_factory: Callable[[HexapodGeometry, np.ndarray], Backend] | None,
               on_step: Callable[[int, np.ndarray, np.ndarray, np.ndarray], None] | None,
               opened: list[Backend] | None = None,
               sensor_factory: Callable[[Scenario, TrialSetup], Any] | None = None
               ) -> list[TrialResult]:
    """Run trials sharing one world in lockstep (backends it opens go to ``opened``)."""
    if opened is None:
        opened = []
    spec = sc.controllers[controller_index]
    n = len(group)
    world = group[0].world
    g = world.geometry
    sensor = (sensor_factory or make_sensor)(sc, group[0])
    controllers = []
    for s in group:
        ctrl = registry.create(spec.name, **spec.options)
        goal = trial_goal(sensor, s, sc)
        ctx = ControllerContext(base_points=s.base_points, geometry=s.nominal_geometry,
                                camera=s.estimated_camera, dt=sc.dt, goal=goal)
        ctrl.reset(ctx)
        controllers.append(ctrl)
    rngs = [trial_rng(sc.seed, s.trial, 1) for s in group]
    backends = None
    if backend_factory is not None:
        backends = []
        for s in group:
            backends.append(backend_factory(g, s.start_lengths + world.joint_offsets))
            opened.append(backends[-1])
    q = np.array([s.start_lengths for s in group])
    R = np.array([s.start_rotation for s in group])
    t = np.array([s.start_translation for s in group])
    R_goal = np.array([s.goal_rotation for s in group])
    t_goal = np.array([s.goal_translation for s in group])
    offsets = world.joint_offsets
    pos_tol = 1e-3 * sc.task.position_tolerance_mm
    ori_tol = np.deg2rad(sc.task.orientation_tolerance_deg)
    active = np.ones(n, dtype=bool)
    steps = np.zeros(n, dtype=int)
    settled = np.zeros(n, dtype=int)
    last_bad = np.full(n, -1)
    tail_start = sc.task.max_steps - max(1, sc.task.max_steps // 5)
    tail_pos: list[list[float]] = [[] for _ in range(n)]
    tail_ori: list[list[float]] = [[] for _ in range(n)]
    converged = np.zeros(n, dtype=bool)
    violations = np.zeros(n, dtype=int)
    refused = np.zeros(n, dtype=int)
    failure: list[str | None] = [None] * n
    step_times: list[list[float]] = [[] for _ in range(n)]
    rtts: list[list[float]] = [[] for _ in range(n)]
    missed = np.zeros(n, dtype=int)
    recording = [s.trial < record_trials for s in group]
    series: list[dict[str, list[Any]]] = [
        {k: [] for k in ("t", "lengths", "rotations", "translations", "edge_visible",
                         "error_norm", "position_error", "orientation_error", "velocities")}
        if rec else {} for rec in recording
    ]
    dt = sc.dt
    for step in range(sc.task.max_steps + 1):
        idx = np.flatnonzero(active)
        if len(idx) == 0:
            break
        dp, da = pose_error(R[idx], t[idx], R_goal[idx], t_goal[idx])
        ok = (dp < pos_tol) & (da < ori_tol)
        settled[idx] = np.where(ok, settled[idx] + 1, 0)
        last_bad[idx[~ok]] = step
        if sc.task.fixed_duration and step > tail_start:
            for j, k in enumerate(idx):
                tail_pos[k].append(float(dp[j]))
                tail_ori[k].append(float(da[j]))
        if sc.task.fixed_duration:
            done = np.full(len(idx), step == sc.task.max_steps)
            converged[idx] = ok
        else:
            done = settled[idx] >= sc.task.settle_steps
            converged[idx[done]] = True
            if step == sc.task.max_steps:
                done[:] = True
        meas = sensor.measure(R[idx], t[idx], [rngs[k] for k in idx])
        if on_step is not None:
            for j, k in enumerate(idx):
                on_step(group[k].trial, R[k], t[k], meas["edge_visible"][j])
        v_cmd = np.zeros((len(idx), 6))
        for j, k in enumerate(idx):
            obs = Observation(
                t=step * dt, lengths=q[k] + offsets,
                normals=meas["normals"][j],
                lines=None if meas["lines"] is None else meas["lines"][j],
                directions=meas["directions"][j],
                edge_visible=meas["edge_visible"][j],
                direction_visible=meas["direction_visible"][j],
            )
            cmd: Command | None = None
            if not done[j]:
                t0 = time.perf_counter()
                cmd = controllers[k].step(obs)
                step_times[k].append(time.perf_counter() - t0)
                vel = np.asarray(cmd.velocities, dtype=float)
                if vel.shape != (6,) or not np.all(np.isfinite(vel)):
                    failure[k] = f"controller returned an invalid command {vel!r}"
                    done[j] = True
                else:
                    v_cmd[j] = vel
                if cmd.reason is not None:
                    refused[k] += 1
                    if refused[k] >= MAX_REFUSED_STEPS:
                        failure[k] = f"controller refused to move: {cmd.reason}"
                        done[j] = True
                else:
                    refused[k] = 0
            if recording[k]:
                ser = series[k]
                ser["t"].append(step * dt)
                ser["lengths"].append(q[k].copy())
                ser["rotations"].append(R[k].copy())
                ser["translations"].append(t[k].copy())
                ser["edge_visible"].append(meas["edge_visible"][j].copy())
                ser["error_norm"].append(cmd.error_norm if cmd is not None else np.nan)
                ser["position_error"].append(dp[j])
                ser["orientation_error"].append(da[j])
                ser["velocities"].append(v_cmd[j].copy())
        finished = idx[done]
        active[finished] = False
        for k in finished:
            steps[k] = step
        run = idx[~done]
        if len(run) == 0:
            continue
        v_run = v_cmd[~done]
        # a stroke violation: the (speed-limited) command would leave the stroke this period
        q_next = q[run] + np.clip(v_run, -g.max_speed, g.max_speed) * dt
        violations[run] += np.any((q_next < g.stroke[0] - 1e-9) | (q_next > g.stroke[1] + 1e-9),
                                  axis=1)
        if backends is None:
            vc, _ = clamp_velocities(q[run], v_run, dt, g.stroke, g.max_speed)
            q[run] = np.clip(q[run] + vc * dt, *g.stroke)
        else:
            for j, k in enumerate(run):
                bs = backends[k].step(v_run[j], dt)
                q[k] = bs.lengths - offsets
                rtts[k].append(bs.round_trip_s)
                missed[k] += int(bs.missed_period)
        sol = forward_kinematics_batch(g, q[run], R[run], t[run])
        bad = ~sol.converged
        if np.any(bad):
            for k in run[bad]:
                failure[k] = "forward kinematics of the true robot failed (singularity?)"
                active[k] = False
                steps[k] = step + 1
        okk = run[~bad]
        R[okk] = sol.rotations[~bad]
        t[okk] = sol.translations[~bad]
    dp, da = pose_error(R, t, R_goal, t_goal)
    out = []
    for m, s in enumerate(group):
        row = _base_row(sc, spec, s.trial)
        fail = failure[m]
        if fail is None and not converged[m]:
            fail = f"not converged within {sc.task.max_steps} steps"
        settle = int(last_bad[m] + 1) if sc.task.fixed_duration else int(steps[m])
        row.update({
            "converged": bool(converged[m]),
            "steps": settle,
            "final_position_error_mm": float(dp[m] * 1e3),
            "final_orientation_error_deg": float(np.rad2deg(da[m])),
            "stroke_violations": int(violations[m]),
            "step_time_us": float(np.median(step_times[m]) * 1e6) if step_times[m] else None,
            "failure": None if converged[m] else fail,
        })
        if tail_pos[m]:
            # the seeds' "median positioning error of the convergence tail": the last 20 %
            row["tail_position_error_mm"] = float(np.median(tail_pos[m]) * 1e3)
            row["tail_orientation_error_deg"] = float(np.rad2deg(np.median(tail_ori[m])))
        times = getattr(sensor, "detect_times", None)
        if times:
            row["detect_time_ms"] = float(np.median(times) * 1e3)
        if rtts[m]:
            arr = np.array(rtts[m]) * 1e3
            row["rtt_median_ms"] = float(np.median(arr))
            row["rtt_p99_ms"] = float(np.percentile(arr, 99))
            row["missed_periods"] = int(missed[m])
        for key, value in s.calibration.items():
            row[f"calibration_{key}"] = value
        ser_out = None
        if recording[m]:
            ser_out = {key: np.array(v) for key, v in series[m].items()}
            ser_out["goal_rotation"] = s.goal_rotation
            ser_out["goal_translation"] = s.goal_translation
        out.append(TrialResult(row, ser_out))
    return out
