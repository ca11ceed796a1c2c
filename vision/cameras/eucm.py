"""The extended unified camera (Khomutenko, Garcia & Martinet, RA-L 2016; Kalibr's ``eucm``).

With ``d = sqrt(beta (X^2 + Y^2) + Z^2)``: ``p = K (X, Y) / (alpha d + (1 - alpha) Z)``
(Kalibr's intrinsics ``[alpha, beta, fu, fv, pu, pv]``).
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from hexapod.kinematics import Transform
from vision.cameras.lens import Lens
from vision.cameras.perspective import PerspectiveCamera
from vision.cameras.radial import ExtendedUnified


class ExtendedUnifiedCamera(PerspectiveCamera):
    """Extended unified camera (Khomutenko et al. 2016).

    Args:
        K: (3, 3) intrinsics [px].
        width: Image width [px].
        height: Image height [px].
        camera_from_base: Pose w.r.t. the robot base (identity by default).
        name: A label.
        source: File the camera was read from (for the messages).
        distortion: ``(alpha, beta)``, ``0 <= alpha <= 1``, ``beta > 0`` (None:
            ``(0, 1)``, the pinhole).

    Raises:
        CameraError: A field is invalid.
        DistortionError: The lens folds inside the image.

    A perspective camera whose lens is :class:`vision.cameras.radial.ExtendedUnified`: rays in
    front of the camera only (``Z > 0``); the ideal image (lines ``K^-T n``) is the
    pinhole's ``K (X/Z, Y/Z)``, which the perspective pipeline (renderer, tracker,
    calibration) uses with the lens as for any distortion.
    """

    kind: ClassVar[str] = "eucm"
    distortion_lengths: ClassVar[tuple[int, ...]] = (2,)

    def __init__(
        self,
        K: np.ndarray,
        width: int,
        height: int,
        camera_from_base: Transform | None = None,
        name: str = "eucm",
        source: str | None = None,
        distortion: Any = None,
    ) -> None:
        super().__init__(K, width, height, camera_from_base, name, source, distortion)

    def _make_lens(self, distortion: Any) -> tuple[Lens, np.ndarray]:
        default = np.array([0.0, 1.0])
        lens = ExtendedUnified(default if distortion is None else distortion, self.source)
        return lens, np.array(lens.coefficients)

    def lens_scaled(self, factor: float) -> PerspectiveCamera:
        """The camera itself (``factor`` 1) or, ignoring the lens (``factor`` 0), the
        pinhole camera of the same ``K`` (what a pipeline without this model uses).

        Raises:
            CameraError: Another factor (the lens has no partial form).
        """
        return self._scaled_to_pinhole(factor)
