"""The allowed range of every number of a scenario, and its check."""

from __future__ import annotations

from typing import Any

from benchmarks.exceptions import ScenarioError
from benchmarks.study.scenario_payload import PAYLOAD_RANGES
from hexapod.config import suggest

#: Allowed range of every numeric key: ``(low, high, low_inclusive, high_inclusive)``.
#: A value that parses but cannot describe a study (a negative seed, a 1e308 mm error,
#: a 1e9 deg noise) is refused when the file is loaded, naming the key and the range.
RANGES: dict[str, tuple[float, float, bool, bool]] = {
    "seed": (0, 2**63 - 1, True, True),
    "trials": (1, 10_000_000, True, True),
    "robot.dt": (0.0, 1.0, False, True),
    "robot.physics_dt": (1e-6, 0.1, True, True),
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
    "calibration_error.distortion_percent": (0.0, 100.0, True, True),
    "calibration_error.mass_percent": (0.0, 50.0, True, True),
    "calibration_error.inertia_percent": (0.0, 50.0, True, True),
    "calibration_error.model_mass_error_percent": (-50.0, 100.0, True, True),
    "calibration_error.model_inertia_error_percent": (-50.0, 100.0, True, True),
    "calibration_error.model_friction_error_percent": (-50.0, 100.0, True, True),
    "calibration_error.model_rotor_inertia_error_percent": (-50.0, 100.0, True, True),
    "calibration_error.model_drive_bandwidth_error_percent": (-50.0, 100.0, True, True),
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
    "task.speed_mm_s": (0.0, 10_000.0, False, True),
    "task.acceleration_mm_s2": (0.0, 1_000_000.0, False, True),
    "task.angular_speed_deg_s": (0.0, 10_000.0, False, True),
    "task.angular_acceleration_deg_s2": (0.0, 1_000_000.0, False, True),
    "task.radius_mm": (0.0, 1000.0, False, True),
    "task.laps": (1, 1000, True, True),
    "task.jerk_mm_s3": (0.0, 1e9, False, True),
    "task.angular_jerk_deg_s3": (0.0, 1e9, False, True),
    "task.peak_acceleration_mm_s2": (0.0, 1e7, True, True),
    "clock.frame_rate_hz": (0.0, 100_000.0, True, True),
    "clock.latency_ms": (0.0, 10_000.0, True, True),
    "clock.latency_frames": (0.0, 1000.0, True, True),
    "clock.jitter_ms": (0.0, 1000.0, True, True),
    "clock.exposure_ms": (0.0, 1000.0, True, True),
    "clock.exposure_samples": (1, 256, True, True),
    "drives.velocity_bandwidth_hz": (0.0, 100_000.0, True, True),
    **PAYLOAD_RANGES,
}

#: Units of keys whose name does not end in one (the others: :func:`unit_of`).
_UNITS = {"robot.dt": "s", "robot.physics_dt": "s"}
#: A key's unit from the end of its name (the longest first).
_SUFFIXES = (("_mm_s3", "mm/s^3"), ("_mm_s2", "mm/s^2"), ("_mm_s", "mm/s"),
             ("_deg_s3", "deg/s^3"), ("_deg_s2", "deg/s^2"), ("_deg_s", "deg/s"),
             ("_mm", "mm"), ("_deg", "deg"), ("_hz", "Hz"), ("_ms", "ms"), ("_px", "px"),
             ("_percent", "%"), ("_kg", "kg"), ("_n", "N"), ("_s", "s"))


def unit_of(key: str) -> str:
    """The unit of a dotted key (``task.speed_mm_s``: ``mm/s``; ``robot.dt``: ``s``), or
    empty for a count or a fraction."""
    if key in _UNITS:
        return _UNITS[key]
    return next((unit for end, unit in _SUFFIXES if key.endswith(end)), "")


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
        unit = unit_of(key)
        interval = (f"{'[' if lo_in else '('}{lo:g}, {hi:g}{']' if hi_in else ')'}"
                    + (f" {unit}" if unit else ""))
        raise ScenarioError(path, f"{value!r}{f' {unit}' if unit else ''} is out of the "
                            f"allowed range {interval}{_unit_hint(value, key, unit)}",
                            key=key)


def _unit_hint(value: float, key: str, unit: str) -> str:
    """A likely slip of units, when the value a thousand times smaller (or larger) is in
    range: milliseconds for seconds (``dt = 20``), metres for millimetres."""
    if not unit:
        return ""
    lo, hi, lo_in, hi_in = RANGES[key]
    for factor in (1e-3, 1e3):
        scaled = value * factor
        if (scaled >= lo if lo_in else scaled > lo) and (scaled <= hi if hi_in else scaled < hi):
            return (f" (a slip of units? {key} is in {unit}; {scaled:g} {unit} would be in "
                    "range)")
    return ""


def typed_value(value: Any, kind: type, path: str, key: str, choices: tuple[str, ...] = ()) -> Any:
    """``value`` of scenario key ``key`` as ``kind`` (a finite float, an int, a bool or a
    string of ``choices``).

    Raises:
        ScenarioError: Naming the file and key: a list where one value is expected (a key
            that cannot be swept), another type, a number not finite, a string not among
            ``choices`` (with the close one).
    """
    if isinstance(value, list) and kind in (float, int, bool, str):  # (a sweep axis?)
        raise ScenarioError(path, f"expected one value, got the list {value!r}: this key "
                            "cannot be swept (docs/scenarios.md lists the sweepable keys)",
                            key=key)
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
