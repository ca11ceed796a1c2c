"""The constructor arguments of a camera read from a file (:class:`CameraFields`).

The lowest layer of :mod:`vision.cameras`: the file readers (:mod:`vision.cameras.files`)
produce these fields, the models (:meth:`vision.cameras.base.Camera._from_fields`) build
and validate a camera from them, so that neither imports the other.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hexapod.kinematics import Transform


@dataclass(frozen=True)
class CameraFields:
    """The constructor arguments of a camera read from a file (not validated yet).

    Attributes:
        kind: ``"perspective"`` or ``"unified"``.
        K: (3, 3) intrinsics [px].
        xi: Mirror parameter (0 for a perspective camera).
        width: Image width [px].
        height: Image height [px].
        camera_from_base: Pose w.r.t. the robot base.
        name: A label (the file's stem by default).
        source: The file.
        distortion: OpenCV's distortion coefficients (None: an ideal lens).
    """

    kind: str
    K: np.ndarray
    xi: float
    width: int
    height: int
    camera_from_base: Transform
    name: str
    source: str
    distortion: np.ndarray | None = None


@dataclass(frozen=True)
class Calibration:
    """The intrinsics of a calibration file (OpenCV, ROS camera_info, Kalibr).

    Attributes:
        kind: The camera model (a camera ``kind``: ``"perspective"``, ``"unified"``,
            ``"fisheye"``, ``"double_sphere"``, ``"eucm"``).
        K: (3, 3) camera matrix [px].
        distortion: The lens coefficients in the order of the model's ``distortion``
            (OpenCV's order for the perspective, unified and fisheye models; ``(xi,
            alpha)`` for the double sphere, ``(alpha, beta)`` for the extended unified).
        xi: Mirror parameter of Mei's model; None for the other models.
        width: Image width [px], None when the file does not say.
        height: Image height [px], None when the file does not say.
        source: The file.
        notes: What the file gave that the camera does not use (e.g. Kalibr's
            ``T_cam_imu``), for the log and the user.
    """

    kind: str
    K: np.ndarray
    distortion: np.ndarray
    xi: float | None
    width: int | None
    height: int | None
    source: str
    notes: tuple[str, ...] = ()
