"""Linear calibration of the base points from images of the legs (``docs/math.md`` section 7).

Each measured edge normal ``n`` of leg ``i`` satisfies ``n.A_i = -r`` (section 4),
whatever the platform pose. Stacking the visible edges of leg ``i`` over N
configurations gives the ``2N x 3`` linear system ``[n^T] A_i = -r 1``, solved per
leg by least squares or by iteratively reweighted least squares (Huber or Tukey
weights). It determines ``A_i`` (in the camera frame) once two configurations give
different leg directions; its smallest singular value says how well.

Then, optionally:

- the rigid fit (Kabsch/Umeyama) of the CAD base to the estimates gives
  ``camera_from_base``;
- an error on the leg radius scales every estimate about the projection centre;
  ``s = mean_{j != k} |A_j - A_k| / |bA_j - bA_k|`` measures it and ``A / s``
  corrects it.

Observations come from a simulation (:func:`collect_observations`) or from a file
that a user provides (:meth:`CalibrationData.load`, JSON or NPZ, leg lengths in
millimetres). Lengths are in metres inside the code, millimetres in files and
reports.
"""

from vision.calibration.collect import (
    ConfigurationsSpec,
    NoiseFunction,
    collect_image_observations,
    collect_observations,
    collect_pixel_observations,
    configuration_poses,
    rotation_noise,
)
from vision.calibration.data import FILE_FORMAT, UNIT_TOLERANCE, CalibrationData
from vision.calibration.fit import CalibrationResult, calibrate, rigid_fit, scale_correction
from vision.calibration.solve import (
    HUBER_K,
    MIN_SCALE,
    MIN_SINGULAR_RATIO,
    TUKEY_C,
    WARN_SINGULAR_RATIO,
    BaseCalibration,
    Method,
    Weight,
    calibrate_base_points,
    check_conditioning_thresholds,
)
from vision.calibration.study import (
    StudyResult,
    calibrate_in_world,
    calibration_study,
    error_summary,
    point_errors,
)

__all__ = [
    "FILE_FORMAT", "HUBER_K", "MIN_SCALE", "MIN_SINGULAR_RATIO", "TUKEY_C", "UNIT_TOLERANCE",
    "WARN_SINGULAR_RATIO", "BaseCalibration", "CalibrationData", "CalibrationResult",
    "ConfigurationsSpec", "Method", "NoiseFunction", "StudyResult", "Weight", "calibrate",
    "calibrate_base_points", "calibrate_in_world", "calibration_study",
    "check_conditioning_thresholds", "collect_image_observations", "collect_observations",
    "collect_pixel_observations",
    "configuration_poses", "error_summary", "point_errors", "rigid_fit", "rotation_noise",
    "scale_correction",
]
