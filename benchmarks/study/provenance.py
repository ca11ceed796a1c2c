"""Calibration provenance: which robot and camera a ``calibrated.toml`` was made with.

``hexapod-bench calibrate`` writes a ``[made_with]`` table (the robot's and the camera's
names and fingerprints: a hash of the parameters the base points depend on). A study
or ``servo`` that uses the file compares it with its own robot and camera: another robot
or camera is refused (its base points describe another machine), unless the user
insists (``--allow-foreign-calibration``, or ``[calibration] allow_foreign = true``),
which is then warned loudly. Base points farther than :data:`FAR_FROM_NOMINAL_MM` from
the nominal ones are flagged either way. See ``docs/calibration.md``.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.exceptions import ForeignCalibrationError

#: A calibrated base point farther than this from its nominal position (both in the
#: camera frame) is flagged [mm]: CAD and placement errors are millimetres to a few
#: centimetres; farther means another robot, another camera pose, or a bad calibration.
FAR_FROM_NOMINAL_MM = 50.0
#: The option that accepts a foreign calibration, for the messages.
ALLOW_OPTION = "--allow-foreign-calibration (in a scenario: [calibration] allow_foreign = true)"


def _digest(values: dict[str, Any]) -> str:
    text = json.dumps(values, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _rounded(a: Any, decimals: int) -> Any:
    return np.round(np.asarray(a, float), decimals).tolist()


def robot_fingerprint(geometry: Any) -> str:
    """Hash of what calibrated base points depend on: the base and platform points, the
    strokes and the leg radius (to the micrometre)."""
    return _digest({"base_points_mm": _rounded(geometry.base_points * 1e3, 3),
                    "platform_points_mm": _rounded(geometry.platform_points * 1e3, 3),
                    "stroke_mm": _rounded(np.array(geometry.stroke) * 1e3, 3),
                    "leg_radius_mm": _rounded(geometry.leg_radius * 1e3, 3)})


def camera_fingerprint(camera: Any) -> str:
    """Hash of the camera model the base points are expressed in: kind, size, intrinsics,
    mirror parameter, distortion and pose relative to the base."""
    T = camera.camera_from_base.as_matrix()
    return _digest({"kind": str(camera.kind), "size": [int(camera.width), int(camera.height)],
                    "K_px": _rounded(camera.K, 4),
                    "xi": _rounded(getattr(camera, "xi", 0.0), 6),
                    "distortion": _rounded(getattr(camera, "distortion", []), 6),
                    "rotation": _rounded(T[:3, :3], 9),
                    "translation_mm": _rounded(T[:3, 3] * 1e3, 3)})


def made_with(robot_name: str, geometry: Any, camera_name: str, camera: Any) -> dict[str, str]:
    """The ``[made_with]`` table of a ``calibrated.toml``."""
    return {"robot": robot_name, "robot_fingerprint": robot_fingerprint(geometry),
            "camera": camera_name, "camera_fingerprint": camera_fingerprint(camera)}


def scenario_setup(sc: Any) -> tuple[str, Any, str, Any]:
    """A scenario's robot and camera: (robot name, nominal geometry, camera name, camera)."""
    from benchmarks.sim import load_camera, load_geometry

    geometry = load_geometry(sc)
    camera = load_camera(sc, geometry)
    robot = sc.robot_preset or Path(str(sc.robot_geometry)).name
    cam = sc.camera_preset or Path(str(sc.camera_file)).name
    return robot, geometry, cam, camera


def distances_from_nominal(points: np.ndarray, geometry: Any, camera: Any) -> np.ndarray:
    """(6,) distances [mm] of base points (camera frame [m]) from the nominal ones."""
    nominal = camera.camera_from_base.apply(geometry.base_points)
    return np.asarray(np.linalg.norm(np.asarray(points, float) - nominal, axis=1) * 1e3)


def far_message(path: str, distances: np.ndarray,
                threshold_mm: float = FAR_FROM_NOMINAL_MM) -> str | None:
    """The flag for base points farther than ``threshold_mm`` from the nominal ones."""
    far = [(i, float(d)) for i, d in enumerate(distances) if d > threshold_mm]
    if not far:
        return None
    legs = ", ".join(f"{i} ({d:.1f} mm)" for i, d in far)
    every = (" (all six: the camera file's pose is not this setup's, or the observations' "
             "normals are not in this camera's frame)" if len(far) == len(distances) else "")
    return (f"{path}: base point(s) {legs} farther than {threshold_mm:g} mm from the "
            f"nominal ones{every}: another robot or camera pose, or a calibration gone wrong; "
            "check the robot and camera files before trusting it")


def check_calibration(path: str, points: np.ndarray, recorded: dict[str, Any] | None,
                      robot_name: str, geometry: Any, camera_name: str, camera: Any,
                      allow_foreign: bool = False) -> list[str]:
    """Compare a calibration file with the robot and camera it is about to be used with.

    Args:
        path: The ``calibrated.toml`` (messages).
        points: Its (6, 3) base points in the camera frame [m].
        recorded: Its ``[made_with]`` table (None: a file without one).
        robot_name, geometry: The robot it is used with (name, nominal geometry).
        camera_name, camera: The camera it is used with.
        allow_foreign: The user insists on another robot's or camera's file.

    Returns:
        Warnings (the caller shows them): a foreign file accepted, a file without provenance,
        points far from the nominal ones.

    Raises:
        ForeignCalibrationError: Made with another robot or camera (and not
            ``allow_foreign``), naming both and how to proceed.
    """
    warnings = []
    if recorded is None:
        warnings.append(f"{path}: records no robot or camera (written before provenance, or "
                        "by hand): it cannot be checked against this robot and camera")
    else:
        current = made_with(robot_name, geometry, camera_name, camera)
        differ = [_difference(what, recorded, current) for what in ("robot", "camera")
                  if recorded.get(what + "_fingerprint") != current[what + "_fingerprint"]]
        if differ:
            text = "made with " + " and with ".join(differ)
            if not allow_foreign:
                raise ForeignCalibrationError(
                    path, f"{text}: its base points belong to another setup; calibrate this "
                    f"one (hexapod-bench calibrate SCENARIO --out DIR), or pass "
                    f"{ALLOW_OPTION} to use it anyway", key="made_with")
            warnings.append(f"{path}: FOREIGN CALIBRATION used as asked: {text}")
    flag = far_message(path, distances_from_nominal(points, geometry, camera))
    if flag:
        warnings.append(flag)
    return warnings


def _difference(what: str, recorded: dict[str, Any], current: dict[str, str]) -> str:
    """``the robot 'a' (fingerprint x), not this robot 'b' (y)``."""
    name, fp = recorded.get(what, "?"), recorded.get(what + "_fingerprint", "?")
    here, here_fp = current[what], current[what + "_fingerprint"]
    if name == here:
        return (f"the {what} '{name}' with other parameters (fingerprint {fp}, this "
                f"{what}'s {here_fp})")
    return f"the {what} '{name}' (fingerprint {fp}), not this {what} '{here}' ({here_fp})"


def check_scenario_calibration(sc: Any, allow_foreign: bool = False) -> list[str]:
    """:func:`check_calibration` for a scenario that controls with a calibration file
    (``[calibration] method = "file"`` or ``run --calibration``); nothing otherwise.

    Raises:
        ForeignCalibrationError: See :func:`check_calibration`.
    """
    if sc.calibration.method != "file" or not sc.calibration.file:
        return []
    from benchmarks.study.calibration import read_calibrated_file

    points, recorded = read_calibrated_file(sc.calibration.file)
    robot, geometry, cam, camera = scenario_setup(sc)
    warnings = check_calibration(str(sc.calibration.file), points, recorded, robot, geometry,
                                 cam, camera, allow_foreign or sc.calibration.allow_foreign)
    drawn = [key for key in _SHIFTS_BASE_POINTS
             if any(sc.calibration_error.scale * v for v in sc.sweep_axes.get(
                 f"calibration_error.{key}", [getattr(sc.calibration_error, key)]))]
    if drawn:
        warnings.append(
            f"{sc.calibration.file}: scenario '{sc.name}' draws a calibration error per trial "
            f"({', '.join(drawn)}): every trial is another robot, and this one file gives "
            "them all the same base points; to calibrate each trial in its own world, use "
            "[calibration] method = \"linear\" without --calibration (docs/calibration.md, "
            "'Two loops')")
    return warnings


#: Calibration errors that move the true base points in the camera frame.
_SHIFTS_BASE_POINTS = ("base_points_mm", "camera_pose_mm", "camera_pose_deg")
