"""The unified central camera (Geyer-Daniilidis / Mei) with ``cv::omnidir``'s distortion.

The camera frame is the mirror (sphere) frame: x right, y down, z along the mirror
axis; pixels and ``K`` as for the perspective camera (:mod:`vision.cameras.perspective`),
``u = fx x_d + s y_d + cx`` as ``cv::omnidir::projectPoints``. ``UnifiedCamera`` with
``xi = 0`` gives bit-identical projections and lifts to the perspective camera.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from hexapod.kinematics import Transform
from vision.cameras import projection
from vision.cameras.base import Camera
from vision.cameras.checks import (
    as_points,
    check_K,
    check_pose,
    check_principal_point,
    check_size,
    check_xi,
)
from vision.cameras.fields import CameraFields


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
    family: ClassVar[str] = "unified"
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
        check_principal_point(self.K, self.width, self.height, source)
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
