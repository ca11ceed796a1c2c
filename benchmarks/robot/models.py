"""The robot and camera models a servo session (and what replays or checks one) loads
from its options (``--geometry``, ``--camera-file`` and ``--camera-pose``), the platform
pose the nominal robot gives the measured lengths (:class:`EncoderPose`), and no silent
simulation: which camera a session may use (:func:`choose_camera`) and how the banner
names it (:func:`describe_camera`)."""

from __future__ import annotations

import argparse
import logging
import math
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.exceptions import BenchmarkError
from hexapod.geometry import HexapodGeometry

log = logging.getLogger(__name__)

#: The option that allows ``--camera sim`` on real hardware.
ALLOW_SIMULATED_FLAG = "--simulated-camera-on-real-robot"


def add_robot_arguments(p: argparse.ArgumentParser) -> None:
    """Add ``--geometry`` and ``--dt`` (the nominal robot, the control period) to a
    parser (``servo``, ``conformance``)."""
    p.add_argument("--geometry", default="deltalab",
                   help="nominal robot: a geometry TOML file or a preset (default deltalab)")
    p.add_argument("--dt", type=float, default=0.02, help="control period [s] (default 0.02)")


def check_option(flag: str, value: float | None, low: float = 0.0, *, strict: bool = True,
                 finite: bool = False, note: str = "") -> None:
    """Refuse an option's ``value`` at or below ``low`` (``strict``: "must be positive"
    when ``low`` is 0) or below it, or (``finite``) not finite; None passes.

    Raises:
        BenchmarkError: Naming the option and the value.
    """
    if value is None or ((value > low if strict else value >= low)
                         and (not finite or math.isfinite(value))):
        return
    need = ("positive" if strict and low == 0 else f">= {low:g}") + (" and finite" if finite
                                                                    else "")
    raise BenchmarkError(f"{flag} must be {need}{note}, got {value}")


def check_dt(dt: float) -> None:
    """Refuse a ``--dt`` [s] that is not a positive period.

    Raises:
        BenchmarkError: Naming the value.
    """
    if not (math.isfinite(dt) and dt > 0):
        raise BenchmarkError(f"--dt must be a positive period in seconds, got {dt}")


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


class EncoderPose:
    """The platform pose of measured leg lengths: the forward kinematics of the nominal
    ``geometry``, seeded with the previous pose; a failure keeps the last pose (logged
    when ``warn``), and with no pose yet is a :class:`BenchmarkError` starting with
    ``what``."""

    def __init__(self, geometry: HexapodGeometry, what: str = "no platform pose",
                 warn: bool = True) -> None:
        self.geometry, self.what, self.warn = geometry, what, warn
        #: The last pose ``(R, t)`` [-, m] (None: none yet).
        self.pose: tuple[np.ndarray, np.ndarray] | None = None

    def __call__(self, lengths: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The pose ``(R (3, 3), t (3,) [m])`` of ``lengths`` (6,) [m].

        Raises:
            BenchmarkError: No pose for the first lengths.
        """
        from hexapod.exceptions import ForwardKinematicsError
        from hexapod.fk import forward_kinematics

        try:
            sol = forward_kinematics(self.geometry, lengths, guess=self.pose,
                                     check_stroke=False)
            self.pose = (sol.rotation, sol.translation)
        except ForwardKinematicsError as exc:
            if self.pose is None:
                raise BenchmarkError(f"{self.what} for the measured lengths "
                                     f"{np.round(lengths * 1e3, 3)} mm: {exc}") from None
            if self.warn:
                log.warning("forward kinematics failed (%s); keeping the last pose", exc)
        return self.pose


def choose_camera(backend: str, camera: str | None, allow_simulated: bool) -> str:
    """The ``--camera`` spec a session on ``--backend`` ``backend`` (checked) uses: the
    ``camera`` given (``sim`` by default with a simulated robot); real hardware (not
    :meth:`~hexapod.backends.registry.BackendRegistry.is_simulated`) needs one, and
    ``sim`` (images rendered at the encoders' pose) only with ``allow_simulated``
    (``--simulated-camera-on-real-robot``).

    Raises:
        BenchmarkError: No camera, or ``sim``, with real hardware (and the flag not given).
    """
    from hexapod.backends.registry import backends

    if backends.is_simulated(backend):
        return "sim" if camera is None else camera
    if camera is None:
        raise BenchmarkError(
            f"--backend {backend} is real hardware: give the camera that watches it "
            f"(--camera device:N, or video:PATH for a recording that agrees with the robot); "
            f"a simulated camera needs --camera sim {ALLOW_SIMULATED_FLAG}")
    if camera == "sim" and not allow_simulated:
        raise BenchmarkError(
            f"--camera sim with --backend {backend} (real hardware) would close the loop on "
            f"images rendered at the encoders' pose, not on what the robot does; give "
            f"--camera device:N, or add {ALLOW_SIMULATED_FLAG} to do it on purpose")
    return camera


def describe_camera(spec: str, camera_file: str, camera_pose: str | None,
                    camera: Any) -> str:
    """The banner's camera of ``--camera`` ``spec``, ``--camera-file`` and
    ``--camera-pose`` (or None), with the loaded ``camera``: e.g. ``camera device:0
    (live; file front, perspective 640x480, at (0.0, -900.0, 300.0) mm in the base
    frame, looking along (0.00, 1.00, -0.20))``."""
    base_from_camera = camera.camera_from_base.inverse()
    x = np.asarray(base_from_camera.translation, float) * 1e3
    z = np.asarray(base_from_camera.rotation, float)[:, 2]
    pose = f"; pose from {camera_pose}" if camera_pose else ""
    what = ("simulated: images rendered at the encoders' pose" if spec == "sim"
            else "a recording" if spec.startswith("video:") else "live")
    return (f"camera {spec} ({what}; file {camera_file}{pose}, {camera.kind} "
            f"{camera.width}x{camera.height}, at ({x[0]:.1f}, {x[1]:.1f}, {x[2]:.1f}) mm in "
            f"the base frame, looking along ({z[0]:.2f}, {z[1]:.2f}, {z[2]:.2f}))")
