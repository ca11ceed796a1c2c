"""The camera file format (TOML): a camera as a table of pixels, millimetres, degrees.

This module turns a table into the fields of a camera (:class:`CameraFields`) and a
camera into a table; the models (:mod:`vision.cameras`) build and validate the camera
itself, so this module does not depend on them.

Format: ``kind`` (``"perspective"``, ``"unified"``, ``"fisheye"``,
``"double_sphere"``, ``"eucm"``), ``name``, ``width_px``, ``height_px``, ``fx_px``,
``fy_px``, ``cx_px``, ``cy_px``, ``skew_px``, ``xi`` (unified only), ``distortion``
(the lens: OpenCV's coefficients ``[k1, k2, p1, p2[, k3[, k4, k5, k6[, s1, s2, s3,
s4[, tau_x, tau_y]]]]]`` for a perspective camera, 4, 5, 8, 12 or 14 numbers;
``[k1, k2, p1, p2]`` for a unified one; ``[k1, k2, k3, k4]`` for a fisheye
(``cv2.fisheye``); ``[xi, alpha]`` for the double sphere, ``[alpha, beta]`` for the
extended unified model; absent for an ideal lens) and a table ``[camera_from_base]``
with ``translation_mm`` and ``rotation_vector_deg`` (axis times angle, degrees) or
``rotation_matrix``, such that ``p_camera = R p_base + t``.

Instead of the intrinsic keys, ``opencv = "calib.yml"`` names an OpenCV calibration
file (:mod:`vision.cameras.files.opencv`; the path is relative to the TOML file; read by
:mod:`vision.cameras.factory`, this module reads no other file): the camera
matrix, the distortion, ``xi`` and the image size come from it, the pose from the
``[camera_from_base]`` table; ``width_px`` and ``height_px`` may give the image size
when the OpenCV file does not (``omni_calibration.cpp``), and ``kind`` may be given
(it must then agree with the file: ``xi`` present means ``"unified"``).
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from hexapod.config import check_keys, get_matrix, get_number, suggest
from hexapod.exceptions import ConfigFileError
from hexapod.kinematics import Transform
from hexapod.se3 import exp_so3, log_so3
from vision.cameras.fields import CameraFields

log = logging.getLogger(__name__)

if TYPE_CHECKING:
    from vision.cameras.base import Camera

#: Keys of a camera table.
CAMERA_KEYS = ("kind", "name", "width_px", "height_px", "fx_px", "fy_px", "cx_px", "cy_px",
               "skew_px", "xi", "distortion", "camera_from_base")
#: Keys of a camera table that takes its intrinsics from an OpenCV file.
OPENCV_TABLE_KEYS = ("kind", "name", "opencv", "width_px", "height_px", "camera_from_base")
#: Keys of its ``[camera_from_base]`` table.
POSE_KEYS = ("translation_mm", "rotation_vector_deg", "rotation_matrix")
#: The camera kinds (models) a file may name.
KINDS = ("perspective", "unified", "fisheye", "double_sphere", "eucm")
#: Accepted lengths of the ``distortion`` list of each kind.
DISTORTION_LENGTHS = {"perspective": (4, 5, 8, 12, 14), "unified": (4,), "fisheye": (4,),
                      "double_sphere": (2,), "eucm": (2,)}
#: The names of the ``distortion`` list of each kind (for the messages).
DISTORTION_NAMES = {
    "perspective": "k1, k2, p1, p2[, k3[, k4, k5, k6[, s1, s2, s3, s4[, tau_x, tau_y]]]]",
    "unified": "k1, k2, p1, p2", "fisheye": "k1, k2, k3, k4", "double_sphere": "xi, alpha",
    "eucm": "alpha, beta"}


def camera_table(camera: Camera) -> dict[str, Any]:
    """The file representation of a camera (pixels, millimetres, degrees)."""
    d: dict[str, Any] = {
        "kind": camera.kind,
        "name": camera.name,
        "width_px": camera.width,
        "height_px": camera.height,
        "fx_px": float(camera.K[0, 0]),
        "fy_px": float(camera.K[1, 1]),
        "cx_px": float(camera.K[0, 2]),
        "cy_px": float(camera.K[1, 2]),
        "skew_px": float(camera.K[0, 1]),
    }
    if camera.kind == "unified":
        d["xi"] = float(camera.xi)
    if camera.is_distorted:
        d["distortion"] = [float(c) for c in camera.distortion]
    d["camera_from_base"] = pose_table(camera.camera_from_base)
    return d


def pose_table(pose: Transform) -> dict[str, Any]:
    """``[camera_from_base]``: ``translation_mm`` and ``rotation_vector_deg``."""
    rv = np.rad2deg(log_so3(pose.rotation))
    return {
        "translation_mm": ((pose.translation * 1e3).round(9) + 0.0).tolist(),
        "rotation_vector_deg": (rv.round(12) + 0.0).tolist(),
    }


def read_pose_table(table: dict[str, Any], path: str) -> Transform:
    """The pose of a ``[camera_from_base]`` table (identity when absent).

    The rotation is given either as ``rotation_vector_deg`` or as a 3x3
    ``rotation_matrix`` (not both); the translation as ``translation_mm``.
    """
    pose = table.get("camera_from_base", {})
    if not isinstance(pose, dict):
        raise ConfigFileError(path, "expected a table", key="camera_from_base")
    pre = "camera_from_base."
    check_keys(pose, POSE_KEYS, path, prefix=pre)
    t = (get_matrix(pose, "translation_mm", (3,), path, pre) * 1e-3
         if "translation_mm" in pose else np.zeros(3))
    if "rotation_vector_deg" in pose and "rotation_matrix" in pose:
        raise ConfigFileError(path, "give rotation_vector_deg or rotation_matrix, not both",
                              key="camera_from_base")
    if "rotation_matrix" in pose:
        R = _rotation_as_written(get_matrix(pose, "rotation_matrix", (3, 3), path, pre), path)
    elif "rotation_vector_deg" in pose:
        R = exp_so3(np.deg2rad(get_matrix(pose, "rotation_vector_deg", (3,), path, pre)))
    else:
        R = np.eye(3)
    return Transform(R, t)


#: How far from orthonormal a file's ``rotation_matrix`` may be, written to a few
#: decimals (3 decimals give about 5e-4): its nearest rotation is used, and said.
ROUNDED_ROTATION = 2e-3


def _rotation_as_written(R: np.ndarray, path: str) -> np.ndarray:
    """A file's ``rotation_matrix``: as it is when a rotation to rounding (1e-9); the
    nearest rotation (SVD, polar factor) of one rounded to a few decimals, logged with
    the largest change; refused beyond :data:`ROUNDED_ROTATION` or when it mirrors."""
    defect = float(np.abs(R.T @ R - np.eye(3)).max())
    det = float(np.linalg.det(R))
    if defect <= 1e-9 and det > 0:
        return R
    key = "camera_from_base.rotation_matrix"
    if det <= 0:
        raise ConfigFileError(path, f"det = {det:.6f}: a mirror (a left-handed frame?), not "
                              "a rotation", key=key)
    if defect > ROUNDED_ROTATION:
        raise ConfigFileError(path, f"not a rotation matrix (|R^T R - I| = {defect:.2e}; one "
                              "rounded to 3 decimals or more is taken, its nearest rotation "
                              "used; or give rotation_vector_deg)", key=key)
    U, _, Vt = np.linalg.svd(R)
    nearest = U @ Vt
    log.warning("%s: %s is a rotation to %.1e only (rounded?): its nearest rotation is used "
                "(no element changed by more than %.1e)", path, key, defect,
                float(np.abs(nearest - R).max()))
    return np.asarray(nearest)


def read_camera_table(table: dict[str, Any], path: str = "<dict>",
                      model: tuple[str, str] | None = None) -> CameraFields:
    """The fields of a camera table (see the module docstring for the format).

    Args:
        table: The parsed TOML table.
        path: The file, for the error messages.
        model: ``(kind, class name)`` when a specific model is being loaded: the
            table's ``kind`` defaults to it and must match it.

    Raises:
        ConfigFileError: Missing, misspelt or unknown key, bad value (naming the key).
    """
    check_keys(table, CAMERA_KEYS, path,
               required=("width_px", "height_px", "fx_px", "fy_px", "cx_px", "cy_px"))
    kind = read_kind(table, path, model, None)
    for key in ("width_px", "height_px"):
        positive_int(table, key, path)
    f = {k: get_number(table, k, path) for k in ("fx_px", "fy_px", "cx_px", "cy_px")}
    skew = get_number(table, "skew_px", path) if "skew_px" in table else 0.0
    for k in ("fx_px", "fy_px"):
        if f[k] <= 0:
            raise ConfigFileError(path, f"focal length must be positive, got {f[k]}", key=k)
    for k, size_key in (("cx_px", "width_px"), ("cy_px", "height_px")):
        size = table[size_key]
        if not -0.5 <= f[k] <= size - 0.5:  # (pixel centres are integers)
            raise ConfigFileError(path, f"the principal point must lie in the image, "
                                  f"[-0.5, {size - 0.5:g}] px for {size_key} = {size}, got "
                                  f"{f[k]:g} (width and height swapped, or another unit?)",
                                  key=k)
    K = np.array([[f["fx_px"], skew, f["cx_px"]], [0.0, f["fy_px"], f["cy_px"]],
                  [0.0, 0.0, 1.0]])
    xi = 0.0
    if kind == "unified":
        if "xi" not in table:
            raise ConfigFileError(path, "missing required key (unified camera)", key="xi")
        xi = get_number(table, "xi", path)
        if xi < 0:
            raise ConfigFileError(path, f"must be >= 0, got {xi}", key="xi")
    elif "xi" in table:
        xi = get_number(table, "xi", path)
        if xi != 0:
            raise ConfigFileError(
                path, (f"a {kind.replace('_', ' ')} camera's xi goes in distortion = "
                       f"[{DISTORTION_NAMES[kind]}], got xi = {xi}"
                       if DISTORTION_NAMES.get(kind, "").startswith("xi") else
                       f"a {kind} camera has xi = 0, got {xi} (use kind = 'unified')"),
                key="xi")
    distortion = (read_distortion(table["distortion"], DISTORTION_LENGTHS[kind], path,
                                  "distortion", DISTORTION_NAMES[kind])
                  if "distortion" in table else None)
    pose = read_pose_table(table, path)
    name = table.get("name", Path(path).stem)
    if not isinstance(name, str):
        raise ConfigFileError(path, f"expected a string, got {name!r}", key="name")
    return CameraFields(kind, K, xi, table["width_px"], table["height_px"], pose, name, path,
                        distortion)


def read_distortion(value: Any, lengths: tuple[int, ...], path: str, key: str,
                    names: str = "k1, k2, p1, p2, k3") -> np.ndarray:
    """A distortion vector of one of the ``lengths`` (finite numbers).

    Raises:
        ConfigFileError: Not a flat list of that many finite numbers (naming ``key``).
    """
    want = " or ".join(str(n) for n in lengths)
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ConfigFileError(path, f"expected {want} numbers ({names}), got {value!r}",
                              key=key) from None
    if arr.ndim != 1 or arr.shape[0] not in lengths:
        raise ConfigFileError(path, f"expected {want} numbers ({names}), got shape "
                              f"{arr.shape}", key=key)
    if not np.all(np.isfinite(arr)):
        raise ConfigFileError(path, f"contains NaN or inf: {arr.tolist()}", key=key)
    return arr


def positive_int(table: dict[str, Any], key: str, path: str) -> int:
    v = table[key]
    if isinstance(v, bool) or not isinstance(v, int) or v <= 0:
        raise ConfigFileError(path, f"expected a positive integer, got {v!r}", key=key)
    return v


def read_kind(table: dict[str, Any], path: str, model: tuple[str, str] | None,
          default: str | None) -> str:
    """The table's ``kind`` (or the default): known, and the model's if one is loaded."""
    if default is None and model is not None:
        default = model[0]
    kind = table.get("kind", default)
    if kind is None:
        raise ConfigFileError(path, "missing required key", key="kind")
    if kind not in KINDS:
        hint = suggest(str(kind), KINDS)
        raise ConfigFileError(path, f"unknown camera kind {kind!r}; expected one of "
                              f"{', '.join(KINDS)}", key="kind", suggestion=hint)
    if model is not None and kind != model[0]:
        raise ConfigFileError(path, f"kind {kind!r} cannot be loaded as {model[1]}", key="kind")
    return str(kind)
