"""Camera models: perspective (pinhole) and unified central (Geyer-Daniilidis / Mei),
with OpenCV's lens distortion.

Conventions (``docs/math.md`` section 5):

- Camera frame: x right, y down, z forward (perspective) or along the mirror axis
  (unified). For the unified model the camera frame is the mirror (sphere) frame.
- Pixel coordinates follow OpenCV: ``(u, v)`` with ``u`` along the image columns
  and ``v`` along the rows; the centre of the pixel in column ``i`` and row ``j``
  is at ``(i, j)``, so the image covers ``[-0.5, width - 0.5] x [-0.5, height - 0.5]``.
- ``K = [[fx, s, cx], [0, fy, cy], [0, 0, 1]]`` maps the distorted normalised point
  ``m_d = D(m)`` to the pixel ``p = K m_d``; ``m`` is the normalised point of the
  projection (:mod:`vision.projection`), ``D`` the lens distortion
  (:mod:`vision.distortion`, OpenCV's ``(k1, k2, p1, p2[, k3])``; the identity for an
  ideal lens). The *ideal image* is the one of ``K m`` (no distortion): the lines and
  conics of the leg edges are defined on it.
- Each camera has a fixed pose with respect to the robot base,
  ``camera_from_base``: ``p_camera = R p_base + t``.

The perspective camera is the unified one with ``xi = 0``; ``UnifiedCamera`` with
``xi = 0`` gives bit-identical projections and lifts. ``PerspectiveCamera`` projects
as ``cv2.projectPoints`` (which ignores the skew ``K[0, 1]``: equal when it is 0, as
``cv2.calibrateCamera`` gives), ``UnifiedCamera`` as ``cv::omnidir::projectPoints``
(``u = fx x_d + s y_d + cx``).
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from hexapod.kinematics import Transform
from vision import projection
from vision.camera_base import Camera
from vision.camera_checks import (
    as_pixels,
    as_points,
    check_K,
    check_pose,
    check_size,
    check_xi,
    unit,
)
from vision.camera_files import CameraFields


class PerspectiveCamera(Camera):
    """Pinhole camera ``p ~ K D(X/Z, Y/Z)``, OpenCV's model (``cv2.projectPoints``).

    Args:
        K: (3, 3) intrinsics [px].
        width: Image width [px].
        height: Image height [px].
        camera_from_base: Pose w.r.t. the robot base (identity by default).
        name: A label.
        source: File the camera was read from (for the messages).
        distortion: OpenCV's coefficients ``(k1, k2, p1, p2[, k3])`` (4 or 5 numbers;
            None or zeros: an ideal lens), applied to ``(X/Z, Y/Z)``.

    Raises:
        CameraError: A field is invalid.
        DistortionError: The distortion folds inside the image.

    The line features (:meth:`normal_to_line`, :attr:`line_matrix`,
    :meth:`pixels_to_line_coordinates`) are those of the ideal image ``K (X/Z, Y/Z)``;
    :meth:`normal_to_pixel_line` and :meth:`pixel_line_to_normal`, which relate
    straight lines of the raw image, refuse a distorted camera.
    """

    kind: ClassVar[str] = "perspective"
    distortion_lengths: ClassVar[tuple[int, ...]] = (4, 5)

    def __init__(
        self,
        K: np.ndarray,
        width: int,
        height: int,
        camera_from_base: Transform | None = None,
        name: str = "perspective",
        source: str | None = None,
        distortion: Any = None,
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
        self._set_lens(distortion)
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

    @classmethod
    def _from_fields(cls, f: CameraFields) -> PerspectiveCamera:
        return cls(f.K, f.width, f.height, f.camera_from_base, name=f.name, source=f.source,
                   distortion=f.distortion)

    def _normalised(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return projection.normalised(X, 0.0)

    def _lift_normalised(self, m: np.ndarray) -> np.ndarray:
        return projection.lift(m, 0.0)

    def normal_to_line(self, n: np.ndarray) -> np.ndarray:
        """Interpretation-plane normals (..., 3) -> unit lines (..., 3) in normalised
        pixel coordinates of the ideal image: ``l = Kt^-T n / |Kt^-T n|`` with
        ``Kt = line_matrix`` (positive scale, so the sign follows ``n``)."""
        n = as_points(n, "n")
        return unit(n @ self._line_matrix_inv_T.T)

    def line_to_normal(self, l: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`normal_to_line`: ``n = Kt^T l / |Kt^T l|``."""
        l = as_points(l, "l")
        return unit(l @ self.line_matrix)

    def normal_to_pixel_line(self, n: np.ndarray) -> np.ndarray:
        """Unit line (..., 3) in raw pixel coordinates (``l^T [u, v, 1] = 0``),
        ``l = K^-T n / |K^-T n|``.

        Raises:
            CameraError: The camera is distorted (the image of a line is a curve).
        """
        self._refuse_distortion("normal_to_pixel_line")
        n = as_points(n, "n")
        return unit(n @ np.linalg.inv(self.K))

    def pixel_line_to_normal(self, l: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`normal_to_pixel_line`: ``n = K^T l / |K^T l|``.

        Raises:
            CameraError: The camera is distorted (the image of a line is a curve).
        """
        self._refuse_distortion("pixel_line_to_normal")
        l = as_points(l, "l")
        return unit(l @ self.K)

    def pixels_to_line_coordinates(self, pixels: np.ndarray) -> np.ndarray:
        """Pixels (..., 2) -> normalised pixel coordinates (..., 2) used by the lines:
        ``((u - w/2)/w, (v - h/2)/w)`` of the ideal pixel ``(u, v) = K m`` (the pixel
        itself for an ideal lens; the distortion removed otherwise)."""
        p = as_pixels(pixels)
        if self.is_distorted:
            m = self.pixels_to_normalised(p)
            K = self.K
            p = np.stack([K[0, 0] * m[..., 0] + K[0, 1] * m[..., 1] + K[0, 2],
                          K[1, 1] * m[..., 1] + K[1, 2]], axis=-1)
        return np.stack([(p[..., 0] - 0.5 * self.width) / self.width,
                         (p[..., 1] - 0.5 * self.height) / self.width], axis=-1)


class UnifiedCamera(Camera):
    """Unified central camera (Geyer-Daniilidis / Mei), ``docs/math.md`` section 5.

    ``X_s = X / |X|``, ``m = (X_s,x, X_s,y) / (X_s,z + xi)``, ``p = K D(m)`` with the
    distortion ``D`` of ``cv::omnidir`` (Mei's model; ``u = fx x_d + s y_d + cx``).
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
        source: File the camera was read from (for the messages).
        distortion: omnidir's coefficients ``(k1, k2, p1, p2)`` (None or zeros: none).

    Raises:
        CameraError: A field is invalid.
        DistortionError: The distortion folds inside the image.

    The conics (:meth:`normal_to_normalised_conic`) are those of the ideal image;
    :meth:`normal_to_conic`, a conic of the raw image, refuses a distorted camera.
    """

    kind: ClassVar[str] = "unified"
    distortion_lengths: ClassVar[tuple[int, ...]] = (4,)

    def __init__(
        self,
        K: np.ndarray,
        xi: float,
        width: int,
        height: int,
        camera_from_base: Transform | None = None,
        name: str = "unified",
        source: str | None = None,
        distortion: Any = None,
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
        self._set_lens(distortion)

    def _fields(self) -> dict[str, Any]:
        d = super()._fields()
        d["xi"] = self.xi
        return d

    @classmethod
    def _from_fields(cls, f: CameraFields) -> UnifiedCamera:
        return cls(f.K, f.xi, f.width, f.height, f.camera_from_base, name=f.name,
                   source=f.source, distortion=f.distortion)

    def _normalised(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return projection.normalised(X, self.xi)

    def _lift_normalised(self, m: np.ndarray) -> np.ndarray:
        return projection.lift(m, self.xi)

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

        Raises:
            CameraError: The camera is distorted (the image is not a conic).
        """
        self._refuse_distortion("normal_to_conic")
        W = projection.omega(as_points(n, "n"), self.xi)
        Ki = np.linalg.inv(self.K)
        C = Ki.T @ W @ Ki
        return C / np.linalg.norm(C, axis=(-2, -1), keepdims=True)

    def normal_to_normalised_conic(self, n: np.ndarray) -> np.ndarray:
        """The conic Ω (..., 3, 3) in normalised coordinates ``m`` (unit Frobenius norm),
        the image of the edge in :meth:`pixels_to_normalised` coordinates."""
        W = projection.omega(as_points(n, "n"), self.xi)
        return W / np.linalg.norm(W, axis=(-2, -1), keepdims=True)


# Re-exported so that ``from vision.cameras import X`` keeps working for every public
# name of the former single module. Imported last: the presets build cameras with the
# classes above (``vision/__init__.py`` imports this module before any other).
from vision.camera_presets import (  # noqa: E402
    FRONT_AZIMUTH_DEG,
    FRONT_DISTANCE,
    FRONT_DISTORTION,
    FRONT_EYE_HEIGHT,
    FRONT_FOCAL_LENGTH,
    FRONT_PIXEL_SIZE,
    FRONT_TARGET_HEIGHT,
    OMNI_DISTORTION,
    OMNI_FOCAL,
    camera_preset,
    front_camera,
    load_camera,
    load_opencv_camera,
    omni_camera,
    save_opencv_camera,
)

__all__ = [
    "FRONT_AZIMUTH_DEG",
    "FRONT_DISTANCE",
    "FRONT_DISTORTION",
    "FRONT_EYE_HEIGHT",
    "FRONT_FOCAL_LENGTH",
    "FRONT_PIXEL_SIZE",
    "FRONT_TARGET_HEIGHT",
    "OMNI_DISTORTION",
    "OMNI_FOCAL",
    "Camera",
    "PerspectiveCamera",
    "UnifiedCamera",
    "camera_preset",
    "front_camera",
    "load_camera",
    "load_opencv_camera",
    "omni_camera",
    "save_opencv_camera",
]
