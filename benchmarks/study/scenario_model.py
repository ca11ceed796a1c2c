"""The scenario model: what a study is (robot, camera, sensor, noise, calibration error,
calibration, task, controllers), the allowed range of every number, and the sweep."""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from benchmarks.exceptions import ScenarioError
from benchmarks.scenario_sections import (
    UNSCALED,
    CalibrationErrorConfig,
    ClockConfig,
    DrivesConfig,
    ImageConfig,
    NoiseConfig,
    TaskConfig,
)
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
#: The worlds a study runs in (``[robot] world``).
WORLDS = ("kinematic", "dynamic")


#: Keys of [clock] (the camera's clock), every one sweepable.
CLOCK_KEYS = ("frame_rate_hz", "latency_ms", "latency_frames", "jitter_ms", "exposure_ms")
#: Keys of [drives] (the robot's drives, world and controllers alike), every one sweepable.
DRIVES_KEYS = ("velocity_bandwidth_hz",)
#: Keys of [task] that may be swept (trajectory tasks).
TASK_KEYS = ("speed_mm_s", "acceleration_mm_s2", "jerk_mm_s3", "peak_acceleration_mm_s2",
             "goal")
#: The ``[task]`` keys only a trajectory task reads (the reference's shape and timing).
TRAJECTORY_ONLY_KEYS = ("shape", "profile", "speed_mm_s", "acceleration_mm_s2",
                        "angular_speed_deg_s", "angular_acceleration_deg_s2", "jerk_mm_s3",
                        "angular_jerk_deg_s3", "peak_acceleration_mm_s2", "radius_mm", "laps",
                        "plane", "feed_forward")
#: The values of ``[task] goal`` (:data:`benchmarks.sim.goal.GOAL_SETTINGS`, which the
#: simulator defines; repeated here so that reading a scenario does not import it, and
#: checked equal by the tests).
GOAL_SETTINGS = ("mixed", "taught", "cartesian")
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
    image: ImageConfig = field(default_factory=ImageConfig)
    noise: NoiseConfig = field(default_factory=NoiseConfig)
    calibration_error: CalibrationErrorConfig = field(default_factory=CalibrationErrorConfig)
    calibration: CalibrationConfig = CalibrationConfig()
    task: TaskConfig = field(default_factory=TaskConfig)
    clock: ClockConfig = field(default_factory=ClockConfig)
    drives: DrivesConfig = field(default_factory=DrivesConfig)
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

            twice = sorted({c for c in controllers if controllers.count(c) > 1})
            if twice:  # (each trial ran twice, its rows written twice under one label)
                raise ScenarioError("--controllers", f"{', '.join(twice)} given twice: a "
                                    "controller runs once per study (to run it twice with "
                                    "other options, give each a label in the scenario file)")

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
