"""Scenario files (TOML) validated into dataclasses.

A scenario says which robot, camera, noise, calibration error, task and
controllers a study uses. Any list in ``[noise]`` or ``[calibration_error]``
makes a sweep axis; the study runs the Cartesian product of the axes. Errors
name the file, the key and what was expected, and suggest the close key for a
typo. See ``docs/scenarios.md`` for the format.
"""

from __future__ import annotations

import copy
import itertools
from dataclasses import dataclass, field, fields, replace
from importlib import resources
from pathlib import Path
from typing import Any

from benchmarks.exceptions import ScenarioError
from hexapod.config import load_toml, suggest
from hexapod.exceptions import ConfigFileError
from vision.calibration import MIN_SINGULAR_RATIO, WARN_SINGULAR_RATIO

#: Keys of [noise] and [calibration_error] that may be swept (given as lists).
NOISE_KEYS = ("amplitude_deg", "pixel_sigma_px", "points_per_edge", "outlier_fraction",
              "dropout_probability")
CALIBRATION_ERROR_KEYS = ("scale", "base_points_mm", "platform_points_mm", "joint_offsets_mm",
                          "camera_pose_mm", "camera_pose_deg", "intrinsics_percent",
                          "leg_radius_percent")


#: Allowed range of every numeric key: ``(low, high, low_inclusive, high_inclusive)``.
#: A value that parses but cannot describe a study (a negative seed, a 1e308 mm error,
#: a 1e9 deg noise) is refused when the file is loaded, naming the key and the range.
RANGES: dict[str, tuple[float, float, bool, bool]] = {
    "seed": (0, 2**63 - 1, True, True),
    "trials": (1, 10_000_000, True, True),
    "robot.dt": (0.0, 1.0, False, True),
    "sensor.teach_frames": (1, 1000, True, True),
    "sensor.blur_px": (0.0, 20.0, True, True),
    "sensor.noise_std": (0.0, 255.0, True, True),
    "noise.amplitude_deg": (0.0, 90.0, True, True),
    "noise.pixel_sigma_px": (0.0, 100.0, True, True),
    "noise.points_per_edge": (2, 10_000, True, True),
    "noise.outlier_fraction": (0.0, 1.0, True, False),
    "noise.dropout_probability": (0.0, 1.0, True, True),
    "calibration_error.scale": (0.0, 100.0, True, True),
    "calibration_error.base_points_mm": (0.0, 100.0, True, True),
    "calibration_error.platform_points_mm": (0.0, 100.0, True, True),
    "calibration_error.joint_offsets_mm": (0.0, 100.0, True, True),
    "calibration_error.camera_pose_mm": (0.0, 1000.0, True, True),
    "calibration_error.camera_pose_deg": (0.0, 45.0, True, True),
    "calibration_error.intrinsics_percent": (0.0, 50.0, True, True),
    "calibration_error.leg_radius_percent": (0.0, 50.0, True, True),
    "calibration.noise_deg": (0.0, 90.0, True, True),
    "calibration.warn_singular_ratio": (0.0, 1.0, True, False),
    "calibration.min_singular_ratio": (0.0, 1.0, True, False),
    "task.max_steps": (1, 10_000_000, True, True),
    "task.position_tolerance_mm": (0.0, 1000.0, False, True),
    "task.orientation_tolerance_deg": (0.0, 180.0, False, True),
    "task.margin_mm": (0.0, 1000.0, True, True),
    "task.max_translation_mm": (0.0, 10_000.0, True, True),
    "task.max_angle_deg": (0.0, 90.0, True, True),
    "task.settle_steps": (1, 10_000_000, True, True),
}
#: The calibration-error keys in millimetres or degrees whose standard deviation, times
#: ``scale``, must stay within the range of the key itself (the effective error).
_SCALED = tuple(k for k in CALIBRATION_ERROR_KEYS if k != "scale")


def check_range(value: Any, key: str, path: str) -> None:
    """Refuse a number outside :data:`RANGES` (``key`` is the dotted key).

    Raises:
        ScenarioError: Naming the file, the key, the value and the allowed range.
    """
    if key not in RANGES or isinstance(value, bool) or not isinstance(value, int | float):
        return
    lo, hi, lo_in, hi_in = RANGES[key]
    ok = (value >= lo if lo_in else value > lo) and (value <= hi if hi_in else value < hi)
    if not ok:
        interval = f"{'[' if lo_in else '('}{lo:g}, {hi:g}{']' if hi_in else ')'}"
        raise ScenarioError(path, f"{value!r} is out of the allowed range {interval}", key=key)


@dataclass(frozen=True)
class ControllerSpec:
    """A controller of a study: registry name (or ``module:attr``), label, options."""

    name: str
    label: str
    options: dict[str, Any] = field(default_factory=dict)


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
    """

    method: str = "none"
    file: str | None = None
    configurations: str = "extremal"
    solver: str = "irls"
    noise_deg: float | None = None
    warn_singular_ratio: float = WARN_SINGULAR_RATIO
    min_singular_ratio: float = MIN_SINGULAR_RATIO


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
class TaskConfig:
    """What each trial must do.

    Attributes:
        kind: ``"random-pairs"`` (start and goal drawn inside the strokes) or ``"fixed"``.
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
        reference: Figures of the reproduced seed (free-form table for the report).
        sweep: The swept keys of this point, e.g. ``{"noise.amplitude_deg": 0.05}``.
        source: File it was read from.
    """

    name: str
    description: str = ""
    seed: int = 1
    trials: int = 10
    controllers: tuple[ControllerSpec, ...] = ()
    robot_preset: str | None = "deltalab"
    robot_geometry: str | None = None
    dt: float = 0.02
    camera_preset: str | None = "front"
    camera_file: str | None = None
    sensor: str = "geometric"
    teach_frames: int = 1
    image: ImageConfig = ImageConfig()
    noise: NoiseConfig = NoiseConfig()
    calibration_error: CalibrationErrorConfig = CalibrationErrorConfig()
    calibration: CalibrationConfig = CalibrationConfig()
    task: TaskConfig = TaskConfig()
    reference: dict[str, Any] = field(default_factory=dict)
    sweep: dict[str, Any] = field(default_factory=dict)
    sweep_axes: dict[str, list[Any]] = field(default_factory=dict)
    source: str = "<dict>"

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

    def with_overrides(self, trials: int | None = None, seed: int | None = None,
                       controllers: list[str] | None = None, max_steps: int | None = None,
                       calibration_file: str | None = None) -> Scenario:
        """Apply command-line overrides."""
        sc = self
        if calibration_file is not None:
            if not Path(calibration_file).exists():
                raise ScenarioError(calibration_file, "calibration file not found")
            sc = replace(sc, calibration=replace(sc.calibration, method="file",
                                                 file=str(calibration_file)))
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
            by_label = {c.label: c for c in sc.controllers}
            sc = replace(sc, controllers=tuple(by_label.get(c, ControllerSpec(c, c))
                                               for c in controllers))
        return sc


def _check_option(value: Any, key: str, option: str) -> None:
    """:func:`check_range` for a command-line override (named by its option)."""
    try:
        check_range(value, key, option)
    except ScenarioError as exc:
        raise ScenarioError(option, exc.problem) from None


_TOP = ("name", "description", "seed", "trials", "controllers", "controller_options", "robot",
        "camera", "sensor", "noise", "calibration_error", "calibration", "task", "reference")


def _section(table: dict[str, Any], key: str, path: str) -> dict[str, Any]:
    value = table.get(key, {})
    if not isinstance(value, dict):
        raise ScenarioError(path, f"expected a table [{key}], got {type(value).__name__}",
                            key=key)
    return value


def _typed(value: Any, kind: type, path: str, key: str, choices: tuple[str, ...] = ()) -> Any:
    if kind is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ScenarioError(path, f"expected a number, got {value!r}", key=key)
        if value != value or value in (float("inf"), float("-inf")):
            raise ScenarioError(path, f"expected a finite number, got {value!r}", key=key)
        return float(value)
    if kind is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ScenarioError(path, f"expected an integer, got {value!r}", key=key)
        return value
    if kind is bool:
        if not isinstance(value, bool):
            raise ScenarioError(path, f"expected true or false, got {value!r}", key=key)
        return value
    if kind is str:
        if not isinstance(value, str):
            raise ScenarioError(path, f"expected a string, got {value!r}", key=key)
        if choices and value not in choices:
            hint = suggest(value, choices)
            raise ScenarioError(path, f"expected one of {', '.join(choices)}, got {value!r}",
                                key=key, suggestion=hint)
        return value
    raise TypeError(kind)


def _parse_dataclass(cls: type, table: dict[str, Any], path: str, section: str,
                     sweepable: tuple[str, ...] = (), choices: dict[str, tuple[str, ...]]
                     | None = None, sweep: dict[str, list[Any]] | None = None) -> Any:
    choices = choices or {}
    names = {f.name: f for f in fields(cls)}
    for key in table:
        if key not in names:
            raise ScenarioError(path, f"unknown key; expected one of {', '.join(names)}",
                                key=f"{section}.{key}", suggestion=suggest(key, names))
    kwargs: dict[str, Any] = {}
    for key, value in table.items():
        f = names[key]
        kind = _base_type(f.type)
        dotted = f"{section}.{key}"
        if isinstance(value, list) and key in sweepable:
            if not value:
                raise ScenarioError(path, "an empty list cannot be a sweep axis", key=dotted)
            values = [_typed(v, kind, path, dotted, choices.get(key, ())) for v in value]
            for v in values:
                check_range(v, dotted, path)
            if sweep is None:
                raise ScenarioError(path, "this key cannot be swept", key=dotted)
            sweep[dotted] = values
            kwargs[key] = values[0]
        elif isinstance(value, list) and kind is tuple:
            try:
                kwargs[key] = tuple(float(v) for v in value)
            except (TypeError, ValueError):
                raise ScenarioError(path, "expected a list of numbers", key=dotted) from None
        elif isinstance(value, list):
            raise ScenarioError(path, "a list is only allowed for the sweepable keys "
                                f"({', '.join(sweepable) or 'none here'})", key=dotted)
        elif kind is tuple:
            raise ScenarioError(path, "expected a list of numbers", key=dotted)
        elif f.name in ("noise_deg", "file") and value is not None:
            kind = float if f.name == "noise_deg" else str
            kwargs[key] = _typed(value, kind, path, dotted)
            check_range(kwargs[key], dotted, path)
        else:
            kwargs[key] = _typed(value, kind, path, dotted, choices.get(key, ()))
            check_range(kwargs[key], dotted, path)
    return cls(**kwargs)


def _base_type(annotation: Any) -> type:
    text = str(annotation)
    if "tuple" in text:
        return tuple
    if "bool" in text:
        return bool
    if "int" in text and "float" not in text:
        return int
    if "float" in text:
        return float
    return str


def parse_scenario(table: dict[str, Any], path: str = "<dict>") -> Scenario:
    """Validate a scenario table (as read from TOML).

    Raises:
        ScenarioError: Naming the file, the key, what was expected, and the close key.
    """
    table = copy.deepcopy(table)
    for key in table:
        if key not in _TOP:
            raise ScenarioError(path, f"unknown key; expected one of {', '.join(_TOP)}",
                                key=key, suggestion=suggest(key, _TOP))
    if "name" not in table:
        raise ScenarioError(path, "missing required key", key="name")
    name = _typed(table["name"], str, path, "name")
    description = _typed(table.get("description", ""), str, path, "description")
    seed = _typed(table.get("seed", 1), int, path, "seed")
    check_range(seed, "seed", path)
    trials = _typed(table.get("trials", 10), int, path, "trials")
    check_range(trials, "trials", path)
    raw_controllers = table.get("controllers")
    if raw_controllers is None:
        raise ScenarioError(path, "missing required key (a list of controller names)",
                            key="controllers")
    if not isinstance(raw_controllers, list) or not raw_controllers:
        raise ScenarioError(path, "expected a non-empty list of controller names or tables",
                            key="controllers")
    specs = []
    for k, item in enumerate(raw_controllers):
        if isinstance(item, str):
            specs.append(ControllerSpec(item, item))
        elif isinstance(item, dict):
            if "name" not in item or not isinstance(item["name"], str):
                raise ScenarioError(path, "a controller table needs a string 'name'",
                                    key=f"controllers[{k}]")
            opts = {k2: v for k2, v in item.items() if k2 not in ("name", "label")}
            specs.append(ControllerSpec(item["name"], str(item.get("label", item["name"])),
                                        opts))
        else:
            raise ScenarioError(path, f"expected a name or a table, got {item!r}",
                                key=f"controllers[{k}]")
    defaults = table.get("controller_options", {})
    if not isinstance(defaults, dict):
        raise ScenarioError(path, "expected a table of options given to every controller",
                            key="controller_options")
    specs = [ControllerSpec(sp.name, sp.label, {**defaults, **sp.options}) for sp in specs]
    labels = [s.label for s in specs]
    dup = {x for x in labels if labels.count(x) > 1}
    if dup:
        raise ScenarioError(path, f"duplicate controller label(s) {sorted(dup)}; give each "
                            "a distinct 'label'", key="controllers")

    robot = _section(table, "robot", path)
    for key in robot:
        if key not in ("preset", "geometry", "dt"):
            raise ScenarioError(path, "unknown key; expected one of preset, geometry, dt",
                                key=f"robot.{key}",
                                suggestion=suggest(key, ("preset", "geometry", "dt")))
    if "preset" in robot and "geometry" in robot:
        raise ScenarioError(path, "give either 'preset' or 'geometry', not both", key="robot")
    base_dir = Path(path).parent if path != "<dict>" else Path.cwd()
    robot_geometry = None
    robot_preset: str | None = "deltalab"
    if "geometry" in robot:
        robot_geometry = str(base_dir / _typed(robot["geometry"], str, path, "robot.geometry"))
        robot_preset = None
    elif "preset" in robot:
        robot_preset = _typed(robot["preset"], str, path, "robot.preset", ("deltalab",))
    dt = _typed(robot.get("dt", 0.02), float, path, "robot.dt")
    check_range(dt, "robot.dt", path)

    camera = _section(table, "camera", path)
    for key in camera:
        if key not in ("preset", "file"):
            raise ScenarioError(path, "unknown key; expected one of preset, file",
                                key=f"camera.{key}",
                                suggestion=suggest(key, ("preset", "file")))
    if "preset" in camera and "file" in camera:
        raise ScenarioError(path, "give either 'preset' or 'file', not both", key="camera")
    camera_file = None
    camera_preset: str | None = "front"
    if "file" in camera:
        camera_file = str(base_dir / _typed(camera["file"], str, path, "camera.file"))
        camera_preset = None
    elif "preset" in camera:
        camera_preset = _typed(camera["preset"], str, path, "camera.preset", ("front", "omni"))

    sensor_t = dict(_section(table, "sensor", path))
    sensor_keys = ("kind", "teach_frames", *(f.name for f in fields(ImageConfig)))
    for key in sensor_t:
        if key not in sensor_keys:
            raise ScenarioError(path, f"unknown key; expected one of {', '.join(sensor_keys)}",
                                key=f"sensor.{key}", suggestion=suggest(key, sensor_keys))
    sensor = _typed(sensor_t.pop("kind", "geometric"), str, path, "sensor.kind",
                    ("geometric", "image"))
    teach_frames = _typed(sensor_t.pop("teach_frames", 1), int, path, "sensor.teach_frames")
    check_range(teach_frames, "sensor.teach_frames", path)
    image = _parse_dataclass(ImageConfig, sensor_t, path, "sensor", (),
                             {"background": ("plain", "cluttered")})

    sweep: dict[str, list[Any]] = {}
    noise = _parse_dataclass(NoiseConfig, _section(table, "noise", path), path, "noise",
                             NOISE_KEYS, {"model": ("none", "rotation", "pixel")}, sweep)
    cal_err = _parse_dataclass(CalibrationErrorConfig,
                               _section(table, "calibration_error", path), path,
                               "calibration_error", CALIBRATION_ERROR_KEYS, None, sweep)
    _check_scaled_errors(cal_err, sweep, path)
    cal = _parse_dataclass(CalibrationConfig, _section(table, "calibration", path), path,
                           "calibration", (), {"method": ("none", "linear", "file"),
                                               "solver": ("lstsq", "irls")})
    if cal.method == "file":
        if not cal.file:
            raise ScenarioError(path, "method 'file' needs a 'file'", key="calibration.file")
        cal = replace(cal, file=str(base_dir / cal.file))
    _check_configurations(cal.configurations, path)
    if cal.min_singular_ratio > cal.warn_singular_ratio:
        raise ScenarioError(path, f"{cal.min_singular_ratio} exceeds warn_singular_ratio "
                            f"({cal.warn_singular_ratio}): the hard limit must be below the "
                            "warning", key="calibration.min_singular_ratio")
    task = _parse_dataclass(TaskConfig, _section(table, "task", path), path, "task", (),
                            {"kind": ("random-pairs", "fixed")})
    if task.settle_steps > task.max_steps:
        raise ScenarioError(path, f"{task.settle_steps} exceeds task.max_steps "
                            f"({task.max_steps})", key="task.settle_steps")
    if task.kind == "fixed":
        _check_fixed_task(task, robot_preset, robot_geometry, path)
    reference = table.get("reference", {})
    if not isinstance(reference, dict):
        raise ScenarioError(path, "expected a table", key="reference")
    return Scenario(
        name=name, description=description, seed=seed, trials=trials,
        controllers=tuple(specs), robot_preset=robot_preset, robot_geometry=robot_geometry,
        dt=dt, camera_preset=camera_preset, camera_file=camera_file, sensor=sensor,
        teach_frames=teach_frames, image=image,
        noise=noise, calibration_error=cal_err, calibration=cal, task=task,
        reference=reference, sweep_axes=sweep, source=path,
    )


def _check_scaled_errors(cal_err: CalibrationErrorConfig, sweep: dict[str, list[Any]],
                         path: str) -> None:
    """Each calibration error times the largest ``scale`` stays within its key's range."""
    scales = sweep.get("calibration_error.scale", [cal_err.scale])
    for key in _SCALED:
        values = sweep.get(f"calibration_error.{key}", [getattr(cal_err, key)])
        worst = max(values) * max(scales)
        hi = RANGES[f"calibration_error.{key}"][1]
        if worst > hi:
            raise ScenarioError(path, f"times scale {max(scales):g} gives a standard "
                                f"deviation of {worst:g}, beyond the allowed {hi:g}",
                                key=f"calibration_error.{key}")


def _check_configurations(value: str, path: str) -> None:
    """``extremal`` or ``random:N`` with an integer N >= 2."""
    key = "calibration.configurations"
    if value == "extremal":
        return
    if not value.startswith("random:"):
        raise ScenarioError(path, f"expected 'extremal' or 'random:N', got {value!r}", key=key)
    count = value.split(":", 1)[1]
    if not count.isdigit() or not 2 <= int(count) <= 100_000:
        raise ScenarioError(path, f"expected 'random:N' with an integer N in [2, 100000], got "
                            f"{value!r}", key=key)


def _check_fixed_task(task: TaskConfig, preset: str | None, geometry_file: str | None,
                      path: str) -> None:
    """A fixed task has 6 leg lengths per end, inside the nominal strokes."""
    from hexapod.geometry import HexapodGeometry
    from hexapod.geometry import preset as geometry_preset

    for key in ("start_mm", "goal_mm"):
        value = getattr(task, key)
        if value is None or len(value) != 6:
            raise ScenarioError(path, "a fixed task needs 6 leg lengths [mm]", key=f"task.{key}")
    try:
        geometry = (HexapodGeometry.from_toml(geometry_file) if geometry_file is not None
                    else geometry_preset(preset or "deltalab"))
    except ConfigFileError as exc:
        raise ScenarioError(exc.path, exc.problem, exc.key, exc.suggestion) from None
    lo, hi = (1e3 * x for x in geometry.stroke)
    for key in ("start_mm", "goal_mm"):
        for leg, q in enumerate(getattr(task, key)):
            if not lo <= q <= hi:
                raise ScenarioError(path, f"leg {leg}: {q:g} mm is outside the stroke "
                                    f"[{lo:g}, {hi:g}] mm", key=f"task.{key}")


def check_controllers(sc: Scenario) -> None:
    """Resolve every controller of a scenario and build it with its options once.

    A misspelt name or an option a controller refuses (a NaN gain, an unknown
    option) is reported before any trial runs, instead of failing every trial.

    Raises:
        UnknownControllerError: A name no controller is registered under (with the close one).
        PluginLoadError: A ``module:attr`` that cannot be imported.
        ScenarioError: An option the controller refuses, naming the controller and option.
    """
    import controllers  # noqa: F401 - registers the built-ins
    from controllers.base import registry
    from controllers.exceptions import OptionError

    for k, spec in enumerate(sc.controllers):
        registry.factory(spec.name)
        try:
            registry.create(spec.name, **spec.options)
        except OptionError as exc:
            raise ScenarioError(sc.source, f"{spec.name}: {exc.problem}",
                                key=f"controllers[{k}].{exc.option}") from None
        except TypeError as exc:  # an option the factory does not take
            raise ScenarioError(sc.source, f"{spec.name}: {exc}",
                                key=f"controllers[{k}]") from None


def builtin_scenarios() -> dict[str, Path]:
    """Built-in scenario names and their files."""
    folder = resources.files("benchmarks") / "scenarios"
    out = {}
    for entry in folder.iterdir():
        if entry.name.endswith(".toml"):
            out[entry.name[:-5]] = Path(str(entry))
    return dict(sorted(out.items()))


def load_scenario(name_or_path: str | Path) -> Scenario:
    """Load a built-in scenario by name or a scenario file by path.

    Raises:
        ScenarioError: Unknown name (with the close one), missing file, invalid content.
    """
    text = str(name_or_path)
    builtins = builtin_scenarios()
    if text in builtins:
        path = builtins[text]
    else:
        path = Path(text)
        if not path.exists():
            hint = suggest(text, builtins)
            raise ScenarioError(text, "no such built-in scenario or file; built-ins: "
                                + ", ".join(builtins), suggestion=hint)
    try:
        table = load_toml(path)
    except ConfigFileError as exc:
        raise ScenarioError(exc.path, exc.problem, exc.key, exc.suggestion) from None
    return parse_scenario(table, str(path))
