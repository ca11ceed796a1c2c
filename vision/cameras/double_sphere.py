"""The double sphere camera (Usenko, Demmel & Cremers, 3DV 2018; Kalibr's ``ds``).

With ``d1 = |X|``, ``d2 = |(X, Y, xi d1 + Z)|``: ``p = K (X, Y) / (alpha d2 + (1 - alpha)
(xi d1 + Z))`` (Kalibr's intrinsics ``[xi, alpha, fu, fv, pu, pv]``).
"""

from __future__ import annotations

from typing import ClassVar

from vision.cameras.radial import DoubleSphere, RadialLens
from vision.cameras.radial_camera import RadialLensCamera


class DoubleSphereCamera(RadialLensCamera):
    """Double sphere camera (Usenko et al. 2018).

    A :class:`~vision.cameras.radial_camera.RadialLensCamera` whose lens is
    :class:`vision.cameras.radial.DoubleSphere`.

    Its ``distortion`` is ``(xi, alpha)``, ``-1 < xi < 1``, ``0 <= alpha <= 1`` (None:
    zeros, the pinhole).
    """

    kind: ClassVar[str] = "double_sphere"
    distortion_lengths: ClassVar[tuple[int, ...]] = (2,)
    lens_type: ClassVar[type[RadialLens]] = DoubleSphere
    default_distortion: ClassVar[tuple[float, ...]] = (0.0, 0.0)
