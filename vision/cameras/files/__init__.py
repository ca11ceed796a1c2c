"""Camera files: the project's TOML format (:mod:`~vision.cameras.files.project`),
OpenCV's calibration files (:mod:`~vision.cameras.files.opencv`, which also reads ROS
``camera_info`` files; :mod:`~vision.cameras.files.ros` writes them) and Kalibr's
camera chains (:mod:`~vision.cameras.files.kalibr`).

The readers give the fields of a camera (:class:`vision.cameras.fields.CameraFields`
or the intrinsics of a calibration); they import no camera model
(:mod:`vision.cameras.factory` builds the cameras).
"""
