"""Camera models: perspective (pinhole) and unified central (Geyer-Daniilidis / Mei).

Conventions (``docs/math.md`` section 5):

- Camera frame: x right, y down, z forward (perspective) or along the mirror axis
  (unified). For the unified model the camera frame is the mirror (sphere) frame.
- Pixel coordinates follow OpenCV: ``(u, v)`` with ``u`` along the image columns
  and ``v`` along the rows; the centre of the pixel in column ``i`` and row ``j``
  is at ``(i, j)``, so the image covers ``[-0.5, width - 0.5] x [-0.5, height - 0.5]``.
- ``K = [[fx, s, cx], [0, fy, cy], [0, 0, 1]]`` maps the normalised point ``m`` to
  the pixel ``p = K m``.
- Each camera has a fixed pose with respect to the robot base,
  ``camera_from_base``: ``p_camera = R p_base + t``.

The perspective camera is the unified one with ``xi = 0``; ``UnifiedCamera`` with
``xi = 0`` gives bit-identical projections and lifts.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import tomli_w

from hexapod.config import check_keys, get_matrix, get_number, load_toml, suggest
from hexapod.exceptions import ConfigFileError
from hexapod.geometry import HexapodGeometry, deltalab
from hexapod.kinematics import Transform
from hexapod.se3 import exp_so3, log_so3, look_at
from vision.exceptions import CameraError

#: Pixel size assumed for the front camera preset [m] (a 1/3" 1024x768-class CCD,
#: e.g. Sony ICX204: 4.65 um square pixels).
FRONT_PIXEL_SIZE = 4.65e-6
#: Focal length of the front camera lens [m] (seed 002).
FRONT_FOCAL_LENGTH = 4.8e-3

#: Tolerance on the orthonormality of a rotation matrix.
_ROT_TOL = 1e-6


# --------------------------------------------------------------------- validation
def _validate_K(K: Any, source: str | None) -> np.ndarray:
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


def _validate_size(name: str, value: Any, source: str | None) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer | float):
        raise CameraError(name, f"expected a positive integer, got {value!r}", source)
    if isinstance(value, float) and (not math.isfinite(value) or value != int(value)):
        raise CameraError(name, f"expected a positive integer, got {value!r}", source)
    if int(value) <= 0:
        raise CameraError(name, f"must be positive, got {value}", source)
    return int(value)


def _validate_xi(xi: Any, source: str | None) -> float:
    try:
        x = float(xi)
    except (TypeError, ValueError):
        raise CameraError("xi", f"expected a number, got {xi!r}", source) from None
    if not math.isfinite(x) or x < 0:
        raise CameraError("xi", f"must be finite and >= 0, got {x}", source)
    return x


def _validate_pose(pose: Any, source: str | None) -> Transform:
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


def _as_points(points: Any, name: str = "points") -> np.ndarray:
    X = np.asarray(points, dtype=float)
    if X.shape[-1:] != (3,):
        raise CameraError(name, f"expected shape (..., 3), got {X.shape}")
    return X


def _as_pixels(pixels: Any) -> np.ndarray:
    p = np.asarray(pixels, dtype=float)
    if p.shape[-1:] != (2,):
        raise CameraError("pixels", f"expected shape (..., 2), got {p.shape}")
    return p


def _unit(x: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore", divide="ignore"):
        return x / np.linalg.norm(x, axis=-1, keepdims=True)


# --------------------------------------------------------------------- cameras
class Camera(ABC):
    """Common base of the camera models.

    Attributes:
        kind: ``"perspective"`` or ``"unified"``.
        K: (3, 3) intrinsics [px] (read-only array).
        width: Image width [px].
        height: Image height [px].
        xi: Mirror parameter of the unified model (0 for the perspective camera).
        camera_from_base: Pose of the camera w.r.t. the robot base,
            ``p_camera = R p_base + t``.
        name: A label.
    """

    kind: ClassVar[str]
    K: np.ndarray
    width: int
    height: int
    xi: float
    camera_from_base: Transform
    name: str
    source: str | None

    # ------------------------------------------------------------- derived
    @property
    def K_inv(self) -> np.ndarray:
        """Inverse intrinsics."""
        return np.linalg.inv(self.K)

    @property
    def fx(self) -> float:
        """Horizontal focal length [px]."""
        return float(self.K[0, 0])

    @property
    def fy(self) -> float:
        """Vertical focal length [px]."""
        return float(self.K[1, 1])

    @property
    def cx(self) -> float:
        """Principal point, column [px]."""
        return float(self.K[0, 2])

    @property
    def cy(self) -> float:
        """Principal point, row [px]."""
        return float(self.K[1, 2])

    @property
    def base_from_camera(self) -> Transform:
        """Pose of the camera in the base frame (``p_base = R p_camera + t``)."""
        return self.camera_from_base.inverse()

    @property
    def centre_in_base(self) -> np.ndarray:
        """Projection centre in the base frame [m]."""
        return self.base_from_camera.translation

    def in_image(self, pixels: np.ndarray) -> np.ndarray:
        """True where pixels (..., 2) are inside ``[-0.5, w - 0.5] x [-0.5, h - 0.5]``."""
        p = _as_pixels(pixels)
        with np.errstate(invalid="ignore"):
            return (
                (p[..., 0] >= -0.5)
                & (p[..., 0] <= self.width - 0.5)
                & (p[..., 1] >= -0.5)
                & (p[..., 1] <= self.height - 0.5)
            )

    # ------------------------------------------------------------- model
    @abstractmethod
    def _normalised(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Normalised coordinates (..., 2) of camera points and the validity mask."""

    @abstractmethod
    def _lift_normalised(self, m: np.ndarray) -> np.ndarray:
        """Unit vectors (..., 3) from normalised coordinates (..., 2)."""

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Project points given in the camera frame.

        Args:
            points: (..., 3) points in the camera frame [m].

        Returns:
            ``pixels`` (..., 2) and ``visible`` (...) bool: False where the point is
            behind the camera / not imaged by the model (pixels NaN there) or
            projects outside the image (pixels still given).
        """
        X = _as_points(points)
        m, valid = self._normalised(X)
        K = self.K
        u = K[0, 0] * m[..., 0] + K[0, 1] * m[..., 1] + K[0, 2]
        v = K[1, 1] * m[..., 1] + K[1, 2]
        pix = np.stack([u, v], axis=-1)
        pix = np.where(valid[..., None], pix, np.nan)
        return pix, valid & self.in_image(pix)

    def project_base(self, points_base: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Like :meth:`project` for points (..., 3) given in the robot base frame."""
        return self.project(self.camera_from_base.apply(_as_points(points_base)))

    def pixels_to_normalised(self, pixels: np.ndarray) -> np.ndarray:
        """Normalised image coordinates ``m = K^-1 p`` (..., 2) of pixels (..., 2)."""
        p = _as_pixels(pixels)
        K = self.K
        y = (p[..., 1] - K[1, 2]) / K[1, 1]
        x = (p[..., 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
        return np.stack([x, y], axis=-1)

    def lift(self, pixels: np.ndarray) -> np.ndarray:
        """Back-project pixels (..., 2) to unit vectors (..., 3) in the camera frame.

        Perspective: the normalised ray ``K^-1 p / |K^-1 p|``. Unified: the point of
        the unit sphere (``docs/math.md`` section 5). NaN where the pixel has no
        pre-image (outside the mirror's field of view, ``xi > 1`` only).
        """
        return self._lift_normalised(self.pixels_to_normalised(pixels))

    # ------------------------------------------------------------- copy / io
    def _fields(self) -> dict[str, Any]:
        return {
            "K": self.K,
            "width": self.width,
            "height": self.height,
            "camera_from_base": self.camera_from_base,
            "name": self.name,
        }

    def replace(self, **changes: Any) -> Camera:
        """Return a copy with some fields changed (validated again).

        Fields: ``K``, ``width``, ``height``, ``camera_from_base``, ``name`` and, for
        the unified camera, ``xi``.
        """
        kwargs = self._fields()
        for key in changes:
            if key not in kwargs:
                hint = suggest(key, kwargs)
                raise CameraError(
                    key,
                    f"not a field of {type(self).__name__}; fields: {', '.join(kwargs)}"
                    + (f" (did you mean '{hint}'?)" if hint else ""),
                )
        kwargs.update(changes)
        return type(self)(**kwargs)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Camera):
            return NotImplemented
        return (
            type(self) is type(other)
            and np.array_equal(self.K, other.K)
            and self.width == other.width
            and self.height == other.height
            and self.xi == other.xi
            and np.array_equal(self.camera_from_base.rotation, other.camera_from_base.rotation)
            and np.array_equal(
                self.camera_from_base.translation, other.camera_from_base.translation
            )
        )

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        xi = f", xi={self.xi}" if self.kind == "unified" else ""
        return (
            f"{type(self).__name__}(name={self.name!r}, {self.width}x{self.height}, "
            f"fx={self.fx:.3f}, fy={self.fy:.3f}, cx={self.cx:.3f}, cy={self.cy:.3f}{xi})"
        )

    _KEYS = ("kind", "name", "width_px", "height_px", "fx_px", "fy_px", "cx_px", "cy_px",
             "skew_px", "xi", "camera_from_base")
    _POSE_KEYS = ("translation_mm", "rotation_vector_deg", "rotation_matrix")

    def to_dict(self) -> dict[str, Any]:
        """The file representation (pixels, millimetres, degrees)."""
        d: dict[str, Any] = {
            "kind": self.kind,
            "name": self.name,
            "width_px": self.width,
            "height_px": self.height,
            "fx_px": float(self.K[0, 0]),
            "fy_px": float(self.K[1, 1]),
            "cx_px": float(self.K[0, 2]),
            "cy_px": float(self.K[1, 2]),
            "skew_px": float(self.K[0, 1]),
        }
        if self.kind == "unified":
            d["xi"] = float(self.xi)
        rv = np.rad2deg(log_so3(self.camera_from_base.rotation))
        d["camera_from_base"] = {
            "translation_mm": ((self.camera_from_base.translation * 1e3).round(9) + 0.0).tolist(),
            "rotation_vector_deg": (rv.round(12) + 0.0).tolist(),
        }
        return d

    def to_toml(self, path: str | Path) -> None:
        """Save the camera to a TOML file.

        Format: ``kind`` (``"perspective"``/``"unified"``), ``name``, ``width_px``,
        ``height_px``, ``fx_px``, ``fy_px``, ``cx_px``, ``cy_px``, ``skew_px``, ``xi``
        (unified only) and a table ``[camera_from_base]`` with ``translation_mm`` and
        ``rotation_vector_deg`` (axis times angle, degrees) such that
        ``p_camera = R p_base + t``.
        """
        Path(path).write_text(tomli_w.dumps(self.to_dict()))

    @classmethod
    def from_dict(cls, table: dict[str, Any], path: str = "<dict>") -> Camera:
        """Build a camera from a table in the file format (see :meth:`to_toml`).

        ``[camera_from_base]`` may give the rotation either as ``rotation_vector_deg``
        or as a 3x3 ``rotation_matrix`` (not both); it defaults to the identity.
        Called on :class:`Camera` the ``kind`` key chooses the model; called on a
        subclass, ``kind`` must match it (or be absent).
        """
        check_keys(table, cls._KEYS, path,
                   required=("width_px", "height_px", "fx_px", "fy_px", "cx_px", "cy_px"))
        kinds = {"perspective": PerspectiveCamera, "unified": UnifiedCamera}
        kind = table.get("kind", getattr(cls, "kind", None))
        if kind is None:
            raise ConfigFileError(path, "missing required key", key="kind")
        if kind not in kinds:
            hint = suggest(str(kind), kinds)
            raise ConfigFileError(path, f"unknown camera kind {kind!r}; expected one of "
                                  f"{', '.join(kinds)}", key="kind", suggestion=hint)
        target = kinds[kind]
        if cls is not Camera and target is not cls:
            raise ConfigFileError(path, f"kind {kind!r} cannot be loaded as {cls.__name__}",
                                  key="kind")
        for key in ("width_px", "height_px"):
            v = table[key]
            if isinstance(v, bool) or not isinstance(v, int) or v <= 0:
                raise ConfigFileError(path, f"expected a positive integer, got {v!r}", key=key)
        f = {k: get_number(table, k, path) for k in ("fx_px", "fy_px", "cx_px", "cy_px")}
        skew = get_number(table, "skew_px", path) if "skew_px" in table else 0.0
        for k in ("fx_px", "fy_px"):
            if f[k] <= 0:
                raise ConfigFileError(path, f"focal length must be positive, got {f[k]}", key=k)
        K = np.array([[f["fx_px"], skew, f["cx_px"]], [0.0, f["fy_px"], f["cy_px"]],
                      [0.0, 0.0, 1.0]])
        if target is UnifiedCamera:
            if "xi" not in table:
                raise ConfigFileError(path, "missing required key (unified camera)", key="xi")
            xi = get_number(table, "xi", path)
            if xi < 0:
                raise ConfigFileError(path, f"must be >= 0, got {xi}", key="xi")
        elif "xi" in table:
            xi = get_number(table, "xi", path)
            if xi != 0:
                raise ConfigFileError(
                    path, f"a perspective camera has xi = 0, got {xi} (use kind = 'unified')",
                    key="xi")
        pose_table = table.get("camera_from_base", {})
        if not isinstance(pose_table, dict):
            raise ConfigFileError(path, "expected a table", key="camera_from_base")
        pre = "camera_from_base."
        check_keys(pose_table, cls._POSE_KEYS, path, prefix=pre)
        t = (get_matrix(pose_table, "translation_mm", (3,), path, pre) * 1e-3
             if "translation_mm" in pose_table else np.zeros(3))
        if "rotation_vector_deg" in pose_table and "rotation_matrix" in pose_table:
            raise ConfigFileError(path, "give rotation_vector_deg or rotation_matrix, not both",
                                  key="camera_from_base")
        if "rotation_matrix" in pose_table:
            R = get_matrix(pose_table, "rotation_matrix", (3, 3), path, pre)
        elif "rotation_vector_deg" in pose_table:
            R = exp_so3(np.deg2rad(get_matrix(pose_table, "rotation_vector_deg", (3,), path, pre)))
        else:
            R = np.eye(3)
        name = table.get("name", Path(path).stem)
        if not isinstance(name, str):
            raise ConfigFileError(path, f"expected a string, got {name!r}", key="name")
        pose = Transform(R, t)
        if target is UnifiedCamera:
            return UnifiedCamera(K, xi, table["width_px"], table["height_px"], pose, name=name,
                                 source=path)
        return PerspectiveCamera(K, table["width_px"], table["height_px"], pose, name=name,
                                 source=path)

    @classmethod
    def from_toml(cls, path: str | Path) -> Camera:
        """Load a camera from a TOML file (see :meth:`to_toml` for the format).

        Raises:
            ConfigFileError: Missing file, bad TOML, missing or misspelt key, bad value.
            CameraError: The camera is invalid (e.g. rotation not orthonormal).
        """
        return cls.from_dict(load_toml(path), str(path))


class PerspectiveCamera(Camera):
    """Pinhole camera ``p ~ K X``.

    Args:
        K: (3, 3) intrinsics [px].
        width: Image width [px].
        height: Image height [px].
        camera_from_base: Pose w.r.t. the robot base (identity by default).
        name: A label.
    """

    kind: ClassVar[str] = "perspective"

    def __init__(
        self,
        K: np.ndarray,
        width: int,
        height: int,
        camera_from_base: Transform | None = None,
        name: str = "perspective",
        source: str | None = None,
    ) -> None:
        self.source = source
        self.K = _validate_K(K, source)
        self.width = _validate_size("width", width, source)
        self.height = _validate_size("height", height, source)
        self.xi = 0.0
        self.camera_from_base = _validate_pose(
            Transform.identity() if camera_from_base is None else camera_from_base, source
        )
        self.name = str(name)
        w, h = float(self.width), float(self.height)
        N = np.array([[1.0 / w, 0.0, -0.5], [0.0, 1.0 / w, -0.5 * h / w], [0.0, 0.0, 1.0]])
        lm = N @ self.K
        lm.flags.writeable = False
        self.line_matrix = lm
        self._line_matrix_inv_T = np.linalg.inv(lm).T

    @property
    def normalisation(self) -> np.ndarray:
        """``N``: pixels -> normalised pixel coordinates ``((u - w/2)/w, (v - h/2)/w)``."""
        return self.line_matrix @ np.linalg.inv(self.K)

    def _normalised(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        z = X[..., 2]
        valid = z > 0
        with np.errstate(invalid="ignore", divide="ignore"):
            m = X[..., :2] / z[..., None]
        return m, valid

    def _lift_normalised(self, m: np.ndarray) -> np.ndarray:
        mh = np.concatenate([m, np.ones((*m.shape[:-1], 1))], axis=-1)
        return _unit(mh)

    def normal_to_line(self, n: np.ndarray) -> np.ndarray:
        """Interpretation-plane normals (..., 3) -> unit lines (..., 3) in normalised
        pixel coordinates: ``l = Kt^-T n / |Kt^-T n|`` with ``Kt = line_matrix``
        (positive scale, so the sign follows ``n``)."""
        n = _as_points(n, "n")
        return _unit(n @ self._line_matrix_inv_T.T)

    def line_to_normal(self, l: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`normal_to_line`: ``n = Kt^T l / |Kt^T l|``."""
        l = _as_points(l, "l")
        return _unit(l @ self.line_matrix)

    def normal_to_pixel_line(self, n: np.ndarray) -> np.ndarray:
        """Unit line (..., 3) in raw pixel coordinates (``l^T [u, v, 1] = 0``),
        ``l = K^-T n / |K^-T n|``."""
        n = _as_points(n, "n")
        return _unit(n @ np.linalg.inv(self.K))

    def pixel_line_to_normal(self, l: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`normal_to_pixel_line`: ``n = K^T l / |K^T l|``."""
        l = _as_points(l, "l")
        return _unit(l @ self.K)

    def pixels_to_line_coordinates(self, pixels: np.ndarray) -> np.ndarray:
        """Pixels (..., 2) -> normalised pixel coordinates (..., 2) used by the lines."""
        p = _as_pixels(pixels)
        return np.stack([(p[..., 0] - 0.5 * self.width) / self.width,
                         (p[..., 1] - 0.5 * self.height) / self.width], axis=-1)


class UnifiedCamera(Camera):
    """Unified central camera (Geyer-Daniilidis / Mei), ``docs/math.md`` section 5.

    ``X_s = X / |X|``, ``m = (X_s,x, X_s,y) / (X_s,z + xi)``, ``p = K m``.
    A point is imaged when ``X_s,z > -min(xi, 1/xi)`` (``X_s,z > 0`` for ``xi = 0``):
    for ``xi <= 1`` the half-line from the centre ``(0, 0, -xi)`` through the sphere
    point leaves forward; for ``xi > 1`` the point is beyond the tangent circle.

    Args:
        K: (3, 3) intrinsics [px] (generalised focal lengths).
        xi: Mirror parameter (0: pinhole, 1: parabolic mirror + orthographic lens).
        width: Image width [px].
        height: Image height [px].
        camera_from_base: Pose of the mirror frame w.r.t. the robot base.
        name: A label.
    """

    kind: ClassVar[str] = "unified"

    def __init__(
        self,
        K: np.ndarray,
        xi: float,
        width: int,
        height: int,
        camera_from_base: Transform | None = None,
        name: str = "unified",
        source: str | None = None,
    ) -> None:
        self.source = source
        self.K = _validate_K(K, source)
        self.xi = _validate_xi(xi, source)
        self.width = _validate_size("width", width, source)
        self.height = _validate_size("height", height, source)
        self.camera_from_base = _validate_pose(
            Transform.identity() if camera_from_base is None else camera_from_base, source
        )
        self.name = str(name)

    def _fields(self) -> dict[str, Any]:
        d = super()._fields()
        d["xi"] = self.xi
        return d

    @property
    def _cos_limit(self) -> float:
        xi = self.xi
        return 0.0 if xi == 0 else min(xi, 1.0 / xi)

    def _normalised(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        # m = X_xy / (X_z + xi |X|): the same as X_s,xy / (X_s,z + xi), and exactly
        # X_xy / X_z (the pinhole) when xi = 0.
        if self.xi == 0:
            z = X[..., 2]
            valid = z > 0
        else:
            rho = np.linalg.norm(X, axis=-1)
            z = X[..., 2] + self.xi * rho
            with np.errstate(invalid="ignore"):
                valid = (X[..., 2] > -self._cos_limit * rho) & (rho > 0)
        with np.errstate(invalid="ignore", divide="ignore"):
            m = X[..., :2] / z[..., None]
        return m, valid

    def _lift_normalised(self, m: np.ndarray) -> np.ndarray:
        if self.xi == 0:
            mh = np.concatenate([m, np.ones((*m.shape[:-1], 1))], axis=-1)
            return _unit(mh)
        xi = self.xi
        r2 = np.sum(m * m, axis=-1)
        with np.errstate(invalid="ignore"):
            lam = (xi + np.sqrt(1.0 + (1.0 - xi * xi) * r2)) / (r2 + 1.0)
        return np.stack([lam * m[..., 0], lam * m[..., 1], lam - xi], axis=-1)

    def normal_to_conic(self, n: np.ndarray) -> np.ndarray:
        """Image conic of the great circle ``n^T X_s = 0`` (a 3D line's projection).

        Args:
            n: (..., 3) interpretation-plane normals.

        Returns:
            (..., 3, 3) symmetric conics ``C`` in pixels, ``[u, v, 1] C [u, v, 1]^T = 0``,
            ``C ∝ K^-T Ω K^-1`` (``docs/math.md`` section 5), scaled to unit Frobenius norm by
            a positive factor. ``C`` is even in ``n`` (both orientations of a plane give
            the same conic) and is the image of the whole great circle, of which a
            leg edge is an arc. For ``xi = 0`` it is the double line ``l l^T``.
        """
        W = self._omega(_as_points(n, "n"))
        Ki = np.linalg.inv(self.K)
        C = Ki.T @ W @ Ki
        return C / np.linalg.norm(C, axis=(-2, -1), keepdims=True)

    def _omega(self, n: np.ndarray) -> np.ndarray:
        k = 1.0 - self.xi**2
        x2 = self.xi**2
        nx, ny, nz = n[..., 0], n[..., 1], n[..., 2]
        return np.stack(
            [
                np.stack([k * nx * nx - x2 * nz * nz, k * nx * ny, nx * nz], axis=-1),
                np.stack([k * nx * ny, k * ny * ny - x2 * nz * nz, ny * nz], axis=-1),
                np.stack([nx * nz, ny * nz, nz * nz], axis=-1),
            ],
            axis=-2,
        )

    def normal_to_normalised_conic(self, n: np.ndarray) -> np.ndarray:
        """The conic Ω (..., 3, 3) in normalised coordinates ``m`` (unit Frobenius norm)."""
        W = self._omega(_as_points(n, "n"))
        return W / np.linalg.norm(W, axis=(-2, -1), keepdims=True)


# --------------------------------------------------------------------- presets
def _intrinsics(f: float, width: int, height: int) -> np.ndarray:
    return np.array([[f, 0.0, (width - 1) / 2.0], [0.0, f, (height - 1) / 2.0], [0.0, 0.0, 1.0]])


def _pose_looking_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray) -> Transform:
    base_R_cam = look_at(eye, target, up)
    return Transform(base_R_cam, np.asarray(eye, float)).inverse()


#: Front camera placement for the reference robot: horizontal distance from the base
#: centre [m], azimuth from the base x axis [deg], height of the projection centre
#: [m] and height of the aim point on the base z axis [m].
FRONT_DISTANCE = 0.80
FRONT_AZIMUTH_DEG = 30.0
FRONT_EYE_HEIGHT = 0.0
FRONT_TARGET_HEIGHT = 0.265


def front_camera(geometry: HexapodGeometry | None = None) -> PerspectiveCamera:
    """The front perspective camera of seed 002 (``docs/math.md`` section 9).

    Intrinsics: 4.8 mm lens on a 1024x780 sensor with 4.65 um square pixels
    (``f = 4.8 / 0.00465 = 1032.26 px``, horizontal field of view 53 deg),
    principal point at the image centre ``(511.5, 389.5)``, no skew.

    Placement (reference robot): projection centre 0.80 m from the base centre,
    horizontally, at azimuth 30 deg (between the base joint pair at 0 deg and the
    platform joint pair at 60 deg) and at the height of the base joints, aimed at
    the point of the base axis 0.265 m high, image rows vertical. The seed says
    "about 0.7 m"; at 0.70 m the nearest legs (0.45 m tall, 0.45 m away) cannot fit
    in the 780-pixel height with this lens, at 0.80 m every leg stays entirely inside
    the image over the workspace of :func:`hexapod.sample_poses` (at least 2 pixels
    of margin on 4,000 random poses, checked by the tests). From there, legs hide
    one another in part of the workspace (about 17 % of the random poses have at
    least one hidden edge), as in the seed. For another geometry the placement is
    scaled by the base radius (distance) and the home height (aim point).
    """
    geo = deltalab() if geometry is None else geometry
    scale = float(np.max(np.linalg.norm(geo.base_points[:, :2], axis=1))) / 0.270
    zscale = geo.home_height / 0.3594098
    zbase = float(np.mean(geo.base_points[:, 2]))
    f = FRONT_FOCAL_LENGTH / FRONT_PIXEL_SIZE
    K = _intrinsics(f, 1024, 780)
    a = np.deg2rad(FRONT_AZIMUTH_DEG)
    d = FRONT_DISTANCE * scale
    eye = np.array([d * np.cos(a), d * np.sin(a), zbase + FRONT_EYE_HEIGHT * zscale])
    target = np.array([0.0, 0.0, zbase + FRONT_TARGET_HEIGHT * zscale])
    pose = _pose_looking_at(eye, target, np.array([0.0, 0.0, 1.0]))
    return PerspectiveCamera(K, 1024, 780, pose, name="front")


#: Generalised focal length of the omnidirectional preset [px].
OMNI_FOCAL = 200.0


def omni_camera(geometry: HexapodGeometry | None = None) -> UnifiedCamera:
    """The omnidirectional camera of seed 003 (``docs/math.md`` section 9).

    Parabolic mirror with an orthographic lens (``xi = 1``), 640x480 image,
    generalised focal length 200 px, principal point at the image centre
    ``(319.5, 239.5)``; the mirror (sphere) centre is at the centre of the base
    joint circle, its axis along the base z axis (looking up at the platform),
    camera x = base x, camera y = base y.

    With this focal length a point at the height of the base joints is imaged on
    the circle of radius 200 px and every leg of the reference robot crosses the
    whole annulus of diameters 184 to 370 px over the workspace (its base end is
    beyond 193 px, its platform end within 89 px of the image centre), as in
    seed 003; no leg hides another one enough to lose an edge.
    """
    geo = deltalab() if geometry is None else geometry
    centre = np.mean(geo.base_points, axis=0).round(12) + 0.0
    K = _intrinsics(OMNI_FOCAL, 640, 480)
    return UnifiedCamera(K, 1.0, 640, 480, Transform(np.eye(3), -centre), name="omni")


_PRESETS = {"front": front_camera, "omni": omni_camera}


def camera_preset(name: str, geometry: HexapodGeometry | None = None) -> Camera:
    """A camera preset by name: ``"front"`` (perspective) or ``"omni"`` (unified).

    Raises:
        CameraError: Unknown name (with the close valid name, if any).
    """
    if name not in _PRESETS:
        hint = suggest(name, _PRESETS)
        raise CameraError(
            "preset",
            f"unknown camera preset '{name}'; available: {', '.join(_PRESETS)}"
            + (f" (did you mean '{hint}'?)" if hint else ""),
        )
    return _PRESETS[name](geometry)


def load_camera(path_or_name: str | Path, geometry: HexapodGeometry | None = None) -> Camera:
    """A preset name (``"front"``, ``"omni"``) or a TOML file path."""
    s = str(path_or_name)
    if s in _PRESETS:
        return camera_preset(s, geometry)
    if s.endswith(".toml") or Path(s).exists():
        return Camera.from_toml(s)
    return camera_preset(s, geometry)
