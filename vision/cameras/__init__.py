"""Camera models: perspective (pinhole) with OpenCV's lens distortion (5 to 14
coefficients), unified central (Geyer-Daniilidis / Mei), OpenCV's fisheye
(Kannala-Brandt), double sphere and extended unified.

Conventions (``docs/math.md`` section 5):

- Camera frame: x right, y down, z forward (perspective) or along the mirror axis
  (unified). For the unified model the camera frame is the mirror (sphere) frame.
- Pixel coordinates follow OpenCV: ``(u, v)`` with ``u`` along the image columns
  and ``v`` along the rows; the centre of the pixel in column ``i`` and row ``j``
  is at ``(i, j)``, so the image covers ``[-0.5, width - 0.5] x [-0.5, height - 0.5]``.
- ``K = [[fx, s, cx], [0, fy, cy], [0, 0, 1]]`` maps the distorted normalised point
  ``m_d = D(m)`` to the pixel ``p = K m_d``; ``m`` is the normalised point of the
  projection (:mod:`vision.cameras.projection`), ``D`` the lens distortion
  (:mod:`vision.cameras.distortion`, OpenCV's ``(k1, k2, p1, p2[, k3])``; the identity
  for an ideal lens). The *ideal image* is the one of ``K m`` (no distortion): the
  lines and conics of the leg edges are defined on it.
- Each camera has a fixed pose with respect to the robot base,
  ``camera_from_base``: ``p_camera = R p_base + t``.

The perspective camera is the unified one with ``xi = 0``; ``UnifiedCamera`` with
``xi = 0`` gives bit-identical projections and lifts. ``PerspectiveCamera`` projects
as ``cv2.projectPoints`` (which ignores the skew ``K[0, 1]``: equal when it is 0, as
``cv2.calibrateCamera`` gives), ``UnifiedCamera`` as ``cv::omnidir::projectPoints``
(``u = fx x_d + s y_d + cx``).

Layout, imports one way (each module imports only those above it):

- :mod:`~vision.cameras.checks`, :mod:`~vision.cameras.fields`: validation, the
  fields a file gives;
- :mod:`~vision.cameras.projection`, :mod:`~vision.cameras.distortion`: the maths;
- :mod:`~vision.cameras.base`: the common base :class:`Camera`;
- :mod:`~vision.cameras.lens` (the base of the lens maps and the fold check),
  :mod:`~vision.cameras.distortion` (OpenCV's five coefficients),
  :mod:`~vision.cameras.distortion_full` (its 14), :mod:`~vision.cameras.radial`
  (Kannala-Brandt, double sphere, extended unified as radial lens maps);
- one module per model: :mod:`~vision.cameras.perspective`,
  :mod:`~vision.cameras.unified`, and on the common base of the radial lenses
  (:mod:`~vision.cameras.radial_camera`) :mod:`~vision.cameras.fisheye`,
  :mod:`~vision.cameras.double_sphere`, :mod:`~vision.cameras.eucm`;
- :mod:`~vision.cameras.presets`: the cameras of the seeds;
- :mod:`vision.cameras.files`: the file formats (project TOML, OpenCV FileStorage,
  ROS camera_info, Kalibr camchain), which import no model;
- :mod:`~vision.cameras.factory`: cameras from names, files and tables.
"""

from vision.cameras.base import Camera
from vision.cameras.double_sphere import DoubleSphereCamera
from vision.cameras.eucm import ExtendedUnifiedCamera
from vision.cameras.factory import (
    camera_from_calibration,
    load_camera,
    load_opencv_camera,
    read_calibration,
    read_camera,
    save_kalibr_camera,
    save_opencv_camera,
    save_ros_camera_info,
)
from vision.cameras.fisheye import FisheyeCamera
from vision.cameras.perspective import PerspectiveCamera
from vision.cameras.presets import (
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
    fisheye_camera,
    front_camera,
    omni_camera,
)
from vision.cameras.unified import UnifiedCamera

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
    "DoubleSphereCamera",
    "ExtendedUnifiedCamera",
    "FisheyeCamera",
    "PerspectiveCamera",
    "UnifiedCamera",
    "camera_from_calibration",
    "camera_preset",
    "fisheye_camera",
    "front_camera",
    "load_camera",
    "load_opencv_camera",
    "omni_camera",
    "read_calibration",
    "read_camera",
    "save_kalibr_camera",
    "save_opencv_camera",
    "save_ros_camera_info",
]
