"""ROS ``camera_info`` YAML files (``camera_calibration_parsers``), written for a camera.

Reading goes through :func:`vision.cameras.files.opencv.read_opencv_calibration`
(``cv2.FileStorage`` reads these files: ``{rows, cols, data}`` matrices and the
``distortion_model`` key). This module writes them, as ROS's ``camera_calibration``
does: ``image_width``, ``image_height``, ``camera_name``, ``camera_matrix``,
``distortion_model``, ``distortion_coefficients``, ``rectification_matrix`` (the
identity: a monocular camera) and ``projection_matrix`` (``[K | 0]``). ROS names three
models: ``plumb_bob`` (OpenCV's five coefficients), ``rational_polynomial`` (eight)
and ``equidistant`` (the fisheye's four); a camera of another model has no ROS file.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from hexapod.exceptions import ConfigFileError

log = logging.getLogger(__name__)

def ros_model(kind: str, distortion: np.ndarray) -> str | None:
    """The ROS ``distortion_model`` of a camera kind and its coefficients, None if none."""
    d = np.asarray(distortion, float)
    if kind == "fisheye":
        return "equidistant"
    if kind != "perspective":
        return None
    if d.size <= 5 or not np.any(d[8:]):
        return "plumb_bob" if not np.any(d[5:]) else "rational_polynomial"
    return None


def _matrix(rows: int, cols: int, values: np.ndarray) -> str:
    data = ", ".join(repr(float(v)) for v in np.asarray(values, float).ravel())
    return f"\n  rows: {rows}\n  cols: {cols}\n  data: [{data}]"


def write_ros_camera_info(path: str | Path, kind: str, K: np.ndarray,
                          distortion: np.ndarray, width: int, height: int,
                          name: str = "camera") -> None:
    """Write a ROS ``camera_info`` YAML file (see the module docstring).

    Raises:
        ConfigFileError: The model has no ROS ``distortion_model`` (naming the model).
    """
    model = ros_model(kind, distortion)
    if model is None:
        raise ConfigFileError(str(path), f"a {kind} camera with coefficients "
                                         f"{np.asarray(distortion).tolist()} has no ROS "
                                         "distortion_model (plumb_bob, rational_polynomial, "
                                         "equidistant)", key="distortion_model")
    d = np.asarray(distortion, float)
    n = 4 if model == "equidistant" else 5 if model == "plumb_bob" else 8
    coeffs = np.zeros(n)
    coeffs[: min(n, d.size)] = d[:n]
    P = np.hstack([np.asarray(K, float), np.zeros((3, 1))])
    text = (f"image_width: {int(width)}\nimage_height: {int(height)}\ncamera_name: {name}\n"
            f"camera_matrix:{_matrix(3, 3, K)}\ndistortion_model: {model}\n"
            f"distortion_coefficients:{_matrix(1, n, coeffs)}\n"
            f"rectification_matrix:{_matrix(3, 3, np.eye(3))}\n"
            f"projection_matrix:{_matrix(3, 4, P)}\n")
    Path(path).write_text(text)
    log.debug("wrote %s (%s)", path, model)
