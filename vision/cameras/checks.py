"""Validation helpers shared by the camera models (internal to :mod:`vision`).

Each check returns the validated value (read-only arrays, plain numbers) or raises
:class:`vision.exceptions.CameraError` naming the field, the problem and the file the
camera was read from.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from hexapod.kinematics import Transform
from hexapod.se3 import norms
from vision.exceptions import CameraError

#: Tolerance on the orthonormality of a rotation matrix.
_ROT_TOL = 1e-6


def check_K(K: Any, source: str | None) -> np.ndarray:
    """Intrinsics ``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]`` [px] as a read-only (3, 3) array."""
    try:
        arr = np.array(K, dtype=float)
    except (TypeError, ValueError):
        raise CameraError("K", "expected a 3x3 array of numbers", source) from None
    if arr.shape != (3, 3):
        raise CameraError("K", f"expected shape (3, 3), got {arr.shape}", source)
    if not np.all(np.isfinite(arr)):
        raise CameraError("K", "contains NaN or inf", source)
    if arr[1, 0] != 0 or arr[2, 0] != 0 or arr[2, 1] != 0 or arr[2, 2] != 1:
        raise CameraError(
            "K", f"expected [[fx, s, cx], [0, fy, cy], [0, 0, 1]], got {arr.tolist()}", source
        )
    if arr[0, 0] <= 0 or arr[1, 1] <= 0:
        raise CameraError(
            "K", f"focal lengths must be positive, got fx={arr[0, 0]}, fy={arr[1, 1]}", source
        )
    arr.flags.writeable = False
    return arr


def check_size(name: str, value: Any, source: str | None) -> int:
    """An image size [px]: a positive integer (an integral float is accepted)."""
    if isinstance(value, bool) or not isinstance(value, int | np.integer | float):
        raise CameraError(name, f"expected a positive integer, got {value!r}", source)
    if isinstance(value, float) and (not math.isfinite(value) or value != int(value)):
        raise CameraError(name, f"expected a positive integer, got {value!r}", source)
    if int(value) <= 0:
        raise CameraError(name, f"must be positive, got {value}", source)
    return int(value)


def check_principal_point(K: np.ndarray, width: int, height: int, source: str | None
                          ) -> None:
    """Refuse a principal point ``(cx, cy)`` outside the image ``[-0.5, width - 0.5] x
    [-0.5, height - 0.5]`` px (pixel centres are integers): a size swapped, or an
    intrinsic in another unit; every camera file and constructor meets it."""
    for value, size, axis, name in ((K[0, 2], width, "cx", "width"),
                                    (K[1, 2], height, "cy", "height")):
        if not -0.5 <= value <= size - 0.5:
            raise CameraError("K", f"the principal point's {axis} = {value:g} px lies outside "
                              f"the image, [-0.5, {size - 0.5:g}] px for {name} {size} (a "
                              "size swapped, or another unit?)", source)


def check_xi(xi: Any, source: str | None) -> float:
    """The mirror parameter of the unified model: finite and >= 0."""
    try:
        x = float(xi)
    except (TypeError, ValueError):
        raise CameraError("xi", f"expected a number, got {xi!r}", source) from None
    if not math.isfinite(x) or x < 0:
        raise CameraError("xi", f"must be finite and >= 0, got {x}", source)
    return x


def check_pose(pose: Any, source: str | None) -> Transform:
    """``camera_from_base``: a :class:`hexapod.Transform` with a proper rotation."""
    if not isinstance(pose, Transform):
        raise CameraError(
            "camera_from_base", f"expected a hexapod.Transform, got {type(pose).__name__}", source
        )
    R = np.array(pose.rotation, dtype=float)
    t = np.array(pose.translation, dtype=float)
    if R.shape != (3, 3) or t.shape != (3,):
        raise CameraError(
            "camera_from_base",
            f"expected rotation (3, 3) and translation (3,), got {R.shape} and {t.shape}",
            source,
        )
    if not (np.all(np.isfinite(R)) and np.all(np.isfinite(t))):
        raise CameraError("camera_from_base", "contains NaN or inf", source)
    err = float(np.abs(R.T @ R - np.eye(3)).max())
    if err > _ROT_TOL or np.linalg.det(R) <= 0:
        raise CameraError(
            "camera_from_base",
            f"rotation is not a proper rotation matrix (|R^T R - I| = {err:.2e}, "
            f"det = {np.linalg.det(R):.6f})",
            source,
        )
    R.flags.writeable = False
    t.flags.writeable = False
    return Transform(R, t)


def as_points(points: Any, name: str = "points") -> np.ndarray:
    """Points (..., 3) as a float array."""
    X = np.asarray(points, dtype=float)
    if X.shape[-1:] != (3,):
        raise CameraError(name, f"expected shape (..., 3), got {X.shape}")
    return X


def as_pixels(pixels: Any, name: str = "pixels") -> np.ndarray:
    """Pixels (..., 2) as a float array."""
    p = np.asarray(pixels, dtype=float)
    if p.shape[-1:] != (2,):
        raise CameraError(name, f"expected shape (..., 2), got {p.shape}")
    return p


def unit(x: np.ndarray) -> np.ndarray:
    """Vectors (..., n) scaled to unit norm (NaN for zero vectors)."""
    x = np.asarray(x)
    with np.errstate(invalid="ignore", divide="ignore"):
        if x.dtype == np.float64:  # np.linalg.norm's own operations, without its checks
            return x / norms(x, keepdims=True)  # type: ignore[no-any-return]
        return x / np.linalg.norm(x, axis=-1, keepdims=True)  # type: ignore[no-any-return]
