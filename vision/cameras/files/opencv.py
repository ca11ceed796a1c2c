"""OpenCV calibration files (``cv2.FileStorage``: YAML, XML, JSON) as camera intrinsics.

The files written by OpenCV's calibration samples and tools:

- ``samples/cpp/calibration.cpp`` and the camera-calibration tutorial
  (``samples/cpp/tutorial_code/calib3d/camera_calibration``): ``image_width``,
  ``image_height``, ``camera_matrix`` (3x3), ``distortion_coefficients`` (5 or 8 values,
  1xN or Nx1: ``(k1, k2, p1, p2, k3[, k4, k5, k6])``), and for the tutorial
  ``fisheye_model`` (0 or 1). Older versions of the tutorial capitalise the keys
  (``Camera_Matrix``, ``image_Width``...): keys are matched without regard to case.
- ``omni_calibration.cpp`` of opencv_contrib (``cv::omnidir``, Mei's model):
  ``camera_matrix``, ``distortion_coefficients`` (``D``: 1x4, ``(k1, k2, p1, p2)``) and
  ``xi``; no image size. ``D`` is accepted as the name of the coefficients.

ROS's camera_info YAML files use the same names (matrices as ``{rows, cols, data}``,
with ``distortion_model``: ``plumb_bob`` and ``rational_polynomial`` are OpenCV's
perspective model, ``equidistant`` its fisheye model; others are refused, naming the
key, and so is a ROS file, one with ``camera_name``, ``rectification_matrix`` or
``projection_matrix``, without ``distortion_model``). A file with ``xi`` is a unified
(omnidirectional) camera, one with ``fisheye_model: 1`` (the tutorial's ``cv::fisheye``
calibrations) or ``distortion_model: equidistant`` a fisheye (Kannala-Brandt, 4
coefficients ``(k1, k2, k3, k4)``), otherwise a perspective one with OpenCV's 4, 5, 8, 12
or 14 coefficients (rational, thin-prism and tilt terms included). The pose of the
camera is not in these files.

Reading and writing go through ``cv2.FileStorage``: YAML 1.0 (``%YAML:1.0``, what
OpenCV up to 4.x writes), YAML 1.2 (what OpenCV 5 writes), XML and JSON; the format
follows the extension (``.yml``, ``.yaml``, ``.xml``, ``.json``).
"""

from __future__ import annotations

import logging
import math
from pathlib import Path
from typing import Any

import numpy as np

from hexapod.exceptions import ConfigFileError
from vision.cameras.fields import Calibration

log = logging.getLogger(__name__)

#: File extensions read and written with ``cv2.FileStorage``.
OPENCV_EXTENSIONS = (".yml", ".yaml", ".xml", ".json")
#: Accepted names of each field (first: the name written), matched without case.
KEYS = {
    "camera_matrix": ("camera_matrix", "K"),
    "distortion": ("distortion_coefficients", "D"),
    "xi": ("xi",),
    "width": ("image_width",),
    "height": ("image_height",),
    "fisheye": ("fisheye_model",),
    "model": ("distortion_model",),
}
#: ``distortion_model`` values (ROS's camera_info files) and the camera kind of each.
ROS_MODELS = {"plumb_bob": "perspective", "rational_polynomial": "perspective",
              "equidistant": "fisheye"}
#: Lengths of OpenCV's perspective coefficient vectors.
PERSPECTIVE_LENGTHS = (4, 5, 8, 12, 14)


def is_opencv_file(path: str | Path) -> bool:
    """True when the extension is one of :data:`OPENCV_EXTENSIONS`."""
    return Path(path).suffix.lower() in OPENCV_EXTENSIONS


def _check_extension(path: Path) -> None:
    if not is_opencv_file(path):
        raise ConfigFileError(
            str(path), f"unknown extension {path.suffix!r} for an OpenCV calibration file; "
                       f"expected one of {', '.join(OPENCV_EXTENSIONS)}")


def _open(path: Path) -> Any:
    import cv2  # here: a run without calibration files never imports OpenCV

    _check_extension(path)
    if not path.is_file():
        raise ConfigFileError(str(path), "file not found")
    if path.stat().st_size == 0:  # (OpenCV asserts on it: '(-215) buf in function open')
        raise ConfigFileError(str(path), "the file is empty")
    try:
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    except (cv2.error, SystemError) as exc:  # the Python binding wraps cv2.error
        cause = exc.__cause__ if exc.__cause__ is not None else exc
        detail = str(cause).strip().splitlines()[-1] if str(cause).strip() else repr(cause)
        raise ConfigFileError(str(path), f"not a valid OpenCV FileStorage file: {detail}"
                              ) from None
    if not fs.isOpened() or not fs.root().isMap():
        raise ConfigFileError(str(path), "not a valid OpenCV FileStorage file (no top-level "
                                         "map of keys)")
    return fs


def _find(fs: Any, field: str, path: str, required: bool = True) -> tuple[str, Any] | None:
    """The node of a field: ``(key as written, node)``, None when absent and optional."""
    names: tuple[str, ...] = fs.root().keys()  # a FileNode method, not a dict's
    keys = {k.lower(): k for k in names}
    found = [keys[a.lower()] for a in KEYS[field] if a.lower() in keys]
    if len(found) > 1:
        raise ConfigFileError(path, f"give one of {' or '.join(found)}, not both", key=found[0])
    if not found:
        if required:
            from hexapod.config import suggest

            wanted = " or ".join(KEYS[field])
            # cv2.calibrateCamera's Python names (cameraMatrix, distCoeffs) are close
            # to none by spelling: compared without the underscores too
            flat = {k.lower().replace("_", ""): k for k in names}
            close = suggest(KEYS[field][0].replace("_", ""), list(flat))
            hint = (f"; the file has {flat[close]!r}: rename it {KEYS[field][0]!r}"
                    if close else f"; the file's keys: {', '.join(names) or 'none'}")
            raise ConfigFileError(path, f"missing required key {wanted}{hint}",
                                  key=KEYS[field][0])
        return None
    return found[0], fs.getNode(found[0])


#: Keys only a ROS ``camera_info`` file has (an OpenCV calibration file has none): a file
#: with one of them is read as ROS's, whose ``distortion_model`` is then required.
ROS_ONLY_KEYS = ("camera_name", "rectification_matrix", "projection_matrix")


def _ros_keys(fs: Any) -> list[str]:
    """The keys of the file that only a ROS ``camera_info`` file has, as written."""
    names: tuple[str, ...] = fs.root().keys()
    return [k for k in names if k.lower() in ROS_ONLY_KEYS]


def _numbers(node: Any, path: str, key: str) -> np.ndarray:
    """A matrix (opencv-matrix map), a sequence of numbers or a number, as an array."""
    if node.isMap():
        import cv2

        try:
            mat = node.mat()
        except cv2.error:
            mat = None
        if mat is None:
            mat = _plain_matrix(node, path, key)
        arr = np.array(mat, dtype=float)
    elif node.isSeq():
        items = [node.at(i) for i in range(node.size())]
        if not all(n.isReal() or n.isInt() for n in items):
            raise ConfigFileError(path, "expected a sequence of numbers", key=key)
        arr = np.array([n.real() for n in items], dtype=float)
    elif node.isReal() or node.isInt():
        arr = np.array(node.real(), dtype=float)
    else:
        raise ConfigFileError(path, "expected numbers", key=key)
    if not np.all(np.isfinite(arr)):
        raise ConfigFileError(path, f"contains NaN or inf: {arr.tolist()}", key=key)
    return arr


def _plain_matrix(node: Any, path: str, key: str) -> np.ndarray:
    """A ``{rows, cols, data}`` map without ``dt`` (ROS's camera_info files), or an empty
    opencv-matrix (which ``FileNode.mat`` does not decode)."""
    rows, cols, data = node.getNode("rows"), node.getNode("cols"), node.getNode("data")
    if not (rows.isInt() and cols.isInt() and (data.isSeq() or data.empty())):
        raise ConfigFileError(path, "expected an opencv-matrix (rows, cols, dt, data)", key=key)
    shape = (int(rows.real()), int(cols.real()))
    items = [data.at(i) for i in range(data.size())] if data.isSeq() else []
    if len(items) != shape[0] * shape[1] or not all(n.isReal() or n.isInt() for n in items):
        raise ConfigFileError(path, f"expected {shape[0]}x{shape[1]} numbers in data", key=key)
    return np.array([n.real() for n in items], dtype=float).reshape(shape)


def _vector(arr: np.ndarray, path: str, key: str) -> np.ndarray:
    """A 1xN, Nx1 or flat array as a vector."""
    if arr.ndim <= 1 or (arr.ndim == 2 and 1 in arr.shape):
        return arr.reshape(-1)
    raise ConfigFileError(path, f"expected a 1xN or Nx1 matrix, got shape {arr.shape}",
                          key=key)


def _size(fs: Any, field: str, path: str) -> int | None:
    hit = _find(fs, field, path, required=False)
    if hit is None:
        return None
    key, node = hit
    v = _numbers(node, path, key)
    if v.size != 1 or v.reshape(-1)[0] != int(v.reshape(-1)[0]) or v.reshape(-1)[0] <= 0:
        raise ConfigFileError(path, f"expected a positive integer, got {v.tolist()}", key=key)
    return int(v.reshape(-1)[0])


def read_opencv_calibration(path: str | Path) -> Calibration:
    """Read the intrinsics of an OpenCV calibration file (see the module docstring).

    Raises:
        ConfigFileError: Unknown extension, missing or unreadable file, a missing key,
            a value of the wrong shape or type, an unsupported model (naming the file
            and the key).
    """
    p = Path(path)
    src = str(p)
    fs = _open(p)
    try:
        kind = "perspective"
        hit = _find(fs, "fisheye", src, required=False)
        if hit is not None and np.any(_numbers(hit[1], src, hit[0]) != 0):
            kind = "fisheye"
        hit = _find(fs, "model", src, required=False)
        ros = _ros_keys(fs)
        if hit is None and ros:
            raise ConfigFileError(src, f"a ROS camera_info file (it has {', '.join(ros)}) "
                                       "must give distortion_model (one of "
                                       f"{', '.join(ROS_MODELS)})", key="distortion_model")
        if hit is not None:
            name = hit[1].string() if hit[1].isString() else None
            if name not in ROS_MODELS:
                raise ConfigFileError(src, f"distortion model {name!r} is not supported; "
                                           f"expected one of {', '.join(ROS_MODELS)}",
                                      key=hit[0])
            kind = ROS_MODELS[name]
        key, node = _find(fs, "camera_matrix", src)  # type: ignore[misc]
        K = _numbers(node, src, key)
        if K.shape != (3, 3):
            raise ConfigFileError(src, f"expected a 3x3 matrix, got shape {K.shape}", key=key)
        if K[1, 0] != 0 or K[2, 0] != 0 or K[2, 1] != 0 or K[2, 2] != 1:
            raise ConfigFileError(src, "expected [[fx, s, cx], [0, fy, cy], [0, 0, 1]], got "
                                       f"{K.tolist()}", key=key)
        if K[0, 0] <= 0 or K[1, 1] <= 0:
            raise ConfigFileError(src, f"focal lengths must be positive, got fx={K[0, 0]}, "
                                       f"fy={K[1, 1]}", key=key)
        xi_hit = _find(fs, "xi", src, required=False)
        xi = None
        if xi_hit is not None:
            v = _numbers(xi_hit[1], src, xi_hit[0])
            if v.size != 1 or v.reshape(-1)[0] < 0:
                raise ConfigFileError(src, f"expected a number >= 0, got {v.tolist()}",
                                      key=xi_hit[0])
            xi = float(v.reshape(-1)[0])
        key, node = _find(fs, "distortion", src)  # type: ignore[misc]
        d = _vector(_numbers(node, src, key), src, key)
        if xi is not None:
            if kind == "fisheye":
                raise ConfigFileError(src, "xi (Mei's model) in a fisheye calibration",
                                      key=xi_hit[0])  # type: ignore[index]
            kind = "unified"
        dist = _coefficients(d, kind, src, key)
        width, height = _size(fs, "width", src), _size(fs, "height", src)
    finally:
        fs.release()
    log.debug("read %s: %s, K=%s, distortion=%s, xi=%s, size=%sx%s", src, kind, K.tolist(),
              dist.tolist(), xi, width, height)
    return Calibration(kind, K, dist, xi, width, height, src)


def _coefficients(d: np.ndarray, kind: str, src: str, key: str) -> np.ndarray:
    """The distortion vector of a model: 4 numbers (unified, fisheye) or OpenCV's
    perspective vector, cut after its last nonzero term at one of OpenCV's lengths
    (at least 5); empty: no distortion.

    Raises:
        ConfigFileError: A length the model does not have (naming the key).
    """
    lengths = PERSPECTIVE_LENGTHS if kind == "perspective" else (4,)
    if d.size not in lengths and d.size != 0:
        model = {"unified": "cv::omnidir (k1, k2, p1, p2)",
                 "fisheye": "cv::fisheye (k1, k2, k3, k4)"}.get(
            kind, "cv2.calibrateCamera (k1, k2, p1, p2[, k3[, k4, k5, k6[, s1..s4[, tx, "
                  "ty]]]])")
        raise ConfigFileError(src, f"expected {' or '.join(map(str, lengths))} "
                                   f"coefficients of {model}, got {d.size}", key=key)
    if kind != "perspective":
        out = np.zeros(4)
        out[: d.size] = d
        return out
    nonzero = np.flatnonzero(d)
    last = int(nonzero[-1]) + 1 if nonzero.size else 0
    n = min(k for k in PERSPECTIVE_LENGTHS if k >= max(last, 5))
    out = np.zeros(n)
    out[: min(n, d.size)] = d[:n]
    return out


def write_opencv_calibration(path: str | Path, K: np.ndarray, distortion: np.ndarray,
                             width: int, height: int, xi: float | None = None,
                             fisheye: bool = False) -> None:
    """Write intrinsics as OpenCV's calibration samples do, with ``cv2.FileStorage``.

    Keys: ``image_width``, ``image_height``, ``camera_matrix`` (3x3),
    ``distortion_coefficients`` (1xN), for Mei's model ``xi`` and for a ``cv::fisheye``
    calibration ``fisheye_model: 1`` (as the calibration tutorial). The format
    follows the extension (YAML 1.2 for ``.yml``/``.yaml`` with OpenCV 5).

    Raises:
        ConfigFileError: Unknown extension or the file cannot be written.
    """
    import cv2

    p = Path(path)
    _check_extension(p)
    try:
        fs = cv2.FileStorage(str(p), cv2.FILE_STORAGE_WRITE)
    except (cv2.error, SystemError) as exc:
        raise ConfigFileError(str(p), f"cannot be written: {exc.__cause__ or exc}") from None
    if not fs.isOpened():
        raise ConfigFileError(str(p), "cannot be written (cv2.FileStorage did not open it)")
    try:
        fs.write("image_width", int(width))
        fs.write("image_height", int(height))
        fs.write("camera_matrix", np.asarray(K, dtype=np.float64))
        fs.write("distortion_coefficients",
                 np.asarray(distortion, dtype=np.float64).reshape(1, -1))
        if xi is not None and not math.isnan(xi):
            fs.write("xi", float(xi))
        if fisheye:
            fs.write("fisheye_model", 1)
    finally:
        fs.release()
    log.debug("wrote %s", p)


def calibration_size(cal: Calibration, given: tuple[int, int] | None,
                     given_by: str, where: str = "") -> tuple[int, int]:
    """The image size of a calibration: the file's, or ``given`` (what gives it:
    ``given_by``, found ``where``) when the file has none (``omni_calibration.cpp`` does
    not write it).

    Raises:
        ConfigFileError: Neither gives it, or both give different sizes.
    """
    if cal.width is None or cal.height is None:
        if given is None:
            missing = "image_width" if cal.width is None else "image_height"
            raise ConfigFileError(cal.source, f"missing required key {missing} (the file "
                                              f"does not give the image size: give "
                                              f"{given_by}{where})", key=missing)
        return int(given[0]), int(given[1])
    if given is not None and (int(given[0]), int(given[1])) != (cal.width, cal.height):
        raise ConfigFileError(cal.source, f"the file says {cal.width}x{cal.height} px, "
                                          f"{given_by} {given[0]}x{given[1]} px",
                              key="image_width")
    return cal.width, cal.height
