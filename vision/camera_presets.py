"""Camera presets of the seeds: the front perspective camera and the omnidirectional one
(``docs/math.md`` section 9); :func:`load_camera` (a preset name, a TOML file or an
OpenCV calibration file) and the OpenCV calibration files of a camera."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from hexapod.config import suggest
from hexapod.exceptions import ConfigFileError
from hexapod.geometry import HexapodGeometry, deltalab
from hexapod.kinematics import Transform
from hexapod.se3 import look_at
from vision.cameras import Camera, PerspectiveCamera, UnifiedCamera
from vision.exceptions import CameraError
from vision.opencv_files import (
    OPENCV_EXTENSIONS,
    calibration_size,
    is_opencv_file,
    read_opencv_calibration,
    write_opencv_calibration,
)

log = logging.getLogger(__name__)

#: Pixel size assumed for the front camera preset [m] (a 1/3" 1024x768-class CCD,
#: e.g. Sony ICX204: 4.65 um square pixels).
FRONT_PIXEL_SIZE = 4.65e-6
#: Focal length of the front camera lens [m] (seed 002).
FRONT_FOCAL_LENGTH = 4.8e-3


def _intrinsics(f: float, width: int, height: int) -> np.ndarray:
    return np.array([[f, 0.0, (width - 1) / 2.0], [0.0, f, (height - 1) / 2.0], [0.0, 0.0, 1.0]])


def _pose_looking_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray) -> Transform:
    base_R_cam = look_at(eye, target, up)
    return Transform(base_R_cam, np.asarray(eye, float)).inverse()


#: Front camera placement for the reference robot: horizontal distance from the base
#: centre [m], azimuth from the base x axis [deg], height of the projection centre
#: [m] and height of the aim point on the base z axis [m].
FRONT_DISTANCE = 0.80
FRONT_AZIMUTH_DEG = 30.0
FRONT_EYE_HEIGHT = 0.0
FRONT_TARGET_HEIGHT = 0.265


def front_camera(geometry: HexapodGeometry | None = None) -> PerspectiveCamera:
    """The front perspective camera of seed 002 (``docs/math.md`` section 9).

    Intrinsics: 4.8 mm lens on a 1024x780 sensor with 4.65 um square pixels
    (``f = 4.8 / 0.00465 = 1032.26 px``, horizontal field of view 53 deg),
    principal point at the image centre ``(511.5, 389.5)``, no skew.

    Placement (reference robot): projection centre 0.80 m from the base centre,
    horizontally, at azimuth 30 deg (between the base joint pair at 0 deg and the
    platform joint pair at 60 deg) and at the height of the base joints, aimed at
    the point of the base axis 0.265 m high, image rows vertical. The seed says
    "about 0.7 m"; at 0.70 m the nearest legs (0.45 m tall, 0.45 m away) cannot fit
    in the 780-pixel height with this lens, at 0.80 m every leg stays entirely inside
    the image over the workspace of :func:`hexapod.sample_poses` (at least 2 pixels
    of margin on 4,000 random poses, checked by the tests). From there, legs hide
    one another in part of the workspace (about 17 % of the random poses have at
    least one hidden edge), as in the seed. For another geometry the placement is
    scaled by the base radius (distance) and the home height (aim point).
    """
    geo = deltalab() if geometry is None else geometry
    scale = float(np.max(np.linalg.norm(geo.base_points[:, :2], axis=1))) / 0.270
    zscale = geo.home_height / 0.3594098
    zbase = float(np.mean(geo.base_points[:, 2]))
    f = FRONT_FOCAL_LENGTH / FRONT_PIXEL_SIZE
    K = _intrinsics(f, 1024, 780)
    a = np.deg2rad(FRONT_AZIMUTH_DEG)
    d = FRONT_DISTANCE * scale
    eye = np.array([d * np.cos(a), d * np.sin(a), zbase + FRONT_EYE_HEIGHT * zscale])
    target = np.array([0.0, 0.0, zbase + FRONT_TARGET_HEIGHT * zscale])
    pose = _pose_looking_at(eye, target, np.array([0.0, 0.0, 1.0]))
    return PerspectiveCamera(K, 1024, 780, pose, name="front")


#: Generalised focal length of the omnidirectional preset [px].
OMNI_FOCAL = 200.0

#: A typical calibrated distortion of the front camera's 4.8 mm lens, OpenCV's
#: ``(k1, k2, p1, p2, k3)``: a strong barrel (``k1 = -0.28``: the image corners are
#: about 87 px nearer the centre than through an ideal lens), small decentring terms;
#: no fold inside (or near) the image (the Jacobian determinant of the distortion is
#: still 0.6 at the corners). For the tests and
#: benchmarks of the distorted image pipeline:
#: ``front_camera().replace(distortion=FRONT_DISTORTION)``.
FRONT_DISTORTION = (-0.28, 0.09, 5e-4, -3e-4, -0.012)

#: A mild Mei distortion of the omnidirectional preset, ``cv::omnidir``'s
#: ``(k1, k2, p1, p2)`` (the decentring terms break the rotational symmetry of the
#: image about the principal point; no fold: the radial derivative of the
#: distortion stays above 0.76):
#: ``omni_camera().replace(distortion=OMNI_DISTORTION)``.
OMNI_DISTORTION = (-0.08, 0.012, 4e-4, -2e-4)


def omni_camera(geometry: HexapodGeometry | None = None) -> UnifiedCamera:
    """The omnidirectional camera of seed 003 (``docs/math.md`` section 9).

    Parabolic mirror with an orthographic lens (``xi = 1``), 640x480 image,
    generalised focal length 200 px, principal point at the image centre
    ``(319.5, 239.5)``; the mirror (sphere) centre is at the centre of the base
    joint circle, its axis along the base z axis (looking up at the platform),
    camera x = base x, camera y = base y.

    With this focal length a point at the height of the base joints is imaged on
    the circle of radius 200 px and every leg of the reference robot crosses the
    whole annulus of diameters 184 to 370 px over the workspace (its base end is
    beyond 193 px, its platform end within 89 px of the image centre), as in
    seed 003; no leg hides another one enough to lose an edge.
    """
    geo = deltalab() if geometry is None else geometry
    centre = np.mean(geo.base_points, axis=0).round(12) + 0.0
    K = _intrinsics(OMNI_FOCAL, 640, 480)
    return UnifiedCamera(K, 1.0, 640, 480, Transform(np.eye(3), -centre), name="omni")


_PRESETS = {"front": front_camera, "omni": omni_camera}


def camera_preset(name: str, geometry: HexapodGeometry | None = None) -> Camera:
    """A camera preset by name: ``"front"`` (perspective) or ``"omni"`` (unified).

    Raises:
        CameraError: Unknown name (with the close valid name, if any).
    """
    if name not in _PRESETS:
        hint = suggest(name, _PRESETS)
        raise CameraError(
            "preset",
            f"unknown camera preset '{name}'; available: {', '.join(_PRESETS)}"
            + (f" (did you mean '{hint}'?)" if hint else ""),
        )
    return _PRESETS[name](geometry)


def load_camera(path_or_name: str | Path, geometry: HexapodGeometry | None = None,
                camera_from_base: Transform | None = None,
                image_size: tuple[int, int] | None = None) -> Camera:
    """A camera preset, a camera TOML file or an OpenCV calibration file.

    Args:
        path_or_name: A preset name (``"front"``, ``"omni"``), a TOML file
            (:meth:`Camera.to_toml`'s format; an existing file without extension is
            read as TOML) or an OpenCV calibration file (``.yml``, ``.yaml``, ``.xml``,
            ``.json``: :func:`load_opencv_camera`).
        geometry: The robot, for the presets (their placement scales with it).
        camera_from_base: The pose of an OpenCV file's camera (identity by default);
            presets and TOML files give their own pose.
        image_size: ``(width, height)`` [px] of an OpenCV file that does not give it.

    Raises:
        CameraError: Unknown preset (with the close name), or a pose or image size
            given for a preset or a TOML file.
        ConfigFileError: Unknown extension, missing file, bad key or value.
        DistortionError: The distortion folds inside the image.
    """
    s = str(path_or_name)
    p = Path(s)
    if is_opencv_file(p):
        return load_opencv_camera(p, camera_from_base, image_size)
    for arg, value in (("camera_from_base", camera_from_base), ("image_size", image_size)):
        if value is not None:
            raise CameraError(arg, f"only for an OpenCV calibration file: {s!r} gives it")
    if s in _PRESETS:
        return camera_preset(s, geometry)
    if p.suffix.lower() == ".toml" or (p.suffix == "" and p.is_file()):
        return Camera.from_toml(p)
    if p.suffix:
        raise ConfigFileError(s, f"unknown extension {p.suffix!r} for a camera file; "
                                 f"expected .toml or one of OpenCV's "
                                 f"{', '.join(OPENCV_EXTENSIONS)}")
    return camera_preset(s, geometry)


def load_opencv_camera(path: str | Path, camera_from_base: Transform | None = None,
                       image_size: tuple[int, int] | None = None,
                       name: str | None = None) -> Camera:
    """The camera of an OpenCV calibration file (:mod:`vision.opencv_files`).

    ``camera_matrix`` and ``distortion_coefficients`` (or ``D``) give the intrinsics,
    ``xi`` makes it a :class:`UnifiedCamera` (Mei's model of ``cv::omnidir``),
    ``image_width`` and ``image_height`` the image size.

    Args:
        path: The file (``.yml``, ``.yaml``, ``.xml``, ``.json``).
        camera_from_base: Its pose w.r.t. the robot base (not in the file; identity by
            default).
        image_size: ``(width, height)`` [px] when the file does not give it.
        name: A label (the file's stem by default).

    Raises:
        ConfigFileError: Unknown extension, missing file, missing key, value of the
            wrong shape or type (naming the file and the key).
        DistortionError: The distortion folds inside the image.
    """
    cal = read_opencv_calibration(path)
    width, height = calibration_size(cal, image_size, "image_size")
    pose = Transform.identity() if camera_from_base is None else camera_from_base
    label = Path(path).stem if name is None else name
    if cal.xi is None:
        return PerspectiveCamera(cal.K, width, height, pose, name=label, source=cal.source,
                                 distortion=cal.distortion)
    return UnifiedCamera(cal.K, cal.xi, width, height, pose, name=label, source=cal.source,
                         distortion=cal.distortion)


def save_opencv_camera(camera: Camera, path: str | Path) -> None:
    """Write the intrinsics of a camera as an OpenCV calibration file (``cv2.FileStorage``;
    YAML, XML or JSON after the extension), as OpenCV's calibration samples do.

    Keys ``image_width``, ``image_height``, ``camera_matrix``, ``distortion_coefficients``
    and, for a unified camera, ``xi``. The pose is not written (OpenCV's files have
    none). ``cv2.projectPoints`` ignores the skew ``K[0, 1]`` of a perspective camera
    (``cv::omnidir`` uses it): a nonzero one is written, with a warning in the log.

    Raises:
        ConfigFileError: Unknown extension or the file cannot be written.
    """
    if camera.kind == "perspective" and camera.K[0, 1] != 0:
        log.warning("%s: the skew K[0, 1] = %g is written, but cv2.projectPoints ignores it",
                    path, camera.K[0, 1])
    write_opencv_calibration(path, camera.K, camera.distortion, camera.width, camera.height,
                             camera.xi if camera.kind == "unified" else None)
