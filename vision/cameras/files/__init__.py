"""Camera files: the project's TOML format (:mod:`~vision.cameras.files.project`) and
OpenCV's calibration files (:mod:`~vision.cameras.files.opencv`).

The readers give the fields of a camera (:class:`vision.cameras.fields.CameraFields`
or the intrinsics of a calibration); they import no camera model
(:mod:`vision.cameras.factory` builds the cameras).
"""
