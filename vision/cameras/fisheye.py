"""OpenCV's fisheye camera (Kannala-Brandt, ``cv2.fisheye``; Kalibr's ``pinhole-equi``).

``p = K (theta_d (x, y) / r)`` with ``(x, y) = (X/Z, Y/Z)``, ``r = |(x, y)|``,
``theta = atan(r)`` and ``theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4
theta^8)``, as ``cv2.fisheye.projectPoints`` (whose skew ``alpha`` is ``K[0, 1] / fx``).
"""

from __future__ import annotations

from typing import ClassVar

from vision.cameras.radial import KannalaBrandt, RadialLens
from vision.cameras.radial_camera import RadialLensCamera


class FisheyeCamera(RadialLensCamera):
    """Kannala-Brandt fisheye camera, as ``cv2.fisheye``.

    A :class:`~vision.cameras.radial_camera.RadialLensCamera` whose lens is
    :class:`vision.cameras.radial.KannalaBrandt`.

    Its ``distortion`` is ``(k1, k2, k3, k4)`` (None: zeros, the equidistant lens);
    ``K[0, 1] = alpha fx`` is OpenCV's fisheye skew.
    """

    kind: ClassVar[str] = "fisheye"
    distortion_lengths: ClassVar[tuple[int, ...]] = (4,)
    lens_type: ClassVar[type[RadialLens]] = KannalaBrandt
    default_distortion: ClassVar[tuple[float, ...]] = (0.0, 0.0, 0.0, 0.0)
