"""Kalibr's camera chain files (``camchain.yaml``) as camera intrinsics.

Kalibr (``kalibr_calibrate_cameras``, ``kalibr_calibrate_imu_camera``) writes one block
per camera, ``cam0``, ``cam1``...::

    cam0:
      camera_model: pinhole          # pinhole, omni, ds, eucm
      intrinsics: [fu, fv, pu, pv]   # omni: [xi, fu, fv, pu, pv]; ds: [xi, alpha, fu, fv,
                                     # pu, pv]; eucm: [alpha, beta, fu, fv, pu, pv]
      distortion_model: radtan       # radtan, equidistant, none
      distortion_coeffs: [k1, k2, r1, r2]
      resolution: [width, height]
      T_cam_imu: [[...], ...]        # camera from IMU (camera-IMU calibration only)
      rostopic: /cam0/image_raw

What is read: ``camera_model``, ``intrinsics``, ``distortion_model``,
``distortion_coeffs`` and ``resolution``. The models: ``pinhole-radtan`` (OpenCV's
four coefficients ``k1, k2, p1, p2``), ``pinhole-equi`` (the fisheye, Kannala-Brandt),
``pinhole-none``, ``omni-radtan`` and ``omni-none`` (Mei's unified model), ``ds-none``
(double sphere) and ``eucm-none`` (extended unified); others (``fov``, ``omni-equi``,
a distortion on ``ds``/``eucm``) are refused, naming the key. What is not used:
``T_cam_imu`` is the pose of the camera with respect to an IMU, and ``T_cn_cnm1`` with
respect to the previous camera of the chain: neither is a pose in the robot's frame,
so the camera's pose (``camera_from_base``) must be given as for any calibration file;
they are listed in :attr:`Calibration.notes` (and logged). ``rostopic`` and
``cam_overlaps`` are ignored. A chain of several cameras gives its first one unless
another is named.

YAML is read with PyYAML (``cv2.FileStorage`` does not parse Kalibr's block lists).
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np

from hexapod.exceptions import ConfigFileError
from vision.cameras.fields import Calibration

log = logging.getLogger(__name__)

#: (camera_model, distortion_model) -> (camera kind, number of intrinsics).
MODELS = {
    ("pinhole", "radtan"): ("perspective", 4),
    ("pinhole", "none"): ("perspective", 4),
    ("pinhole", "equidistant"): ("fisheye", 4),
    ("omni", "radtan"): ("unified", 5),
    ("omni", "none"): ("unified", 5),
    ("ds", "none"): ("double_sphere", 6),
    ("eucm", "none"): ("eucm", 6),
}
#: Coefficients of each distortion model.
DISTORTION_SIZES = {"radtan": 4, "equidistant": 4, "none": 0}
#: Keys of a camera block this reader uses, and those it knows and does not use.
USED_KEYS = ("camera_model", "intrinsics", "distortion_model", "distortion_coeffs",
             "resolution")
POSE_KEYS = ("T_cam_imu", "T_cn_cnm1")


def load_yaml(path: str | Path) -> Any:
    """The parsed YAML of a file, or None when it is not plain YAML (OpenCV's
    ``%YAML:1.0`` files with ``!!opencv-matrix`` tags are not)."""
    import yaml  # here: a run without Kalibr files never imports PyYAML

    try:
        return yaml.safe_load(Path(path).read_text())
    except (yaml.YAMLError, UnicodeDecodeError, OSError):
        return None


def is_camchain(data: Any) -> bool:
    """Whether parsed YAML is a Kalibr camera chain (a map of blocks with
    ``camera_model``)."""
    return isinstance(data, dict) and any(
        isinstance(v, dict) and "camera_model" in v for v in data.values())


def _numbers(block: dict[str, Any], key: str, n: int | None, path: str, pre: str
             ) -> np.ndarray:
    if key not in block:
        raise ConfigFileError(path, "missing required key", key=pre + key)
    try:
        arr = np.array(block[key], dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ConfigFileError(path, f"expected a list of numbers, got {block[key]!r}",
                              key=pre + key) from None
    if n is not None and arr.size != n:
        raise ConfigFileError(path, f"expected {n} numbers, got {arr.size}", key=pre + key)
    if not np.all(np.isfinite(arr)):
        raise ConfigFileError(path, f"contains NaN or inf: {arr.tolist()}", key=pre + key)
    return arr


def read_kalibr_camchain(path: str | Path, data: Any = None, camera: str | None = None
                         ) -> Calibration:
    """The intrinsics of one camera of a Kalibr ``camchain.yaml`` (module docstring).

    Args:
        path: The file.
        data: Its parsed YAML (read from ``path`` when None).
        camera: The block to read (``"cam1"``...); None: the first one.

    Raises:
        ConfigFileError: Not a camera chain, unknown or unsupported model, a missing
            key, a value of the wrong size (naming the file and the key, e.g.
            ``cam0.intrinsics``).
    """
    src = str(path)
    if data is None:
        if not Path(path).is_file():
            raise ConfigFileError(src, "file not found")
        data = load_yaml(path)
    if not is_camchain(data):
        raise ConfigFileError(src, "not a Kalibr camera chain (no block with camera_model)")
    names = [k for k, v in data.items() if isinstance(v, dict) and "camera_model" in v]
    name = names[0] if camera is None else camera
    if name not in names:
        raise ConfigFileError(src, f"no camera {name!r}; the chain has {', '.join(names)}",
                              key=name)
    block = data[name]
    pre = f"{name}."
    cam_model = block.get("camera_model")
    dist_model = block.get("distortion_model", "none")
    if (cam_model, dist_model) not in MODELS:
        known = ", ".join(f"{c}-{d}" for c, d in MODELS)
        bad = "camera_model" if cam_model not in {c for c, _ in MODELS} else "distortion_model"
        raise ConfigFileError(src, f"Kalibr model {cam_model}-{dist_model} is not supported; "
                                   f"supported: {known}", key=pre + bad)
    kind, n = MODELS[(cam_model, dist_model)]
    intr = _numbers(block, "intrinsics", n, src, pre)
    fu, fv, pu, pv = intr[-4:]
    if fu <= 0 or fv <= 0:
        raise ConfigFileError(src, f"focal lengths must be positive, got fu={fu}, fv={fv}",
                              key=pre + "intrinsics")
    K = np.array([[fu, 0.0, pu], [0.0, fv, pv], [0.0, 0.0, 1.0]])
    nd = DISTORTION_SIZES[dist_model]
    coeffs = (_numbers(block, "distortion_coeffs", nd, src, pre) if nd
              else np.zeros(0))
    xi = None
    if kind == "unified":
        xi = float(intr[0])
        distortion = coeffs if nd else np.zeros(4)
    elif kind in ("double_sphere", "eucm"):
        distortion = intr[:2].copy()
    elif kind == "perspective":
        distortion = np.concatenate([coeffs, [0.0]]) if nd else np.zeros(5)
    else:
        distortion = coeffs
    size = _numbers(block, "resolution", 2, src, pre)
    if np.any(size <= 0) or np.any(size != np.round(size)):
        raise ConfigFileError(src, f"expected [width, height] in pixels, got {size.tolist()}",
                              key=pre + "resolution")
    notes = []
    for key in POSE_KEYS:
        if key in block:
            notes.append(f"{name}.{key} (the pose of the camera w.r.t. "
                         f"{'the IMU' if key == 'T_cam_imu' else 'the previous camera'}) is "
                         "not a pose in the robot's frame: not used (give camera_from_base)")
    if len(names) > 1:
        notes.append(f"the chain has cameras {', '.join(names)}: read {name}")
    for note in notes:  # said by default: the README promises it is reported
        log.warning("%s: %s", src, note)
    log.debug("read %s %s: %s-%s (%s), K=%s, distortion=%s, xi=%s, size=%s", src, name,
              cam_model, dist_model, kind, K.tolist(), distortion.tolist(), xi,
              size.tolist())
    return Calibration(kind, K, np.asarray(distortion, float), xi, int(size[0]),
                       int(size[1]), src, tuple(notes))


def write_kalibr_camchain(path: str | Path, kind: str, K: np.ndarray,
                          distortion: np.ndarray, width: int, height: int,
                          xi: float | None = None) -> None:
    """Write one camera as Kalibr's ``cam0`` block (the inverse of
    :func:`read_kalibr_camchain`; no ``T_cam_imu``).

    Raises:
        ConfigFileError: A model Kalibr does not have (OpenCV's full model, a skew,
            a radial-tangential ``k3``), naming the field.
    """
    K = np.asarray(K, float)
    d = np.asarray(distortion, float)
    src = str(path)
    if K[0, 1] != 0:
        raise ConfigFileError(src, f"Kalibr's cameras have no skew, got {K[0, 1]}",
                              key="cam0.intrinsics")
    f = [float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2])]
    block: dict[str, Any] = {}
    if kind in ("perspective", "unified"):
        if np.any(d[4:]):
            raise ConfigFileError(src, "Kalibr's radtan has k1, k2, r1, r2 only, got "
                                       f"{d.tolist()}", key="cam0.distortion_coeffs")
        block["camera_model"] = "pinhole" if kind == "perspective" else "omni"
        block["intrinsics"] = f if kind == "perspective" else [float(xi or 0.0), *f]
        block["distortion_model"] = "radtan" if np.any(d) else "none"
        block["distortion_coeffs"] = [float(c) for c in d[:4]] if np.any(d) else []
    elif kind == "fisheye":
        block.update(camera_model="pinhole", intrinsics=f, distortion_model="equidistant",
                     distortion_coeffs=[float(c) for c in d])
    elif kind in ("double_sphere", "eucm"):
        block.update(camera_model="ds" if kind == "double_sphere" else "eucm",
                     intrinsics=[float(d[0]), float(d[1]), *f], distortion_model="none",
                     distortion_coeffs=[])
    else:
        raise ConfigFileError(src, f"no Kalibr model for a {kind} camera", key="cam0")
    block["resolution"] = [int(width), int(height)]
    import yaml

    Path(path).write_text(yaml.safe_dump({"cam0": block}, sort_keys=False))
    log.debug("wrote %s", path)
