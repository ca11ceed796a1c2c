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

from abc import ABC, abstractmethod
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import tomli_w

from hexapod.config import load_toml, suggest
from hexapod.kinematics import Transform
from vision.camera_checks import (
    as_pixels,
    as_points,
    check_K,
    check_pose,
    check_size,
    check_xi,
    unit,
)
from vision.camera_files import CAMERA_KEYS, POSE_KEYS, camera_table, read_camera_table
from vision.exceptions import CameraError


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
        p = as_pixels(pixels)
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
        X = as_points(points)
        m, valid = self._normalised(X)
        K = self.K
        u = K[0, 0] * m[..., 0] + K[0, 1] * m[..., 1] + K[0, 2]
        v = K[1, 1] * m[..., 1] + K[1, 2]
        pix = np.stack([u, v], axis=-1)
        pix = np.where(valid[..., None], pix, np.nan)
        return pix, valid & self.in_image(pix)

    def project_base(self, points_base: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Like :meth:`project` for points (..., 3) given in the robot base frame."""
        return self.project(self.camera_from_base.apply(as_points(points_base)))

    def pixels_to_normalised(self, pixels: np.ndarray) -> np.ndarray:
        """Normalised image coordinates ``m = K^-1 p`` (..., 2) of pixels (..., 2)."""
        p = as_pixels(pixels)
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

    _KEYS = CAMERA_KEYS
    _POSE_KEYS = POSE_KEYS

    def to_dict(self) -> dict[str, Any]:
        """The file representation (pixels, millimetres, degrees; :mod:`vision.camera_files`)."""
        return camera_table(self)

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
        model = None if cls is Camera else (cls.kind, cls.__name__)
        f = read_camera_table(table, path, model)
        if f.kind == "unified":
            return UnifiedCamera(f.K, f.xi, f.width, f.height, f.camera_from_base, name=f.name,
                                 source=f.source)
        return PerspectiveCamera(f.K, f.width, f.height, f.camera_from_base, name=f.name,
                                 source=f.source)

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
        self.K = check_K(K, source)
        self.width = check_size("width", width, source)
        self.height = check_size("height", height, source)
        self.xi = 0.0
        self.camera_from_base = check_pose(
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
        return unit(mh)

    def normal_to_line(self, n: np.ndarray) -> np.ndarray:
        """Interpretation-plane normals (..., 3) -> unit lines (..., 3) in normalised
        pixel coordinates: ``l = Kt^-T n / |Kt^-T n|`` with ``Kt = line_matrix``
        (positive scale, so the sign follows ``n``)."""
        n = as_points(n, "n")
        return unit(n @ self._line_matrix_inv_T.T)

    def line_to_normal(self, l: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`normal_to_line`: ``n = Kt^T l / |Kt^T l|``."""
        l = as_points(l, "l")
        return unit(l @ self.line_matrix)

    def normal_to_pixel_line(self, n: np.ndarray) -> np.ndarray:
        """Unit line (..., 3) in raw pixel coordinates (``l^T [u, v, 1] = 0``),
        ``l = K^-T n / |K^-T n|``."""
        n = as_points(n, "n")
        return unit(n @ np.linalg.inv(self.K))

    def pixel_line_to_normal(self, l: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`normal_to_pixel_line`: ``n = K^T l / |K^T l|``."""
        l = as_points(l, "l")
        return unit(l @ self.K)

    def pixels_to_line_coordinates(self, pixels: np.ndarray) -> np.ndarray:
        """Pixels (..., 2) -> normalised pixel coordinates (..., 2) used by the lines."""
        p = as_pixels(pixels)
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
        self.K = check_K(K, source)
        self.xi = check_xi(xi, source)
        self.width = check_size("width", width, source)
        self.height = check_size("height", height, source)
        self.camera_from_base = check_pose(
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
            return unit(mh)
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
        W = self._omega(as_points(n, "n"))
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
        W = self._omega(as_points(n, "n"))
        return W / np.linalg.norm(W, axis=(-2, -1), keepdims=True)


# Re-exported so that ``from vision.cameras import X`` keeps working for every public
# name of the former single module. Imported last: the presets build cameras with the
# classes above (``vision/__init__.py`` imports this module before any other).
from vision.camera_presets import (  # noqa: E402
    FRONT_AZIMUTH_DEG,
    FRONT_DISTANCE,
    FRONT_EYE_HEIGHT,
    FRONT_FOCAL_LENGTH,
    FRONT_PIXEL_SIZE,
    FRONT_TARGET_HEIGHT,
    OMNI_FOCAL,
    camera_preset,
    front_camera,
    load_camera,
    omni_camera,
)

__all__ = [
    "FRONT_AZIMUTH_DEG",
    "FRONT_DISTANCE",
    "FRONT_EYE_HEIGHT",
    "FRONT_FOCAL_LENGTH",
    "FRONT_PIXEL_SIZE",
    "FRONT_TARGET_HEIGHT",
    "OMNI_FOCAL",
    "Camera",
    "PerspectiveCamera",
    "UnifiedCamera",
    "camera_preset",
    "front_camera",
    "load_camera",
    "omni_camera",
]
