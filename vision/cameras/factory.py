"""Cameras from files, names and tables: the factory on top of the models.

:func:`load_camera` takes a preset name, a camera TOML file (the project's format,
:mod:`vision.cameras.files.project`) or a calibration file (:func:`read_calibration`:
OpenCV's ``FileStorage`` files, :mod:`vision.cameras.files.opencv`, fisheye
calibrations included; ROS ``camera_info`` files; Kalibr's ``camchain.yaml``,
:mod:`vision.cameras.files.kalibr`); :func:`read_camera` builds a camera of the right
model from a table (the reader :meth:`Camera.from_dict` uses, installed here). The
writers: :func:`save_opencv_camera`, :func:`save_ros_camera_info`,
:func:`save_kalibr_camera`. The models never import the file readers: this module
imports both.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from hexapod.config import check_keys
from hexapod.exceptions import ConfigFileError
from hexapod.geometry import HexapodGeometry
from hexapod.kinematics import Transform
from vision.cameras.base import Camera, install_table_io
from vision.cameras.fields import Calibration, CameraFields
from vision.cameras.files.kalibr import (
    is_camchain,
    load_yaml,
    read_kalibr_camchain,
    write_kalibr_camchain,
)
from vision.cameras.files.opencv import (
    OPENCV_EXTENSIONS,
    calibration_size,
    is_opencv_file,
    read_opencv_calibration,
    write_opencv_calibration,
)
from vision.cameras.files.project import (
    CAMERA_KEYS,
    OPENCV_TABLE_KEYS,
    camera_table,
    positive_int,
    read_camera_table,
    read_kind,
    read_pose_table,
)
from vision.cameras.files.ros import write_ros_camera_info
from vision.cameras.presets import PRESETS, camera_preset
from vision.exceptions import CameraError

log = logging.getLogger(__name__)


def read_camera(table: dict[str, Any], path: str = "<dict>",
                model: type[Camera] | None = None) -> Camera:
    """The camera of a table in the camera file format (see :meth:`Camera.from_dict`).

    Args:
        table: The parsed TOML table.
        path: The file, for the messages (and the base of a relative ``opencv`` path).
        model: The model being loaded (:meth:`PerspectiveCamera.from_toml`...): the
            table's ``kind`` defaults to it and must match it; None: any model.

    Raises:
        ConfigFileError: Missing, misspelt or unknown key, bad value (naming the key).
        CameraError: The camera is invalid.
    """
    spec = None if model is None else (model.kind, model.__name__)
    f = (read_opencv_table(table, path, spec) if "opencv" in table
         else read_camera_table(table, path, spec))
    return Camera.models[f.kind]._from_fields(f)


install_table_io(read_camera, camera_table)


def read_opencv_table(table: dict[str, Any], path: str,
                       model: tuple[str, str] | None) -> CameraFields:
    """A camera table whose intrinsics come from the OpenCV file named by ``opencv``."""
    for key in CAMERA_KEYS:
        if key in table and key not in OPENCV_TABLE_KEYS:
            raise ConfigFileError(path, f"the intrinsics come from the OpenCV file "
                                        f"{table['opencv']!r}: remove this key", key=key)
    check_keys(table, OPENCV_TABLE_KEYS, path)
    ref = table["opencv"]
    if not isinstance(ref, str) or not ref:
        raise ConfigFileError(path, f"expected the path of an OpenCV calibration file, got "
                                    f"{ref!r}", key="opencv")
    cal_path = Path(ref) if Path(ref).is_absolute() else Path(path).parent / ref
    if not cal_path.is_file():  # the full path tried, and the rule for relative paths
        rule = ("" if Path(ref).is_absolute() else " (a relative path is relative to the "
                f"folder of the camera file, {Path(path).parent.resolve()})")
        raise ConfigFileError(path, f"{ref!r}: file not found: tried {cal_path.resolve()}"
                              f"{rule}", key="opencv")
    cal = read_calibration(cal_path)
    file_kind = cal.kind
    kind = read_kind(table, path, model, file_kind)
    if kind != file_kind:
        raise ConfigFileError(path, f"kind {kind!r} but {cal_path} is a {file_kind} "
                                    "calibration", key="kind")
    given = None
    if "width_px" in table or "height_px" in table:
        for key in ("width_px", "height_px"):
            if key not in table:
                raise ConfigFileError(path, "missing (give width_px and height_px)", key=key)
        given = (positive_int(table, "width_px", path), positive_int(table, "height_px", path))
    width, height = calibration_size(cal, given, f"width_px and height_px in {path}")
    name = table.get("name", Path(path).stem)
    if not isinstance(name, str):
        raise ConfigFileError(path, f"expected a string, got {name!r}", key="name")
    return CameraFields(kind, cal.K, 0.0 if cal.xi is None else cal.xi, width, height,
                        read_pose_table(table, path), name, str(cal_path), cal.distortion)


def read_calibration(path: str | Path, camera: str | None = None) -> Calibration:
    """The intrinsics of a calibration file, whatever wrote it.

    A YAML file that is a Kalibr camera chain (blocks with ``camera_model``) is read by
    :func:`~vision.cameras.files.kalibr.read_kalibr_camchain` (``camera``: which block,
    the first by default); any other ``.yml``, ``.yaml``, ``.xml`` or ``.json`` file by
    :func:`~vision.cameras.files.opencv.read_opencv_calibration` (OpenCV's calibration
    samples and tutorial, ``cv::omnidir``, ``cv::fisheye``, ROS ``camera_info``).

    Raises:
        ConfigFileError: Unknown extension, missing file, missing or bad key, an
            unsupported model (naming the file and the key).
    """
    p = Path(path)
    if p.suffix.lower() in (".yml", ".yaml") and p.is_file():
        data = load_yaml(p)
        if is_camchain(data):
            return read_kalibr_camchain(p, data, camera)
    if camera is not None:
        raise ConfigFileError(str(p), f"camera {camera!r}: only a Kalibr camera chain names "
                                      "its cameras")
    return read_opencv_calibration(p)


def camera_from_calibration(cal: Calibration, camera_from_base: Transform | None = None,
                            image_size: tuple[int, int] | None = None,
                            name: str | None = None) -> Camera:
    """The camera of a calibration (:func:`read_calibration`), of the file's model.

    Raises:
        ConfigFileError: The file gives no image size and ``image_size`` is None, or
            they differ.
        CameraError: The camera is invalid (a lens parameter out of range...).
        DistortionError: The lens folds inside the image.
    """
    width, height = calibration_size(
        cal, image_size, "width_px and height_px", " beside it (in a scenario's [camera] "
        "table, or a camera file's table with opencv = ...; in Python, image_size=)")
    pose = Transform.identity() if camera_from_base is None else camera_from_base
    label = Path(cal.source).stem if name is None else name
    xi = 0.0 if cal.xi is None else cal.xi
    f = CameraFields(cal.kind, cal.K, xi, width, height, pose, label, cal.source,
                     cal.distortion)
    return Camera.models[cal.kind]._from_fields(f)


def _looks_like_path(path_or_name: str | Path) -> bool:
    """Whether ``path_or_name`` can only be a file, not a preset name: a :class:`Path`, or
    a string with a folder separator (``/``, ``\\``) or starting with ``~``."""
    if isinstance(path_or_name, Path):
        return True
    return "/" in path_or_name or "\\" in path_or_name or path_or_name.startswith("~")


def load_camera(path_or_name: str | Path, geometry: HexapodGeometry | None = None,
                camera_from_base: Transform | None = None,
                image_size: tuple[int, int] | None = None) -> Camera:
    """A camera preset, a camera TOML file or a calibration file.

    Args:
        path_or_name: A preset name (``"front"``, ``"omni"``), a TOML file
            (:meth:`Camera.to_toml`'s format; an existing file without extension is
            read as TOML) or a calibration file (``.yml``, ``.yaml``, ``.xml``,
            ``.json``: OpenCV, ROS ``camera_info`` or Kalibr ``camchain.yaml``,
            :func:`load_opencv_camera`).
        geometry: The robot, for the presets (their placement scales with it).
        camera_from_base: The pose of an OpenCV file's camera (identity by default);
            presets and TOML files give their own pose.
        image_size: ``(width, height)`` [px] of an OpenCV file that does not give it.

    Raises:
        CameraError: Unknown preset (with the close name), or a pose or image size
            given for a preset or a TOML file.
        ConfigFileError: Unknown extension, missing file (a name with a folder separator,
            or a :class:`Path`, is a file, never a preset), bad key or value.
        DistortionError: The distortion folds inside the image.
    """
    s = str(path_or_name)
    p = Path(s)
    if is_opencv_file(p):
        return load_opencv_camera(p, camera_from_base, image_size)
    for arg, value in (("camera_from_base", camera_from_base), ("image_size", image_size)):
        if value is not None:
            raise CameraError(arg, f"only for an OpenCV calibration file: {s!r} gives it")
    if s in PRESETS:
        return camera_preset(s, geometry)
    if p.suffix.lower() == ".toml" or (p.suffix == "" and (p.is_file()
                                                          or _looks_like_path(path_or_name))):
        return Camera.from_toml(p)  # a missing file: ConfigFileError "<path>: file not found"
    if p.suffix:
        raise ConfigFileError(s, f"unknown extension {p.suffix!r} for a camera file; "
                                 f"expected .toml or one of OpenCV's "
                                 f"{', '.join(OPENCV_EXTENSIONS)}")
    return camera_preset(s, geometry)


def load_opencv_camera(path: str | Path, camera_from_base: Transform | None = None,
                       image_size: tuple[int, int] | None = None,
                       name: str | None = None) -> Camera:
    """The camera of a calibration file (:func:`read_calibration`: OpenCV, ROS
    ``camera_info``, Kalibr).

    For OpenCV's files, ``camera_matrix`` and ``distortion_coefficients`` (or ``D``)
    give the intrinsics, ``xi`` makes it a :class:`UnifiedCamera` (Mei's model of
    ``cv::omnidir``), ``fisheye_model: 1`` or ROS's ``distortion_model: equidistant`` a
    :class:`FisheyeCamera`, ``image_width`` and ``image_height`` the image size. Kalibr's
    ``camera_model``/``distortion_model`` choose the model (``ds``: a
    :class:`DoubleSphereCamera`, ``eucm``: an :class:`ExtendedUnifiedCamera`).

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
    cal = read_calibration(path)
    return camera_from_calibration(cal, camera_from_base, image_size,
                                   Path(path).stem if name is None else name)


def save_opencv_camera(camera: Camera, path: str | Path) -> None:
    """Write the intrinsics of a camera as an OpenCV calibration file (``cv2.FileStorage``;
    YAML, XML or JSON after the extension), as OpenCV's calibration samples do.

    Keys ``image_width``, ``image_height``, ``camera_matrix``, ``distortion_coefficients``
    and, for a unified camera, ``xi``, for a fisheye ``fisheye_model: 1``. The pose is
    not written (OpenCV's files have none). ``cv2.projectPoints`` ignores the skew
    ``K[0, 1]`` of a perspective camera (``cv::omnidir`` uses it, ``cv::fisheye`` as
    ``alpha = K[0, 1] / fx``): a nonzero one is written, with a warning in the log.

    Raises:
        ConfigFileError: Unknown extension or the file cannot be written.
        CameraError: A model OpenCV does not have (double sphere, extended unified).
    """
    if camera.kind not in ("perspective", "unified", "fisheye"):
        raise CameraError("kind", f"OpenCV has no {camera.kind} model: save it as Kalibr's "
                                  "camchain.yaml (save_kalibr_camera) or a camera TOML file",
                          camera.source)
    if camera.kind == "perspective" and camera.K[0, 1] != 0:
        log.warning("%s: the skew K[0, 1] = %g is written, but cv2.projectPoints ignores it",
                    path, camera.K[0, 1])
    write_opencv_calibration(path, camera.K, camera.distortion, camera.width, camera.height,
                             camera.xi if camera.kind == "unified" else None,
                             fisheye=camera.kind == "fisheye")


def save_ros_camera_info(camera: Camera, path: str | Path) -> None:
    """Write the intrinsics of a camera as a ROS ``camera_info`` YAML file
    (:mod:`vision.cameras.files.ros`; ``plumb_bob``, ``rational_polynomial`` or
    ``equidistant``).

    Raises:
        ConfigFileError: The camera's model has no ROS ``distortion_model``.
    """
    write_ros_camera_info(path, camera.kind, camera.K, camera.distortion, camera.width,
                          camera.height, camera.name)


def save_kalibr_camera(camera: Camera, path: str | Path) -> None:
    """Write the intrinsics of a camera as Kalibr's ``camchain.yaml`` (one block,
    ``cam0``; :mod:`vision.cameras.files.kalibr`).

    Raises:
        ConfigFileError: The camera's model has no Kalibr form (OpenCV's full model,
            ``k3``, a skew), naming the field.
    """
    write_kalibr_camchain(path, camera.kind, camera.K, camera.distortion, camera.width,
                          camera.height, camera.xi if camera.kind == "unified" else None)
