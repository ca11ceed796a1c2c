"""The common base of the camera models (:class:`Camera`): pixels, distortion, lifting,
Jacobians, copies; the models themselves are one module each in :mod:`vision.cameras`
(conventions there and in ``docs/math.md`` section 5).

The base reads and writes no file: :meth:`Camera.from_dict` and :meth:`Camera.to_dict`
go through the table reader and writer that :mod:`vision.cameras.factory` installs
(:func:`install_table_io`), so that no model imports the file readers.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import tomli_w

from hexapod.config import load_toml, suggest
from hexapod.kinematics import Transform
from vision.cameras import projection
from vision.cameras.checks import as_pixels, as_points
from vision.cameras.distortion import RadialTangential, parse_coefficients
from vision.cameras.fields import CameraFields
from vision.cameras.lens import Lens, check_no_fold_in_image
from vision.exceptions import CameraError

#: ``(table, path, model) -> camera`` and ``camera -> table``: the camera file format,
#: installed by :mod:`vision.cameras.factory` (:func:`install_table_io`).
TableReader = Callable[[dict[str, Any], str, "type[Camera] | None"], "Camera"]
TableWriter = Callable[["Camera"], dict[str, Any]]
_table_io: dict[str, Any] = {}


def install_table_io(reader: TableReader, writer: TableWriter) -> None:
    """Install the camera file format (called once by :mod:`vision.cameras.factory`)."""
    _table_io["read"] = reader
    _table_io["write"] = writer


class Camera(ABC):
    """Common base of the camera models.

    Attributes:
        kind: The model: ``"perspective"``, ``"unified"``, ``"fisheye"``,
            ``"double_sphere"`` or ``"eucm"``.
        K: (3, 3) intrinsics [px] (read-only array).
        width: Image width [px].
        height: Image height [px].
        xi: Mirror parameter of the unified model (0 for the perspective camera).
        distortion: Read-only lens parameters in the model's order: OpenCV's
            ``(k1, k2, p1, p2, k3[, k4..k6[, s1..s4[, tau_x, tau_y]]])`` (perspective),
            ``(k1, k2, p1, p2)`` (unified), ``(k1, k2, k3, k4)`` (fisheye), ``(xi,
            alpha)`` (double sphere), ``(alpha, beta)`` (extended unified); zeros for
            an ideal lens.
        lens: The distortion map (:class:`vision.cameras.lens.Lens`: OpenCV's
            radial-tangential model, its full model, or a radial fisheye model).
        camera_from_base: Pose of the camera w.r.t. the robot base,
            ``p_camera = R p_base + t``.
        name: A label.
    """

    kind: ClassVar[str]
    #: ``"perspective"`` (a pinhole, possibly through a lens: the edges are lines of
    #: the ideal image, the tracker detects them) or ``"unified"`` (conics, the
    #: omnidirectional circle scan): the part of the pipeline the model uses.
    family: ClassVar[str]
    #: Accepted lengths of the distortion vector.
    distortion_lengths: ClassVar[tuple[int, ...]]
    K: np.ndarray
    width: int
    height: int
    xi: float
    distortion: np.ndarray
    lens: Lens
    camera_from_base: Transform
    name: str
    source: str | None

    #: The models by kind (filled by the subclasses).
    models: ClassVar[dict[str, type[Camera]]] = {}

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if "kind" in cls.__dict__:
            Camera.models[cls.kind] = cls

    @classmethod
    @abstractmethod
    def _from_fields(cls, f: CameraFields) -> Camera:
        """The camera of fields read from a file."""

    def _set_lens(self, distortion: Any) -> None:
        """Validate the distortion; refuse one that folds inside the image."""
        self.lens, d = self._make_lens(distortion)
        d.flags.writeable = False
        self.distortion = d
        check_no_fold_in_image(self.lens, self.K, self.width, self.height,
                               projection.domain_radius(self.xi), self.source)

    def _make_lens(self, distortion: Any) -> tuple[Lens, np.ndarray]:
        """The lens map of the distortion coefficients and the coefficients kept
        (OpenCV's radial-tangential model; other models override)."""
        coeffs = parse_coefficients(distortion, self.distortion_lengths, self.source)
        return RadialTangential(coeffs), coeffs[: max(self.distortion_lengths)].copy()

    def lens_scaled(self, factor: float) -> Camera:
        """The camera with its distortion coefficients times ``factor`` (0: the ideal
        lens), e.g. the model of a user who misses part of the lens."""
        if factor == 1.0 or not self.is_distorted:
            return self
        d = np.asarray(self.distortion, float) * factor
        return self.replace(distortion=None if not np.any(d) else d)

    # ------------------------------------------------------------- derived
    @property
    def is_distorted(self) -> bool:
        """True when the lens has a nonzero distortion coefficient."""
        return not self.lens.is_identity

    @property
    def K_inv(self) -> np.ndarray:
        """Inverse intrinsics: pixels to *distorted* normalised coordinates (the
        distortion-aware path is :meth:`pixels_to_normalised`)."""
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

    def distort(self, m: np.ndarray) -> np.ndarray:
        """Distorted normalised coordinates ``m_d = D(m)`` (..., 2) of ``m`` (..., 2)."""
        m = as_pixels(m, "m")
        return m if self.lens.is_identity else self.lens.apply(m)

    def undistort(self, m_d: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`distort` (..., 2), on the fold-free sheet around the principal
        point (NaN where there is no pre-image there)."""
        m_d = as_pixels(m_d, "m_d")
        return m_d if self.lens.is_identity else self.lens.remove(m_d)

    def distortion_jacobian(self, m: np.ndarray) -> np.ndarray:
        """``d m_d / d m`` (..., 2, 2) of the distortion at normalised coordinates ``m``."""
        return self.lens.jacobian(as_pixels(m, "m"))

    def normalised_to_pixels(self, m: np.ndarray) -> np.ndarray:
        """Pixels ``K D(m)`` (..., 2) of normalised coordinates ``m`` (..., 2)."""
        md = self.distort(m)
        K = self.K
        u = K[0, 0] * md[..., 0] + K[0, 1] * md[..., 1] + K[0, 2]
        v = K[1, 1] * md[..., 1] + K[1, 2]
        return np.stack([u, v], axis=-1)

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Project points given in the camera frame (distortion included).

        Args:
            points: (..., 3) points in the camera frame [m].

        Returns:
            ``pixels`` (..., 2) and ``visible`` (...) bool: False where the point is
            behind the camera / not imaged by the model (pixels NaN there), beyond
            the fold of the lens distortion (outside the field of view where the
            polynomial is one-to-one; OpenCV's pixel is still given, it may even fall
            in the image) or projects outside the image (pixels still given).
        """
        pix, imaged = self.project_imaged(points)
        return pix, imaged & self.in_image(pix)

    def project_imaged(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`project`'s ``pixels`` and whether the model images the points at all
        (in its domain, and within the fold of the lens distortion; in the image or
        not): its ``visible`` without the image's bounds."""
        X = as_points(points)
        m, valid = self._normalised(X)
        m = np.where(valid[..., None], m, 0.0)
        with np.errstate(invalid="ignore", over="ignore"):
            pix = self.normalised_to_pixels(m)
        pix = np.where(valid[..., None], pix, np.nan)
        if self.is_distorted:
            valid = valid & (np.linalg.norm(m, axis=-1) < self.lens.fold_free_radius(m))
        return pix, valid

    def imaged(self, points: np.ndarray) -> np.ndarray:
        """Whether points (..., 3) in the camera frame are imaged by the model at all
        (:meth:`project_imaged`)."""
        return self.project_imaged(points)[1]

    def project_base(self, points_base: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Like :meth:`project` for points (..., 3) given in the robot base frame."""
        return self.project(self.camera_from_base.apply(as_points(points_base)))

    def project_jacobian(self, points: np.ndarray) -> np.ndarray:
        """``d pixel / d point`` (..., 2, 3) of :meth:`project` [px/m], distortion included.

        Args:
            points: (..., 3) points in the camera frame [m] (for points in the base
                frame, multiply on the right by ``camera_from_base.rotation``).

        Returns:
            ``K[:2, :2] dD/dm dm/dX``; NaN where the point is not imaged.
        """
        X = as_points(points)
        m, valid = self._normalised(X)
        m = np.where(valid[..., None], m, 0.0)
        J = self._normalised_jacobian(X)
        return np.asarray(self.K[:2, :2] @ self.distortion_jacobian(m) @ J)

    def pixels_to_distorted(self, pixels: np.ndarray) -> np.ndarray:
        """Distorted normalised coordinates ``m_d = K^-1 p`` (..., 2) of pixels (..., 2)."""
        p = as_pixels(pixels)
        K = self.K
        y = (p[..., 1] - K[1, 2]) / K[1, 1]
        x = (p[..., 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
        return np.stack([x, y], axis=-1)

    def pixels_to_normalised(self, pixels: np.ndarray) -> np.ndarray:
        """Normalised coordinates ``m = D^-1(K^-1 p)`` (..., 2) of pixels (..., 2): the
        distortion removed (``K^-1 p`` for an ideal lens), NaN where not invertible."""
        return self.undistort(self.pixels_to_distorted(pixels))

    def lift(self, pixels: np.ndarray) -> np.ndarray:
        """Back-project pixels (..., 2) to unit vectors (..., 3) in the camera frame.

        The distortion is removed first (:meth:`pixels_to_normalised`). Perspective:
        the normalised ray ``(m, 1) / |(m, 1)|``. Unified: the point of the unit sphere
        (``docs/math.md`` section 5). NaN where the pixel has no pre-image (outside the
        mirror's field of view, ``xi > 1`` only, or beyond the lens's fold).
        """
        return self._lift_normalised(self.pixels_to_normalised(pixels))

    def lift_jacobian(self, pixels: np.ndarray) -> np.ndarray:
        """``d ray / d pixel`` (..., 3, 2) of :meth:`lift` [1/px], distortion included.

        ``dX_s/dm (dD/dm)^-1 K[:2, :2]^-1`` at the undistorted point of each pixel;
        NaN where the pixel has no pre-image.
        """
        m = self.pixels_to_normalised(pixels)
        Jd = self.distortion_jacobian(m)
        a, b, c, d = Jd[..., 0, 0], Jd[..., 0, 1], Jd[..., 1, 0], Jd[..., 1, 1]
        with np.errstate(invalid="ignore", divide="ignore"):
            inv = np.stack([np.stack([d, -b], -1), np.stack([-c, a], -1)], -2)
            inv /= (a * d - b * c)[..., None, None]
        return np.asarray(self._lift_jacobian(m) @ inv @ np.linalg.inv(self.K[:2, :2]))

    def _normalised_jacobian(self, X: np.ndarray) -> np.ndarray:
        return projection.normalised_jacobian(X, self.xi)

    def _lift_jacobian(self, m: np.ndarray) -> np.ndarray:
        return projection.lift_jacobian(m, self.xi)

    def _refuse_distortion(self, what: str) -> None:
        if self.is_distorted:
            raise CameraError(
                "distortion",
                f"{what} is only defined for an ideal lens: with distortion "
                f"{tuple(float(c) for c in self.distortion)} the image of a 3D line is a "
                "curve; use the ideal-image features (normal_to_line, "
                "normal_to_normalised_conic, pixels_to_normalised) or lift",
                self.source,
            )

    # ------------------------------------------------------------- copy / io
    def _fields(self) -> dict[str, Any]:
        return {
            "K": self.K,
            "width": self.width,
            "height": self.height,
            "camera_from_base": self.camera_from_base,
            "name": self.name,
            "distortion": self.distortion,
        }

    def replace(self, **changes: Any) -> Camera:
        """Return a copy with some fields changed (validated again).

        Fields: ``K``, ``width``, ``height``, ``camera_from_base``, ``name``,
        ``distortion`` and, for the unified camera, ``xi``.
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
            and np.array_equal(self.distortion, other.distortion)
            and np.array_equal(self.camera_from_base.rotation, other.camera_from_base.rotation)
            and np.array_equal(
                self.camera_from_base.translation, other.camera_from_base.translation
            )
        )

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        xi = f", xi={self.xi}" if self.kind == "unified" else ""
        dist = (f", distortion=({', '.join(f'{c:g}' for c in self.distortion)})"
                if self.is_distorted else "")
        return (
            f"{type(self).__name__}(name={self.name!r}, {self.width}x{self.height}, "
            f"fx={self.fx:.3f}, fy={self.fy:.3f}, cx={self.cx:.3f}, cy={self.cy:.3f}{xi}{dist})"
        )

    def to_dict(self) -> dict[str, Any]:
        """The file representation (pixels, millimetres, degrees;
        :mod:`vision.cameras.files.project`)."""
        return dict(_table_io["write"](self))

    def to_toml(self, path: str | Path) -> None:
        """Save the camera to a TOML file.

        Format (:mod:`vision.cameras.files.project`): ``kind`` (the model), ``name``,
        ``width_px``, ``height_px``, ``fx_px``, ``fy_px``, ``cx_px``, ``cy_px``,
        ``skew_px``, ``xi`` (unified only), ``distortion`` (the lens parameters, absent
        for an ideal lens) and a table ``[camera_from_base]`` with ``translation_mm``
        and ``rotation_vector_deg`` (axis times angle, degrees) such that
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
        from hexapod.config import check_file_kind

        check_file_kind(table, path, "camera file")
        camera: Camera = _table_io["read"](table, path, None if cls is Camera else cls)
        return camera

    @classmethod
    def from_toml(cls, path: str | Path) -> Camera:
        """Load a camera from a TOML file (see :meth:`to_toml` for the format).

        Raises:
            ConfigFileError: Missing file, bad TOML, missing or misspelt key, bad value.
            CameraError: The camera is invalid (e.g. rotation not orthonormal).
        """
        return cls.from_dict(load_toml(path), str(path))
