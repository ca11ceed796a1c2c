"""OpenCV's fisheye camera (Kannala-Brandt, ``cv2.fisheye``; Kalibr's ``pinhole-equi``).

``p = K (theta_d (x, y) / r)`` with ``(x, y) = (X/Z, Y/Z)``, ``r = |(x, y)|``,
``theta = atan(r)`` and ``theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4
theta^8)``, as ``cv2.fisheye.projectPoints`` (whose skew ``alpha`` is ``K[0, 1] / fx``).
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from hexapod.kinematics import Transform
from vision.cameras.lens import Lens
from vision.cameras.perspective import PerspectiveCamera
from vision.cameras.radial import KannalaBrandt


class FisheyeCamera(PerspectiveCamera):
    """Kannala-Brandt fisheye camera, as ``cv2.fisheye``.

    Args:
        K: (3, 3) intrinsics [px] (``K[0, 1] = alpha fx``: OpenCV's fisheye skew).
        width: Image width [px].
        height: Image height [px].
        camera_from_base: Pose w.r.t. the robot base (identity by default).
        name: A label.
        source: File the camera was read from (for the messages).
        distortion: ``(k1, k2, k3, k4)`` (None: zeros, the equidistant lens).

    Raises:
        CameraError: A field is invalid.
        DistortionError: The lens folds inside the image.

    A perspective camera whose lens is :class:`vision.cameras.radial.KannalaBrandt`: rays in
    front of the camera only (``Z > 0``); the ideal image (lines ``K^-T n``) is the
    pinhole's ``K (X/Z, Y/Z)``, which the perspective pipeline (renderer, tracker,
    calibration) uses with the lens as for any distortion.
    """

    kind: ClassVar[str] = "fisheye"
    distortion_lengths: ClassVar[tuple[int, ...]] = (4,)

    def __init__(
        self,
        K: np.ndarray,
        width: int,
        height: int,
        camera_from_base: Transform | None = None,
        name: str = "fisheye",
        source: str | None = None,
        distortion: Any = None,
    ) -> None:
        super().__init__(K, width, height, camera_from_base, name, source, distortion)

    def _make_lens(self, distortion: Any) -> tuple[Lens, np.ndarray]:
        lens = KannalaBrandt(np.zeros(4) if distortion is None else distortion, self.source)
        return lens, np.array(lens.coefficients)

    def lens_scaled(self, factor: float) -> PerspectiveCamera:
        """The camera itself (``factor`` 1) or, ignoring the lens (``factor`` 0), the
        pinhole camera of the same ``K`` (what a pipeline without this model uses).

        Raises:
            CameraError: Another factor (the lens has no partial form).
        """
        return self._scaled_to_pinhole(factor)
