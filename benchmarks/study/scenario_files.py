"""The files a scenario names, read once when it is loaded: the controllers' robot model
(``[robot] model``), the robot and camera files (an OpenCV calibration with its pose), the
calibrated base points, and a camera preset's lens for the checks."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from benchmarks.exceptions import ScenarioError
from benchmarks.study.scenario_checks import referenced_file
from benchmarks.study.scenario_model import CalibrationConfig
from benchmarks.study.scenario_ranges import typed_value
from hexapod.exceptions import ConfigFileError


def read_model(robot: dict[str, Any], base_dir: Path, path: str) -> tuple[str | None, Any]:
    """``[robot] model``: a robot file whose ``[inertia]`` and ``[drives]`` are the
    controllers' model (e.g. ``hexapod-bench identify``'s ``identified.toml``), read once.

    Raises:
        ScenarioError: The file is missing or invalid, naming it.
    """
    if "model" not in robot:
        return None, None
    from hexapod.exceptions import HexapodError
    from hexapod.geometry import HexapodGeometry

    value = typed_value(robot["model"], str, path, "robot.model")
    model = referenced_file(base_dir, value, "robot.model", path)
    try:
        return model, HexapodGeometry.from_toml(model)
    except HexapodError as exc:
        raise ScenarioError(path, f"{model}: {exc}", key="robot.model") from None


def read_files(geometry_file: str | None, camera_file: str | None, cal: CalibrationConfig,
                opencv: dict[str, Any] | None, robot_preset: str | None, path: str
                ) -> tuple[Any, Any, Any]:
    """Read the files a scenario names, once (see :class:`Scenario`).

    Args:
        geometry_file, camera_file: The robot and camera files (None: presets).
        cal: The calibration settings (``file`` with method ``"file"``).
        opencv: For an OpenCV calibration file: ``pose`` (a preset's placement) or
            ``camera_from_base`` (a table as in camera files), ``width_px``/``height_px``.
        robot_preset: The robot preset (a preset placement scales with the robot).
        path: The scenario file (errors).

    Raises:
        ScenarioError: A file missing or invalid, naming it and the key at fault.
    """
    from benchmarks.study.calibration import load_calibrated_base_points
    from hexapod.geometry import HexapodGeometry
    from hexapod.geometry import preset as geometry_preset
    from vision.cameras import camera_preset, load_camera
    from vision.cameras.files.project import read_pose_table
    from vision.exceptions import CameraError

    try:
        geometry = None if geometry_file is None else HexapodGeometry.from_toml(geometry_file)
        camera = None
        if camera_file is not None and opencv is not None:
            robot = geometry or geometry_preset(robot_preset or "deltalab")
            pose = (camera_preset(opencv["pose"], robot).camera_from_base if "pose" in opencv
                    else read_pose_table({"camera_from_base": opencv.get("camera_from_base",
                                                                         {})}, path))
            size = None
            if "width_px" in opencv or "height_px" in opencv:
                for given, other in (("width_px", "height_px"), ("height_px", "width_px")):
                    if given in opencv and other not in opencv:
                        raise ScenarioError(path, f"{given} needs {other} (the image's "
                                            "size, both in pixels)", key=f"camera.{other}")
                size = (typed_value(opencv.get("width_px"), int, path, "camera.width_px"),
                        typed_value(opencv.get("height_px"), int, path, "camera.height_px"))
            camera = load_camera(camera_file, camera_from_base=pose, image_size=size)
        elif camera_file is not None:
            camera = load_camera(camera_file)
        points = (load_calibrated_base_points(cal.file)
                  if cal.method == "file" and cal.file else None)
    except ConfigFileError as exc:
        raise ScenarioError(exc.path, exc.problem, exc.key, exc.suggestion) from None
    except CameraError as exc:
        raise ScenarioError(camera_file or path, str(exc), key="camera") from None
    return geometry, camera, points


def preset_camera(name: str) -> Any:
    """A camera preset's lens, for the checks of a scenario that names it (the preset on
    the default robot: its lens model does not depend on the robot)."""
    from vision.cameras import camera_preset

    return camera_preset(name)


__all__ = ["preset_camera", "read_files", "read_model"]
