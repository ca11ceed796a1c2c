"""The scenario model: what a study is (robot, camera, sensor, noise, calibration error,
calibration, task, controllers), the allowed range of every number, and the sweep."""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from benchmarks.exceptions import ScenarioError
from benchmarks.study.scenario_payload import PayloadConfig
from benchmarks.study.scenario_ranges import RANGES as RANGES
from benchmarks.study.scenario_ranges import check_range
from hexapod.exceptions import ConfigFileError
from vision.calibration import MIN_SINGULAR_RATIO, WARN_SINGULAR_RATIO

#: Keys of [noise] and [calibration_error] that may be swept (given as lists).
NOISE_KEYS = ("amplitude_deg", "pixel_sigma_px", "points_per_edge", "outlier_fraction",
              "dropout_probability")
CALIBRATION_ERROR_KEYS = ("scale", "base_points_mm", "platform_points_mm", "joint_offsets_mm",
                          "camera_pose_mm", "camera_pose_deg", "intrinsics_percent",
                          "leg_radius_percent", "distortion_percent", "mass_percent",
                          "inertia_percent", "model_mass_error_percent",
                          "model_inertia_error_percent", "model_friction_error_percent",
                          "model_rotor_inertia_error_percent",
                          "model_drive_bandwidth_error_percent", "payload_mass_percent")
#: The controllers' model's systematic errors [%] (not random, not multiplied by ``scale``):
#: the true robot's value is the robot file's divided by ``1 + e / 100``.
MODEL_ERROR_KEYS = ("model_mass_error_percent", "model_inertia_error_percent",
                    "model_friction_error_percent", "model_rotor_inertia_error_percent",
                    "model_drive_bandwidth_error_percent")
#: The worlds a study runs in (``[robot] world``).
WORLDS = ("kinematic", "dynamic")


#: Keys of [clock] (the camera's clock), every one sweepable.
CLOCK_KEYS = ("frame_rate_hz", "latency_ms", "latency_frames", "jitter_ms", "exposure_ms")
#: Keys of [drives] (the robot's drives, world and controllers alike), every one sweepable.
DRIVES_KEYS = ("velocity_bandwidth_hz",)
#: Keys of [task] that may be swept (trajectory tasks).
TASK_KEYS = ("speed_mm_s", "acceleration_mm_s2", "jerk_mm_s3", "peak_acceleration_mm_s2",
             "goal")
#: The values of ``[task] goal`` (:data:`benchmarks.sim.goal.GOAL_SETTINGS`, which the
#: simulator defines; repeated here so that reading a scenario does not import it, and
#: checked equal by the tests).
GOAL_SETTINGS = ("mixed", "taught", "cartesian")
#: Calibration errors that are not standard deviations: not multiplied by ``scale``.
UNSCALED = ("scale", "distortion_percent", *MODEL_ERROR_KEYS, "payload_mass_percent")
#: The calibration-error keys in millimetres or degrees whose standard deviation, times
#: ``scale``, must stay within the range of the key itself (the effective error).
SCALED_ERROR_KEYS = tuple(k for k in CALIBRATION_ERROR_KEYS if k not in UNSCALED)


@dataclass(frozen=True)
class ControllerSpec:
    """A controller of a study: registry name (or ``module:attr``), label, options.

    ``key`` is where the file names it (``"controllers[0]"``; None: the command line)
    and ``option_keys`` the file key of each option (``"controllers[0].gain"`` or
    ``"controller_options.gain"``), for the error messages.
    """

    name: str
    label: str
    options: dict[str, Any] = field(default_factory=dict)
    key: str | None = field(default=None, compare=False)
    option_keys: dict[str, str] = field(default_factory=dict, compare=False)


@dataclass(frozen=True)
class NoiseConfig:
    """Measurement noise.

    Attributes:
        model: ``"none"``, ``"rotation"`` (random rotation of each edge normal,
            angle uniform in [0, amplitude]) or ``"pixel"`` (Gaussian noise on
            points sampled along each edge, then the normal fit).
        amplitude_deg: Rotation-noise amplitude [deg].
        pixel_sigma_px: Pixel-noise standard deviation [px].
        points_per_edge: Points sampled per edge (pixel model).
        outlier_fraction: Fraction of outlier points (pixel model).
        dropout_probability: Probability that an edge is missed at a step.
        on_goal: Whether the desired features (taken from the goal image) are noisy too.
    """

    model: str = "none"
    amplitude_deg: float = 0.0
    pixel_sigma_px: float = 0.0
    points_per_edge: int = 20
    outlier_fraction: float = 0.0
    dropout_probability: float = 0.0
    on_goal: bool = True


@dataclass(frozen=True)
class CalibrationErrorConfig:
    """Truth minus what the controllers are told (standard deviations).

    Attributes:
        base_points_mm: Per-coordinate std of the base points [mm].
        platform_points_mm: Per-coordinate std of the platform points [mm].
        joint_offsets_mm: Std of the encoder offsets [mm].
        camera_pose_mm: Per-axis std of the camera position [mm].
        camera_pose_deg: Std of the camera orientation error angle per axis [deg].
        intrinsics_percent: Relative std of focal lengths and principal point [%].
        leg_radius_percent: Relative std of the leg radius [%].
        distortion_percent: How much of the lens distortion the camera model misses
            [%]: its coefficients are the true ones times ``1 - distortion_percent /
            100`` (100: a model that ignores the distortion, what a pipeline without
            distortion support assumes). Not random, not multiplied by ``scale``.
        mass_percent: Relative std of the platform's and the legs' masses [%] (the
            dynamic world's true robot; the controllers are told the robot file's).
        inertia_percent: Relative std of their rotational inertias [%]. Each body's
            factor is ``exp(s z)`` (always positive, about ``1 + s z`` for small ``s``).
        model_mass_error_percent: The controllers' model's error on every body's mass
            (platform, leg body, leg rod) [%], the same for every trial: the robot
            file's masses (what the controllers are told) are the true ones times
            ``1 + e / 100`` (+30: the model is 30 % too heavy). Not random, not
            multiplied by ``scale``; the drives' rotor inertia is not changed.
        model_inertia_error_percent: Likewise for their rotational inertias [%].
        model_friction_error_percent: The controllers' model's error on every drive's
            friction, viscous [N s/m] and Coulomb [N] alike [%]: the true drives' are the
            robot file's divided by ``1 + e / 100`` (+30: the model's friction 30 %
            too high). Not random, not multiplied by ``scale``.
        model_rotor_inertia_error_percent: Likewise for the drives' rotor inertia
            reflected to the legs [%].
        model_drive_bandwidth_error_percent: Likewise for the bandwidth of the drives'
            velocity loops [%] (what the drive-aware predictive controllers and the
            ``leg_rate_feedforward`` option model).
        payload_mass_percent: The controllers' model of the ``[payload]``: its mass
            (and inertia) the true one's times ``1 + e / 100`` [%] (-100: unknown to
            them). Not random, not multiplied by ``scale``; the true world is unchanged.
        scale: Multiplies every standard deviation above (sweep it to grow all
            errors together).
    """

    scale: float = 1.0
    base_points_mm: float = 0.0
    platform_points_mm: float = 0.0
    joint_offsets_mm: float = 0.0
    camera_pose_mm: float = 0.0
    camera_pose_deg: float = 0.0
    intrinsics_percent: float = 0.0
    leg_radius_percent: float = 0.0
    distortion_percent: float = 0.0
    mass_percent: float = 0.0
    inertia_percent: float = 0.0
    model_mass_error_percent: float = 0.0
    model_inertia_error_percent: float = 0.0
    model_friction_error_percent: float = 0.0
    model_rotor_inertia_error_percent: float = 0.0
    model_drive_bandwidth_error_percent: float = 0.0
    payload_mass_percent: float = 0.0

    def at_scale(self) -> CalibrationErrorConfig:
        """The errors at the scale: every key but :data:`UNSCALED` times ``scale``."""
        return type(self)(**{k: getattr(self, k) * self.scale if k not in UNSCALED
                             else getattr(self, k) for k in self.__dataclass_fields__})

    def nominal_world(self) -> bool:
        """Whether no error moves the true world away from the nominal one (every trial
        then shares it: ``distortion_percent`` and ``payload_mass_percent`` change only
        the controllers' models)."""
        return all(getattr(self, k) == 0.0 for k in self.__dataclass_fields__
                   if k not in ("scale", "distortion_percent", "payload_mass_percent"))


@dataclass(frozen=True)
class CalibrationConfig:
    """Optional linear calibration of the base points before control (docs/math.md section 7).

    Attributes:
        method: ``"none"`` (controllers get nominal values), ``"linear"`` (calibrate
            in the simulated world first) or ``"file"`` (base points from a file
            written by ``hexapod-bench calibrate``).
        file: The calibrated parameter file (method ``"file"``).
        configurations: ``"extremal"`` or ``"random:N"``.
        solver: ``"lstsq"`` or ``"irls"``.
        noise_deg: Rotation noise on the calibration images [deg] (None: as [noise]).
        warn_singular_ratio: A leg whose system's smallest/largest singular value is
            below this is ill-conditioned: logged, and the trial is marked
            (``calibration_ill_conditioned_legs`` in its row).
        min_singular_ratio: Below this the calibration refuses (the trial fails with a
            ``CalibrationError`` naming the leg and the ratio).
        allow_foreign: Method ``"file"``: use a file made with another robot or camera
            (warned loudly) instead of refusing it.
    """

    method: str = "none"
    file: str | None = None
    configurations: str = "extremal"
    solver: str = "irls"
    noise_deg: float | None = None
    warn_singular_ratio: float = WARN_SINGULAR_RATIO
    min_singular_ratio: float = MIN_SINGULAR_RATIO
    allow_foreign: bool = False


@dataclass(frozen=True)
class ImageConfig:
    """Rendering settings of the image sensor (``[sensor] kind = "image"``).

    Attributes:
        background: ``"plain"`` (seed 003) or ``"cluttered"``.
        blur_px: Gaussian blur [px].
        noise_std: Pixel noise standard deviation [grey levels].
    """

    background: str = "plain"
    blur_px: float = 0.8
    noise_std: float = 2.0


@dataclass(frozen=True)
class ClockConfig:
    """The camera's clock (:mod:`benchmarks.sim.clock`); the defaults: a camera triggered
    at every control instant whose image arrives at once.

    Attributes:
        frame_rate_hz: Frames per second (0: one frame per control period, at its instant).
        latency_ms: Delay from capture to delivery [ms].
        latency_frames: Further delay, in frame periods (control periods at rate 0).
        jitter_ms: Standard deviation of the capture times around their nominal grid
            [ms] (clipped to 0.45 frame).
        exposure_ms: Exposure time [ms] (0: an instant): a frame integrates the robot's
            motion over the exposure that ends at its capture time (motion blur; the
            rendered images only, ``[sensor] kind = "image"``); its ``image_t`` is the
            middle of the exposure.
        exposure_samples: Poses drawn and averaged over the exposure
            (:func:`vision.exposure.render_exposed`).
    """

    frame_rate_hz: float = 0.0
    latency_ms: float = 0.0
    latency_frames: float = 0.0
    jitter_ms: float = 0.0
    exposure_ms: float = 0.0
    exposure_samples: int = 8


@dataclass(frozen=True)
class DrivesConfig:
    """Changes to the robot's drives (the robot file's ``[drives]``): the true robot of the
    dynamic world and the controllers' nominal model alike, so that a study can sweep
    them on one robot file.

    Attributes:
        velocity_bandwidth_hz: Bandwidth of every leg's velocity loop [Hz] (0: the robot
            file's own).
    """

    velocity_bandwidth_hz: float = 0.0


@dataclass(frozen=True)
class TaskConfig:
    """What each trial must do.

    Attributes:
        kind: ``"random-pairs"`` (start and goal drawn inside the strokes), ``"fixed"``
            or ``"trajectory"`` (track a reference from a random start: the trial runs
            ``max_steps``, as ``fixed_duration``).
        start_mm: Start leg lengths (fixed task) [mm].
        goal_mm: Goal leg lengths (fixed task) [mm].
        max_steps: Step budget.
        position_tolerance_mm: Convergence threshold on the platform position [mm].
        orientation_tolerance_deg: Convergence threshold on the orientation [deg].
        margin_mm: Random poses keep this distance from the stroke limits [mm].
        max_translation_mm: Half-width of the random position box [mm].
        max_angle_deg: Maximal random rotation [deg].
        settle_steps: Steps the tolerances must hold to count as converged.
        fixed_duration: Run every trial for ``max_steps`` (noise studies: the final
            error is the error at the end; converged means within tolerance then).
        shape: Trajectory task: ``"line"`` (start to goal), ``"circle"`` or
            ``"lemniscate"`` (through the start, ``laps`` times); see
            :mod:`hexapod.trajectory`.
        profile: Trajectory timing law: ``"quintic"``, ``"trapezoidal"`` or ``"s-curve"``
            (jerk-limited, :mod:`hexapod.scurve`).
        speed_mm_s: Largest platform speed along the trajectory [mm/s].
        acceleration_mm_s2: Largest tangential acceleration [mm/s^2].
        angular_speed_deg_s: Largest angular speed of a line [deg/s].
        angular_acceleration_deg_s2: Largest angular acceleration of a line [deg/s^2].
        jerk_mm_s3: Largest tangential jerk [mm/s^3] (the ``"s-curve"`` profile).
        angular_jerk_deg_s3: Largest angular jerk of a line [deg/s^3] (``"s-curve"``).
        peak_acceleration_mm_s2: The motion scaled in time until its largest
            acceleration ``|d2p/dt2|`` is this [mm/s^2] (0: as the limits time it).
        radius_mm: Radius of the circle, half-width of the lemniscate [mm].
        laps: Turns of a closed curve.
        plane: Plane of a closed curve in the base frame: ``"xy"``, ``"xz"``, ``"yz"``.
        feed_forward: Add the reference's nominal leg-length rate to the velocity
            commands (:mod:`controllers.tracking`); false: feedback only.
        goal: What the controllers are told about the goal (:mod:`benchmarks.sim.goal`):
            ``"mixed"`` (the legacy default: vision laws taught at the true goal, encoder
            and pose laws the nominal inverse kinematics), ``"taught"`` (images and
            encoders recorded at the true goal) or ``"cartesian"`` (a pose; every law
            predicts its goal from its model).
    """

    kind: str = "random-pairs"
    start_mm: tuple[float, ...] | None = None
    goal_mm: tuple[float, ...] | None = None
    max_steps: int = 1000
    position_tolerance_mm: float = 0.1
    orientation_tolerance_deg: float = 0.01
    margin_mm: float = 5.0
    max_translation_mm: float = 60.0
    max_angle_deg: float = 10.0
    settle_steps: int = 1
    fixed_duration: bool = False
    shape: str = "line"
    profile: str = "quintic"
    speed_mm_s: float = 50.0
    acceleration_mm_s2: float = 500.0
    angular_speed_deg_s: float = 10.0
    angular_acceleration_deg_s2: float = 50.0
    jerk_mm_s3: float = 10_000.0
    angular_jerk_deg_s3: float = 1000.0
    peak_acceleration_mm_s2: float = 0.0
    radius_mm: float = 20.0
    laps: int = 1
    plane: str = "xy"
    feed_forward: bool = True
    goal: str = "mixed"


@dataclass(frozen=True)
class Scenario:
    """A validated scenario (one point of its sweep once expanded).

    Attributes:
        name: Study name.
        description: What it shows (and which seed it reproduces).
        seed: Every trial is seeded from (seed, trial index).
        trials: Trials per sweep point and controller.
        controllers: Controllers to compare.
        robot_preset: Geometry preset name (or None when ``robot_geometry`` is set).
        robot_geometry: Path to a geometry TOML file.
        dt: Control period [s].
        world: ``"kinematic"`` (the massless ideal robot, the default) or ``"dynamic"``
            (the true robot's dynamics and drives, ``docs/dynamic-world.md``).
        physics_dt: Physics step of the dynamic world [s] (``dt`` is a multiple of it).
        camera_preset: ``"front"`` or ``"omni"`` (or None when ``camera_file`` is set).
        camera_file: Path to a camera TOML file.
        sensor: ``"geometric"`` or ``"image"``.
        teach_frames: Measurements of the goal averaged into the desired features
            (:func:`vision.estimate.average_normals`), as a user teaching the goal
            averages a burst of frames.
        noise: Noise settings.
        calibration_error: Calibration error settings.
        calibration: Calibration procedure settings.
        task: Task settings.
        clock: The camera's clock (frame rate, latency, jitter).
        drives: Changes to the robot's drives (:class:`DrivesConfig`).
        payload: A payload fixed to the true platform (``[payload]``; None: none).
        reference: Figures of the reproduced seed (free-form table for the report).
        sweep: The swept keys of this point, e.g. ``{"noise.amplitude_deg": 0.05}``.
        source: File it was read from.
        geometry_data: The robot read from ``robot_geometry`` when the scenario was loaded.
        camera_data: The camera read from ``camera_file`` when the scenario was loaded.
        calibration_points: (6, 3) base points [m] read from ``calibration.file``.
        controller_options: The file's ``[controller_options]`` (given to each controller
            that declares the option, :func:`benchmarks.study.scenario_checks.
            check_controllers`; kept for the controllers ``--controllers`` chooses).
        robot_model: ``[robot] model``: a robot file whose ``[inertia]`` and ``[drives]``
            the controllers use instead of the robot's (an identified model); the world's
            truth is unchanged.
        model_data: The robot read from ``robot_model``.

    The files a scenario names are read once, where it is loaded (the client): work
    units carry their data to the workers, which need not see the files (a Dask
    cluster whose workers do not share the client's filesystem).
    """

    name: str
    description: str = ""
    seed: int = 1
    trials: int = 10
    controllers: tuple[ControllerSpec, ...] = ()
    robot_preset: str | None = "deltalab"
    robot_geometry: str | None = None
    dt: float = 0.02
    world: str = "kinematic"
    physics_dt: float = 0.001
    camera_preset: str | None = "front"
    camera_file: str | None = None
    sensor: str = "geometric"
    teach_frames: int = 1
    image: ImageConfig = ImageConfig()
    noise: NoiseConfig = NoiseConfig()
    calibration_error: CalibrationErrorConfig = CalibrationErrorConfig()
    calibration: CalibrationConfig = CalibrationConfig()
    task: TaskConfig = TaskConfig()
    clock: ClockConfig = ClockConfig()
    drives: DrivesConfig = DrivesConfig()
    payload: PayloadConfig | None = None
    reference: dict[str, Any] = field(default_factory=dict)
    sweep: dict[str, Any] = field(default_factory=dict)
    sweep_axes: dict[str, list[Any]] = field(default_factory=dict)
    source: str = "<dict>"
    geometry_data: Any = None
    camera_data: Any = None
    calibration_points: Any = None
    controller_options: dict[str, Any] = field(default_factory=dict, compare=False)
    robot_model: str | None = None
    model_data: Any = None

    def expand(self) -> list[Scenario]:
        """One scenario per point of the sweep (Cartesian product of the swept keys)."""
        if not self.sweep_axes:
            return [self]
        keys = list(self.sweep_axes)
        points = []
        for values in itertools.product(*(self.sweep_axes[k] for k in keys)):
            sc = self
            for key, value in zip(keys, values, strict=True):
                section, name = key.split(".")
                sc = replace(sc, **{section: replace(getattr(sc, section), **{name: value})})
            points.append(replace(sc, sweep=dict(zip(keys, values, strict=True))))
        return points

    def with_goal(self, goal: str) -> Scenario:
        """The scenario under another goal setting (``--goal``).

        Raises:
            ScenarioError: ``goal`` is not a setting, or the scenario sweeps
                ``task.goal``.
        """
        if goal not in GOAL_SETTINGS:
            raise ScenarioError("--goal", f"expected one of {', '.join(GOAL_SETTINGS)}, got "
                                f"{goal!r}")
        if "task.goal" in self.sweep_axes:
            raise ScenarioError(self.source, "--goal: the scenario sweeps task.goal "
                                f"({', '.join(self.sweep_axes['task.goal'])})", key="task.goal")
        return replace(self, task=replace(self.task, goal=goal))

    def with_overrides(self, trials: int | None = None, seed: int | None = None,
                       controllers: list[str] | None = None, max_steps: int | None = None,
                       calibration_file: str | None = None) -> Scenario:
        """Apply command-line overrides."""
        sc = self
        if calibration_file is not None:
            if not Path(calibration_file).exists():
                raise ScenarioError("--calibration", f"{calibration_file!r}: file not found: tried "
                                    f"{Path(calibration_file).resolve()} (relative to the "
                                    "current folder)")
            from benchmarks.study.calibration import load_calibrated_base_points

            try:
                points = load_calibrated_base_points(calibration_file)
            except ConfigFileError as exc:
                raise ScenarioError(exc.path, exc.problem, exc.key, exc.suggestion) from None
            sc = replace(sc, calibration=replace(sc.calibration, method="file",
                                                 file=str(calibration_file)),
                         calibration_points=points)
        if max_steps is not None:
            _check_option(max_steps, "task.max_steps", "--max-steps")
            sc = replace(sc, task=replace(sc.task, max_steps=max_steps))
        if trials is not None:
            _check_option(trials, "trials", "--trials")
            sc = replace(sc, trials=trials)
        if seed is not None:
            _check_option(seed, "seed", "--seed")
            sc = replace(sc, seed=seed)
        if controllers:
            from hexapod.exceptions import UnsafeNameError
            from hexapod.outputs import check_name

            for c in controllers:
                try:
                    check_name(c, "controller")
                except UnsafeNameError as exc:
                    raise ScenarioError("--controllers", f"{exc.value!r}: {exc.problem}"
                                        ) from None
            by_label = {c.label: c for c in sc.controllers}
            defaults = sc.controller_options  # the file's [controller_options], as in a file
            keys = {o: f"controller_options.{o}" for o in defaults}
            sc = replace(sc, controllers=tuple(
                by_label.get(c, ControllerSpec(c, c, dict(defaults), None, dict(keys)))
                for c in controllers))
        return sc


def _check_option(value: Any, key: str, option: str) -> None:
    """:func:`check_range` for a command-line override (named by its option)."""
    try:
        check_range(value, key, option)
    except ScenarioError as exc:
        raise ScenarioError(option, exc.problem) from None
