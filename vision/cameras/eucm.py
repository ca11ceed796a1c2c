"""The extended unified camera (Khomutenko, Garcia & Martinet, RA-L 2016; Kalibr's ``eucm``).

With ``d = sqrt(beta (X^2 + Y^2) + Z^2)``: ``p = K (X, Y) / (alpha d + (1 - alpha) Z)``
(Kalibr's intrinsics ``[alpha, beta, fu, fv, pu, pv]``).
"""

from __future__ import annotations

from typing import ClassVar

from vision.cameras.radial import ExtendedUnified, RadialLens
from vision.cameras.radial_camera import RadialLensCamera


class ExtendedUnifiedCamera(RadialLensCamera):
    """Extended unified camera (Khomutenko et al. 2016).

    A :class:`~vision.cameras.radial_camera.RadialLensCamera` whose lens is
    :class:`vision.cameras.radial.ExtendedUnified`.

    Its ``distortion`` is ``(alpha, beta)``, ``0 <= alpha <= 1``, ``beta > 0`` (None:
    ``(0, 1)``, the pinhole).
    """

    kind: ClassVar[str] = "eucm"
    distortion_lengths: ClassVar[tuple[int, ...]] = (2,)
    lens_type: ClassVar[type[RadialLens]] = ExtendedUnified
    default_distortion: ClassVar[tuple[float, ...]] = (0.0, 1.0)
