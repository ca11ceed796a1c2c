"""No silent simulation: which camera a servo session may use (:func:`choose_camera`), and
how the banner names it (:func:`describe_camera`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from benchmarks.exceptions import BenchmarkError

#: The option that allows ``--camera sim`` on real hardware.
ALLOW_SIMULATED_FLAG = "--simulated-camera-on-real-robot"


def choose_camera(backend: str, camera: str | None, allow_simulated: bool) -> str:
    """The ``--camera`` spec a session uses: a real robot (a backend the registry does not
    mark simulated, :meth:`hexapod.backends.registry.BackendRegistry.is_simulated`) needs
    ``--camera``, and ``sim`` (images rendered at the encoders' pose) only with
    ``--simulated-camera-on-real-robot``.

    Args:
        backend: The ``--backend`` spec (already checked).
        camera: The ``--camera`` given, or None.
        allow_simulated: ``--simulated-camera-on-real-robot`` was given.

    Returns:
        The camera spec (``sim`` by default with a simulated robot).

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
    """The banner's camera: its spec, its file, its model and where it is.

    Args:
        spec: The ``--camera`` spec.
        camera_file: ``--camera-file``.
        camera_pose: ``--camera-pose`` (or None).
        camera: The loaded camera model (``camera_from_base``, ``kind``, size).

    Returns:
        E.g. ``camera device:0 (file front, perspective 640x480, at (0.0, -900.0, 300.0)
        mm in the base frame, looking along (0.00, 1.00, -0.20))``.
    """
    base_from_camera = camera.camera_from_base.inverse()
    x = np.asarray(base_from_camera.translation, float) * 1e3
    z = np.asarray(base_from_camera.rotation, float)[:, 2]
    pose = f"; pose from {camera_pose}" if camera_pose else ""
    what = ("simulated: images rendered at the encoders' pose" if spec == "sim"
            else "a recording" if spec.startswith("video:") else "live")
    return (f"camera {spec} ({what}; file {camera_file}{pose}, {camera.kind} "
            f"{camera.width}x{camera.height}, at ({x[0]:.1f}, {x[1]:.1f}, {x[2]:.1f}) mm in "
            f"the base frame, looking along ({z[0]:.2f}, {z[1]:.2f}, {z[2]:.2f}))")
