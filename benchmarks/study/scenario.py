"""Scenario files (TOML) validated into dataclasses.

A scenario says which robot, camera, noise, calibration error, task and
controllers a study uses. Any list in ``[noise]`` or ``[calibration_error]``
makes a sweep axis; the study runs the Cartesian product of the axes. Errors
name the file, the key and what was expected, and suggest the close key for a
typo. See ``docs/scenarios.md`` for the format.
"""
from __future__ import annotations

import copy
import logging
from dataclasses import fields, replace
from importlib import resources
from pathlib import Path
from typing import Any

from benchmarks.exceptions import ScenarioError
from benchmarks.study.scenario_checks import (
    check_configurations,
    check_controllers,
    check_fixed_task,
    check_lens_error,
    check_reference,
    check_scaled_errors,
    check_trajectory_task,
    referenced_file,
)
from benchmarks.study.scenario_files import preset_camera, read_files, read_model
from benchmarks.study.scenario_model import (
    CALIBRATION_ERROR_KEYS,
    CLOCK_KEYS,
    DRIVES_KEYS,
    GOAL_SETTINGS,
    NOISE_KEYS,
    RANGES,
    TASK_KEYS,
    WORLDS,
    CalibrationConfig,
    CalibrationErrorConfig,
    ClockConfig,
    ControllerSpec,
    DrivesConfig,
    ImageConfig,
    NoiseConfig,
    Scenario,
    TaskConfig,
    check_range,
)
from benchmarks.study.scenario_payload import PAYLOAD_KEYS, PayloadConfig, check_payload
from benchmarks.study.scenario_ranges import typed_value
from hexapod.config import load_toml, suggest
from hexapod.exceptions import ConfigFileError
from hexapod.trajectory import PLANES, PROFILES, SHAPES

__all__ = [
    "CALIBRATION_ERROR_KEYS", "NOISE_KEYS", "RANGES", "CalibrationConfig",
    "CalibrationErrorConfig", "ControllerSpec", "ImageConfig", "NoiseConfig", "Scenario",
    "TaskConfig", "builtin_scenarios", "check_controllers", "check_range", "load_scenario",
    "parse_scenario",
]

log = logging.getLogger(__name__)

#: The top-level keys of a scenario file.
SCENARIO_KEYS = ("name", "description", "seed", "trials", "controllers", "controller_options",
                 "robot", "camera", "sensor", "noise", "calibration_error", "calibration",
                 "task", "reference", "clock", "drives", "payload")


def _section(table: dict[str, Any], key: str, path: str) -> dict[str, Any]:
    value = table.get(key, {})
    if not isinstance(value, dict):
        raise ScenarioError(path, f"expected a table [{key}], got {type(value).__name__}",
                            key=key)
    return value


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
            values = [typed_value(v, kind, path, dotted, choices.get(key, ())) for v in value]
            for v in values:
                check_range(v, dotted, path)
            if sweep is None:
                raise ScenarioError(path, "this key cannot be swept", key=dotted)
            sweep[dotted] = values
            kwargs[key] = values[0]
        elif isinstance(value, list) and kind is tuple:
            if not all(isinstance(v, int | float) and not isinstance(v, bool) for v in value):
                # (strings and booleans were converted: ["0", "0", "-50"] passed)
                raise ScenarioError(path, f"expected a list of numbers, got {value!r}",
                                    key=dotted)
            kwargs[key] = tuple(float(v) for v in value)
        elif isinstance(value, list):
            raise ScenarioError(path, "a list is only allowed for the sweepable keys "
                                f"({', '.join(sweepable) or 'none here'})", key=dotted)
        elif kind is tuple:
            raise ScenarioError(path, "expected a list of numbers", key=dotted)
        elif f.name in ("noise_deg", "file") and value is not None:
            kind = float if f.name == "noise_deg" else str
            kwargs[key] = typed_value(value, kind, path, dotted)
            check_range(kwargs[key], dotted, path)
        else:
            kwargs[key] = typed_value(value, kind, path, dotted, choices.get(key, ()))
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
        if key not in SCENARIO_KEYS:
            raise ScenarioError(path, f"unknown key; expected one of {', '.join(SCENARIO_KEYS)}",
                                key=key, suggestion=suggest(key, SCENARIO_KEYS))
    if "name" not in table:
        raise ScenarioError(path, "missing required key", key="name")
    name = _checked_name(typed_value(table["name"], str, path, "name"), "scenario name", path,
                         "name")
    description = typed_value(table.get("description", ""), str, path, "description")
    seed = typed_value(table.get("seed", 1), int, path, "seed")
    check_range(seed, "seed", path)
    trials = typed_value(table.get("trials", 10), int, path, "trials")
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
    specs = [ControllerSpec(sp.name, sp.label, {**shared, **sp.options}, f"controllers[{k}]",
                            {**{o: f"controller_options.{o}" for o in shared},
                             **{o: f"controllers[{k}].{o}" for o in sp.options}})
             for k, sp in enumerate(specs)
             for shared in [_shared_for(defaults, sp.options, path, f"controllers[{k}]")]]
    for k, sp in enumerate(specs):
        _checked_name(sp.name, "controller name", path, f"controllers[{k}]")
        _checked_name(sp.label, "controller label", path, f"controllers[{k}].label")
    labels = [s.label for s in specs]
    dup = {x for x in labels if labels.count(x) > 1}
    if dup:
        raise ScenarioError(path, f"duplicate controller label(s) {sorted(dup)}; give each "
                            "a distinct 'label'", key="controllers")

    robot = _section(table, "robot", path)
    robot_keys = ("preset", "geometry", "dt", "world", "physics_dt", "model")
    for key in robot:
        if key not in robot_keys:
            raise ScenarioError(path, f"unknown key; expected one of {', '.join(robot_keys)}",
                                key=f"robot.{key}", suggestion=suggest(key, robot_keys))
    if "preset" in robot and "geometry" in robot:
        raise ScenarioError(path, "give either 'preset' or 'geometry', not both", key="robot")
    base_dir = Path(path).parent if path != "<dict>" else Path.cwd()
    robot_geometry = None
    robot_preset: str | None = "deltalab"
    if "geometry" in robot:
        value = typed_value(robot["geometry"], str, path, "robot.geometry")
        robot_geometry = referenced_file(base_dir, value, "robot.geometry", path)
        robot_preset = None
    elif "preset" in robot:
        robot_preset = typed_value(robot["preset"], str, path, "robot.preset", ("deltalab",))
    robot_model, model_data = read_model(robot, base_dir, path)
    dt = typed_value(robot.get("dt", 0.02), float, path, "robot.dt")
    check_range(dt, "robot.dt", path)
    world, physics_dt = _parse_world(robot, dt, path)

    camera = _section(table, "camera", path)
    camera_keys = ("preset", "file", "opencv", "pose", "camera_from_base", "width_px",
                   "height_px")
    for key in camera:
        if key not in camera_keys:
            raise ScenarioError(path, f"unknown key; expected one of {', '.join(camera_keys)}",
                                key=f"camera.{key}", suggestion=suggest(key, camera_keys))
    given = [k for k in ("preset", "file", "opencv") if k in camera]
    if len(given) > 1:
        raise ScenarioError(path, f"give one of 'preset', 'file' or 'opencv', not "
                            f"{' and '.join(given)}", key="camera")
    from vision.cameras.files.opencv import is_opencv_file

    # 'opencv', or 'file' naming a calibration file (OpenCV, ROS camera_info, Kalibr).
    calibration = "opencv" if "opencv" in camera else (
        "file" if isinstance(camera.get("file"), str) and is_opencv_file(camera["file"])
        else None)
    for key in ("pose", "camera_from_base", "width_px", "height_px"):
        if key in camera and calibration is None:
            raise ScenarioError(path, "only with 'opencv' or a calibration 'file' (a preset "
                                "or a camera TOML file gives its own pose and size)",
                                key=f"camera.{key}")
    if "pose" in camera and "camera_from_base" in camera:
        raise ScenarioError(path, "give 'pose' (a preset's placement) or a "
                            "[camera.camera_from_base] table, not both", key="camera")
    camera_file = None
    camera_preset: str | None = "front"
    opencv: dict[str, Any] | None = None
    if "file" in camera and calibration is None:
        camera_file = referenced_file(
            base_dir, typed_value(camera["file"], str, path, "camera.file"), "camera.file", path)
        camera_preset = None
    elif calibration is not None:
        camera_file = referenced_file(base_dir, typed_value(camera[calibration], str, path,
                                                            f"camera.{calibration}"),
                                      f"camera.{calibration}", path)
        camera_preset = None
        opencv = {k: camera[k] for k in ("pose", "camera_from_base", "width_px", "height_px")
                  if k in camera}
        if "pose" in opencv:
            typed_value(opencv["pose"], str, path, "camera.pose", ("front", "omni", "fisheye"))
    elif "preset" in camera:
        camera_preset = typed_value(camera["preset"], str, path, "camera.preset",
                                    ("front", "omni", "fisheye"))

    sensor_t = dict(_section(table, "sensor", path))
    sensor_keys = ("kind", "teach_frames", *(f.name for f in fields(ImageConfig)))
    for key in sensor_t:
        if key not in sensor_keys:
            raise ScenarioError(path, f"unknown key; expected one of {', '.join(sensor_keys)}",
                                key=f"sensor.{key}", suggestion=suggest(key, sensor_keys))
    sensor = typed_value(sensor_t.pop("kind", "geometric"), str, path, "sensor.kind",
                    ("geometric", "image"))
    teach_frames = typed_value(sensor_t.pop("teach_frames", 1), int, path, "sensor.teach_frames")
    check_range(teach_frames, "sensor.teach_frames", path)
    image = _parse_dataclass(ImageConfig, sensor_t, path, "sensor", (),
                             {"background": ("plain", "cluttered")})

    sweep: dict[str, list[Any]] = {}
    noise = _parse_dataclass(NoiseConfig, _section(table, "noise", path), path, "noise",
                             NOISE_KEYS, {"model": ("none", "rotation", "pixel")}, sweep)
    cal_err = _parse_dataclass(CalibrationErrorConfig,
                               _section(table, "calibration_error", path), path,
                               "calibration_error", CALIBRATION_ERROR_KEYS, None, sweep)
    check_scaled_errors(cal_err, sweep, path)
    cal = _parse_dataclass(CalibrationConfig, _section(table, "calibration", path), path,
                           "calibration", (), {"method": ("none", "linear", "file"),
                                               "solver": ("lstsq", "irls")})
    if cal.method == "file":
        if not cal.file:
            raise ScenarioError(path, "method 'file' needs a 'file'", key="calibration.file")
        cal = replace(cal, file=referenced_file(base_dir, cal.file, "calibration.file", path))
    elif cal.file:  # (it was ignored, a missing one too: a calibration of its own ran)
        raise ScenarioError(path, f"a calibration file is read by method = \"file\" only, "
                            f"and the method is {cal.method!r}: set method = \"file\" or "
                            "remove the file", key="calibration.file")
    check_configurations(cal.configurations, path)
    if cal.min_singular_ratio > cal.warn_singular_ratio:
        raise ScenarioError(path, f"{cal.min_singular_ratio} exceeds warn_singular_ratio "
                            f"({cal.warn_singular_ratio}): the hard limit must be below the "
                            "warning", key="calibration.min_singular_ratio")
    task = _parse_dataclass(TaskConfig, _section(table, "task", path), path, "task", TASK_KEYS,
                            {"kind": ("random-pairs", "fixed", "trajectory"),
                             "shape": SHAPES, "profile": PROFILES, "plane": tuple(PLANES),
                             "goal": GOAL_SETTINGS},
                            sweep)
    task = check_trajectory_task(task, sweep, path, set(_section(table, "task", path)))
    clock = _parse_dataclass(ClockConfig, _section(table, "clock", path), path, "clock",
                             CLOCK_KEYS, None, sweep)
    drives = _parse_dataclass(DrivesConfig, _section(table, "drives", path), path, "drives",
                              DRIVES_KEYS, None, sweep)
    payload = None
    if "payload" in table:
        payload = _parse_dataclass(PayloadConfig, _section(table, "payload", path), path,
                                   "payload", PAYLOAD_KEYS, None, sweep)
        check_payload(payload, sweep, path)
    if sensor != "image" and max(sweep.get("clock.exposure_ms", [clock.exposure_ms])) > 0:
        raise ScenarioError(path, "motion blur needs rendered images ([sensor] kind = "
                            "\"image\")", key="clock.exposure_ms")
    if task.settle_steps > task.max_steps:
        raise ScenarioError(path, f"{task.settle_steps} exceeds task.max_steps "
                            f"({task.max_steps})", key="task.settle_steps")
    geometry_data, camera_data, points = read_files(robot_geometry, camera_file, cal, opencv,
                                                     robot_preset, path)
    if task.kind == "fixed":
        check_fixed_task(task, robot_preset, geometry_data, path)
    check_lens_error(preset_camera(camera_preset) if camera_data is None
                     and camera_file is None and camera_preset is not None else camera_data,
                     cal_err, sweep, path)
    reference = check_reference(table.get("reference", {}), path)
    return Scenario(
        name=name, description=description, seed=seed, trials=trials,
        controllers=tuple(specs), robot_preset=robot_preset, robot_geometry=robot_geometry,
        dt=dt, camera_preset=camera_preset, camera_file=camera_file, sensor=sensor,
        world=world, physics_dt=physics_dt,
        teach_frames=teach_frames, image=image,
        noise=noise, calibration_error=cal_err, calibration=cal, task=task, clock=clock,
        drives=drives, payload=payload,
        reference=reference, sweep_axes=sweep, source=path, geometry_data=geometry_data,
        camera_data=camera_data, calibration_points=points, controller_options=dict(defaults),
        robot_model=robot_model, model_data=model_data,
    )


def _shared_for(defaults: dict[str, Any], own: dict[str, Any], path: str, key: str
                ) -> dict[str, Any]:
    """The ``[controller_options]`` a controller takes beside its own table's: not one
    its own table chose another way of setting (:data:`~controllers.options.
    ALTERNATIVE_OPTIONS`: its ``gain`` is not replaced by a file-wide ``adaptive_gain``).

    Its own table giving two of a group is warned of (``adaptive_gain`` wins, as the
    laws take it; a run's kept scenario written before this rule holds both).
    """
    from controllers.options import ALTERNATIVE_OPTIONS

    shared = dict(defaults)
    for group in ALTERNATIVE_OPTIONS:
        chosen = sorted(group & own.keys())
        if len(chosen) > 1:
            log.warning("%s: key '%s': %s both given: they set the same thing "
                        "(adaptive_gain replaces gain, which is not used); give one",
                        path, key, " and ".join(chosen))
        if chosen:
            for other in group - own.keys():
                shared.pop(other, None)
    return shared


def _checked_name(value: str, what: str, path: str, key: str) -> str:
    """:func:`hexapod.outputs.check_name` as a :class:`ScenarioError` naming the file and key."""
    from hexapod.exceptions import UnsafeNameError
    from hexapod.outputs import check_name

    try:
        return check_name(value, what)
    except UnsafeNameError as exc:
        raise ScenarioError(path, f"{exc.value!r}: {exc.problem}", key=key) from None


def _parse_world(robot: dict[str, Any], dt: float, path: str) -> tuple[str, float]:
    """``[robot] world`` and ``physics_dt`` (in the dynamic world, a divisor of the control
    period ``dt``; the kinematic world has no physics step)."""
    world = typed_value(robot.get("world", "kinematic"), str, path, "robot.world", WORLDS)
    physics_dt = typed_value(robot.get("physics_dt", 0.001), float, path, "robot.physics_dt")
    check_range(physics_dt, "robot.physics_dt", path)
    if world == "dynamic":
        check_physics_dt(dt, physics_dt, path)
    return world, physics_dt


def check_physics_dt(dt: float, physics_dt: float, path: str) -> None:
    """The dynamic world's physics step divides the control period.

    Raises:
        ScenarioError: It does not, naming ``robot.physics_dt``.
    """
    if physics_dt > dt * (1 + 1e-9):
        raise ScenarioError(path, f"{physics_dt:g} s is longer than the control period "
                            f"robot.dt ({dt:g} s)", key="robot.physics_dt")
    steps = round(dt / physics_dt)
    if abs(steps * physics_dt - dt) > 1e-9 * dt:
        raise ScenarioError(path, f"the control period robot.dt ({dt:g} s) is not a whole "
                            f"number of physics steps of {physics_dt:g} s",
                            key="robot.physics_dt")


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
