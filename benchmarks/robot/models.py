"""The robot and camera models a servo session (and what replays or checks one) loads
from its options: ``--geometry``, ``--camera-file`` and ``--camera-pose``."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from benchmarks.exceptions import BenchmarkError
from hexapod.geometry import HexapodGeometry

__all__ = ["camera_model", "robot_geometry"]


def robot_geometry(spec: str) -> HexapodGeometry:
    """The nominal robot of ``--geometry``: a geometry TOML file or a preset name."""
    from hexapod.geometry import preset

    if spec.endswith(".toml") or Path(spec).is_file():
        return HexapodGeometry.from_toml(spec)
    return preset(spec)


def camera_model(spec: str, pose_spec: str | None, geometry: HexapodGeometry) -> Any:
    """The camera of ``--camera-file`` (and ``--camera-pose`` for an OpenCV file).

    Raises:
        BenchmarkError: An OpenCV file without a pose, or a pose for another camera.
    """
    from vision.cameras import load_camera
    from vision.cameras.files.opencv import is_opencv_file

    if not is_opencv_file(spec):
        if pose_spec is not None:
            raise BenchmarkError("--camera-pose: only with an OpenCV calibration file (a "
                                 f"preset or a camera TOML file gives its own pose: {spec})")
        return load_camera(spec, geometry)
    if pose_spec is None:
        raise BenchmarkError(f"--camera-file {spec}: an OpenCV calibration file has no pose; "
                             "give --camera-pose front|omni or a camera TOML file whose "
                             "[camera_from_base] places it")
    pose = load_camera(pose_spec, geometry).camera_from_base
    return load_camera(spec, camera_from_base=pose)
