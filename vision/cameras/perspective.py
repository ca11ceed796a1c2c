"""The perspective (pinhole) camera with OpenCV's lens distortion (``cv2.projectPoints``).

Conventions (``docs/math.md`` section 5, and :mod:`vision.cameras`):

- Camera frame: x right, y down, z forward.
- Pixel coordinates follow OpenCV: ``(u, v)`` with ``u`` along the image columns
  and ``v`` along the rows; the centre of the pixel in column ``i`` and row ``j``
  is at ``(i, j)``, so the image covers ``[-0.5, width - 0.5] x [-0.5, height - 0.5]``.
- ``K = [[fx, s, cx], [0, fy, cy], [0, 0, 1]]`` maps the distorted normalised point
  ``m_d = D(m)`` to the pixel ``p = K m_d``; ``m = (X/Z, Y/Z)``, ``D`` the lens distortion
  (:mod:`vision.cameras.distortion`). The *ideal image* is the one of ``K m`` (no
  distortion): the lines of the leg edges are defined on it.
- ``PerspectiveCamera`` projects as ``cv2.projectPoints`` (which ignores the skew
  ``K[0, 1]``: equal when it is 0, as ``cv2.calibrateCamera`` gives).
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from hexapod.kinematics import Transform
from vision.cameras import projection
from vision.cameras.base import Camera
from vision.cameras.checks import (
    as_pixels,
    as_points,
    check_K,
    check_pose,
    check_principal_point,
    check_size,
    unit,
)
from vision.cameras.distortion import RadialTangential, parse_coefficients
from vision.cameras.distortion_full import OpenCVLens, check_tilt, needs_full_model
from vision.cameras.fields import CameraFields
from vision.cameras.lens import Lens
from vision.exceptions import CameraError

#: OpenCV's coefficient-vector lengths and the terms they end with.
OPENCV_LENGTHS = (4, 5, 8, 12, 14)


class PerspectiveCamera(Camera):
    """Pinhole camera ``p ~ K D(X/Z, Y/Z)``, OpenCV's model (``cv2.projectPoints``).

    Args:
        K: (3, 3) intrinsics [px].
        width: Image width [px].
        height: Image height [px].
        camera_from_base: Pose w.r.t. the robot base (identity by default).
        name: A label (None: the model's :attr:`kind`).
        source: File the camera was read from (for the messages).
        distortion: OpenCV's coefficients ``(k1, k2, p1, p2[, k3[, k4, k5, k6[, s1, s2,
            s3, s4[, tau_x, tau_y]]]])`` (4, 5, 8, 12 or 14 numbers, as
            ``cv2.projectPoints``; None or zeros: an ideal lens), applied to
            ``(X/Z, Y/Z)``. With a nonzero term beyond ``k3`` the lens is OpenCV's full
            model (:class:`vision.cameras.distortion_full.OpenCVLens`), else the
            radial-tangential one (:class:`vision.cameras.distortion.RadialTangential`)
            and :attr:`distortion` keeps five numbers.

    Raises:
        CameraError: A field is invalid.
        DistortionError: The distortion folds inside the image.

    The line features (:meth:`normal_to_line`, :attr:`line_matrix`,
    :meth:`pixels_to_line_coordinates`) are those of the ideal image ``K (X/Z, Y/Z)``;
    :meth:`normal_to_pixel_line` and :meth:`pixel_line_to_normal`, which relate
    straight lines of the raw image, refuse a distorted camera.
    """

    kind: ClassVar[str] = "perspective"
    family: ClassVar[str] = "perspective"
    distortion_lengths: ClassVar[tuple[int, ...]] = OPENCV_LENGTHS

    def __init__(
        self,
        K: np.ndarray,
        width: int,
        height: int,
        camera_from_base: Transform | None = None,
        name: str | None = None,
        source: str | None = None,
        distortion: Any = None,
    ) -> None:
        self.source = source
        self.K = check_K(K, source)
        self.width = check_size("width", width, source)
        self.height = check_size("height", height, source)
        check_principal_point(self.K, self.width, self.height, source)
        self.xi = 0.0
        self.camera_from_base = check_pose(
            Transform.identity() if camera_from_base is None else camera_from_base, source
        )
        self.name = self.kind if name is None else str(name)
        self._set_lens(distortion)
        w, h = float(self.width), float(self.height)
        N = np.array([[1.0 / w, 0.0, -0.5], [0.0, 1.0 / w, -0.5 * h / w], [0.0, 0.0, 1.0]])
        lm = N @ self.K
        lm.flags.writeable = False
        self.line_matrix = lm
        self._line_matrix_inv_T = np.linalg.inv(lm).T

    def _make_lens(self, distortion: Any) -> tuple[Lens, np.ndarray]:
        c = parse_coefficients(distortion, OPENCV_LENGTHS, self.source,
                               "k1, k2, p1, p2[, k3[, k4, k5, k6[, s1..s4[, tau_x, tau_y]]]]")
        if not needs_full_model(c):
            return RadialTangential(c[:5]), c[:5].copy()
        check_tilt(c, self.source)
        last = int(np.flatnonzero(c)[-1]) + 1
        n = min(k for k in OPENCV_LENGTHS if k >= last)
        return OpenCVLens(c), c[:n].copy()

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

    @property
    def normal_to_line_matrix(self) -> np.ndarray:
        """(3, 3) ``M`` of :meth:`normal_to_line`, ``l = n M / |n M|`` (``M = Kt^-1``, a
        read-only view; :func:`normals_to_lines` takes one per row)."""
        return self._line_matrix_inv_T.T  # type: ignore[no-any-return]

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


def normals_to_lines(normals: np.ndarray, matrices: np.ndarray) -> np.ndarray:
    """:meth:`PerspectiveCamera.normal_to_line` of each row through its own camera, in one
    call: the same numbers as row by row.

    Args:
        normals: (n, ..., 3) interpretation-plane normals of row ``k`` seen by camera ``k``.
        matrices: (n, 3, 3) each camera's :attr:`PerspectiveCamera.normal_to_line_matrix`.

    Returns:
        (n, ..., 3) unit lines in normalised pixel coordinates.

    Raises:
        CameraError: ``matrices`` is not one (3, 3) per row.
    """
    n = as_points(normals, "normals")
    M = np.asarray(matrices, dtype=float)
    if M.shape != (len(n), 3, 3):
        raise CameraError("matrices", f"expected shape ({len(n)}, 3, 3) (one per row of the "
                          f"normals {n.shape}), got {M.shape}")
    return unit(np.matmul(n, M.reshape(len(n), *([1] * (n.ndim - 3)), 3, 3)))


def lines_and_normals(normals: np.ndarray, matrices: np.ndarray,
                      estimated: PerspectiveCamera) -> tuple[np.ndarray, np.ndarray]:
    """The image lines of normals seen by each row's own camera (:func:`normals_to_lines`)
    and the normals the ``estimated`` camera gives them back
    (:meth:`PerspectiveCamera.line_to_normal`), in one C call when compiled (the same
    bits, ``vision/csrc/sensor_kernels.c``).

    Args:
        normals: (n, ..., 3) interpretation-plane normals of row ``k`` seen by camera ``k``.
        matrices: (n, 3, 3) each camera's :attr:`PerspectiveCamera.normal_to_line_matrix`.
        estimated: The camera the lines are lifted with.

    Returns:
        (n, ..., 3) unit lines and (n, ..., 3) unit normals.

    Raises:
        CameraError: ``matrices`` is not one (3, 3) per row.
    """
    from vision import kernels

    lib = kernels.library()
    fused = None if lib is None else _lines_mode(lib)
    n = as_points(normals, "normals")
    M = np.asarray(matrices, dtype=float)
    if fused is None or M.shape != (len(n), 3, 3):
        lines = normals_to_lines(n, M)
        return lines, estimated.line_to_normal(lines)
    return _lines_normals(lib, fused, n, M, estimated.line_matrix)


def _lines_normals(lib: Any, fused: int, normals: np.ndarray, matrices: np.ndarray,
                   line_matrix: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``hexapod_lines_normals`` of row-major float arrays."""
    n = np.ascontiguousarray(normals)
    M = np.ascontiguousarray(matrices)
    L = np.ascontiguousarray(line_matrix)
    lines, out = np.empty_like(n), np.empty_like(n)
    lib.hexapod_lines_normals(n.ctypes.data, len(n), n.size // (3 * max(len(n), 1)),
                              M.ctypes.data, L.ctypes.data, fused, lines.ctypes.data,
                              out.ctypes.data)
    return lines, out


def _lines_mode(lib: Any) -> int | None:
    """:func:`vision.kernels.blas_mode` of ``hexapod_lines_normals``, probed on random
    normals (one NaN) and cameras."""
    from vision import kernels

    def inputs() -> tuple[np.ndarray, np.ndarray, PerspectiveCamera]:
        rng = np.random.default_rng(8)
        normals = rng.normal(size=(8, 6, 2, 3))
        normals[2, 1, 0, 1] = np.nan
        K = np.array([[900.0, 0.0, 310.0], [0.0, 880.0, 250.0], [0.0, 0.0, 1.0]])
        cams = [PerspectiveCamera(K + rng.normal(size=(3, 3)) * [[9, 0, 9], [0, 9, 9], [0, 0, 0]],
                                  640, 480) for _ in range(9)]
        return normals, np.stack([c.normal_to_line_matrix for c in cams[:8]]), cams[8]

    def numpy_path() -> np.ndarray:
        normals, M, est = inputs()
        lines = normals_to_lines(normals, M)
        return np.stack([lines, est.line_to_normal(lines)])

    def compiled(fused: int) -> np.ndarray:
        normals, M, est = inputs()
        return np.stack(_lines_normals(lib, fused, normals, M, est.line_matrix))

    return kernels.blas_mode("hexapod_lines_normals", compiled, numpy_path)
