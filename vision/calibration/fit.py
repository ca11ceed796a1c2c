"""After the linear solve: the rigid fit of the CAD base (camera pose), the scale correction
of a leg-radius error, and :func:`calibrate` which chains them.
"""

from __future__ import annotations

import itertools
import logging
from dataclasses import dataclass
from typing import Any

import numpy as np

from hexapod.exceptions import ShapeError
from hexapod.kinematics import Transform
from vision.calibration.data import CalibrationData
from vision.calibration.solve import (
    MIN_SINGULAR_RATIO,
    WARN_SINGULAR_RATIO,
    BaseCalibration,
    Method,
    Weight,
    calibrate_base_points,
)
from vision.exceptions import CalibrationError

log = logging.getLogger(__name__)

def rigid_fit(
    estimated: np.ndarray, cad: np.ndarray, with_scale: bool = False
) -> tuple[Transform, float, float]:
    """Fit the CAD base points to estimates (Kabsch, or Umeyama with a scale).

    Minimises ``sum_i |A_i - (s R bA_i + t)|^2`` over the rotation ``R``, the
    translation ``t`` and (``with_scale``) the scale ``s``.

    Args:
        estimated: (K, 3) estimated points in the camera frame [m] (K >= 3).
        cad: (K, 3) the same points in the base frame (CAD) [m].
        with_scale: Fit a scale too (else ``s = 1``).

    Returns:
        ``(camera_from_base, s, rms)``: the transform (rotation, translation [m]), the
        scale and the RMS distance of the fit [m].

    Raises:
        ShapeError: Mismatched shapes, fewer than 3 points or non-finite values.
        CalibrationError: The CAD points are collinear (the rotation is undetermined).
    """
    P = np.asarray(estimated, dtype=float)
    Q = np.asarray(cad, dtype=float)
    if P.ndim != 2 or P.shape[1] != 3 or P.shape != Q.shape or len(P) < 3:
        raise ShapeError("estimated/cad", "two (K, 3) arrays with K >= 3",
                         f"{P.shape} and {Q.shape}")
    if not (np.all(np.isfinite(P)) and np.all(np.isfinite(Q))):
        raise ShapeError("estimated/cad", "finite values", "NaN or inf")
    mp, mq = P.mean(axis=0), Q.mean(axis=0)
    Pc, Qc = P - mp, Q - mq
    H = Qc.T @ Pc / len(P)  # cross-covariance, cad -> estimated
    U, S, Vt = np.linalg.svd(H)
    if np.linalg.svd(Qc, compute_uv=False)[1] < 1e-9 * max(np.abs(Qc).max(), 1e-12):
        raise CalibrationError(None, "rigid fit: the CAD points are collinear",
                               singular_values=S)
    D = np.eye(3)
    if np.linalg.det(Vt.T @ U.T) < 0:
        D[2, 2] = -1.0
    R = Vt.T @ D @ U.T
    s = 1.0
    if with_scale:
        var_q = float(np.sum(Qc**2) / len(Q))
        s = float(np.trace(np.diag(S) @ D) / var_q)
    t = mp - s * R @ mq
    rms = float(np.sqrt(np.mean(np.sum((P - (s * Q @ R.T + t)) ** 2, axis=1))))
    return Transform(R, t), s, rms


def scale_correction(estimated: np.ndarray, cad: np.ndarray) -> float:
    """Scale of the estimates relative to the CAD (``docs/math.md`` section 7).

    ``s = mean_{j != k} |A_j - A_k| / |bA_j - bA_k|``. A relative error on the leg
    radius used in the linear system scales every estimate by the same factor about
    the projection centre; ``estimated / s`` corrects it (and ``radius / s`` is the
    corrected radius).

    Args:
        estimated: (K, 3) estimates [m].
        cad: (K, 3) CAD points [m].
    """
    P = np.asarray(estimated, dtype=float)
    Q = np.asarray(cad, dtype=float)
    if P.ndim != 2 or P.shape[1] != 3 or P.shape != Q.shape or len(P) < 2:
        raise ShapeError("estimated/cad", "two (K, 3) arrays with K >= 2",
                         f"{P.shape} and {Q.shape}")
    ratios = [np.linalg.norm(P[j] - P[k]) / np.linalg.norm(Q[j] - Q[k])
              for j, k in itertools.combinations(range(len(P)), 2)]
    return float(np.mean(ratios))


@dataclass(frozen=True)
class CalibrationResult:
    """Full calibration: linear estimates, scale, rigid fit.

    Attributes:
        base_points: (6, 3) calibrated base points in the camera frame [m] (the linear
            estimates, divided by ``scale`` when the scale was corrected).
        fitted_base_points: (6, 3) the CAD base placed by ``camera_from_base`` [m].
        camera_from_base: Rigid fit of the CAD base to ``base_points``.
        scale: Measured scale ``s`` of the raw estimates relative to the CAD.
        scale_corrected: Whether ``base_points`` were divided by ``scale``.
        radius: Leg radius, corrected when the scale was [m].
        fit_rms: RMS distance of the rigid fit [m].
        linear: The per-leg solution (:class:`BaseCalibration`).
    """

    base_points: np.ndarray
    fitted_base_points: np.ndarray
    camera_from_base: Transform
    scale: float
    scale_corrected: bool
    radius: float
    fit_rms: float
    linear: BaseCalibration

    def to_dict(self) -> dict[str, Any]:
        """JSON-able summary (millimetres, degrees)."""
        from hexapod.se3 import log_so3

        T = self.camera_from_base
        return {
            "base_points_mm": (self.base_points * 1e3).tolist(),
            "fitted_base_points_mm": (self.fitted_base_points * 1e3).tolist(),
            "camera_from_base": {
                "rotation": T.rotation.tolist(),
                "translation_mm": (T.translation * 1e3).tolist(),
                "rotation_vector_deg": np.rad2deg(log_so3(T.rotation)).tolist(),
            },
            "scale": self.scale,
            "scale_corrected": self.scale_corrected,
            "leg_radius_mm": self.radius * 1e3,
            "fit_rms_mm": self.fit_rms * 1e3,
            "linear": self.linear.to_dict(),
        }


#: The ratio of the estimated base to the CAD base a calibration accepts: a leg radius
#: known to a few percent gives a ratio as close to 1; 1000 or 0.001 is a unit slip.
#: Between, the fit itself says what is wrong (observations that agree with no base
#: point gave 0.11: the report's diagnosis, not a unit's).
SCALE_RANGE = (0.01, 100.0)


def calibrate(
    data: CalibrationData,
    radius: float,
    cad_base_points: np.ndarray,
    method: Method = "irls",
    weight: Weight = "tukey",
    threshold: float | None = None,
    correct_scale: bool = False,
    min_singular_ratio: float = MIN_SINGULAR_RATIO,
    warn_singular_ratio: float = WARN_SINGULAR_RATIO,
    warn: bool = True,
) -> CalibrationResult:
    """Linear calibration, optional scale correction and rigid fit of the CAD base.

    Args:
        data: The observations.
        radius: Nominal leg radius [m].
        cad_base_points: (6, 3) CAD base points in the base frame [m].
        method, weight, threshold, min_singular_ratio, warn_singular_ratio, warn: See
            :func:`calibrate_base_points`.
        correct_scale: Divide the estimates by :func:`scale_correction` (use it when
            the leg radius is uncertain; with the right radius it only adds noise).

    Returns:
        The :class:`CalibrationResult`.

    Raises:
        CalibrationError: As :func:`calibrate_base_points`, or an estimated base outside
            :data:`SCALE_RANGE` times the CAD base (the radius and the CAD in different
            units).
    """
    lin = calibrate_base_points(data, radius, method, weight, threshold, min_singular_ratio,
                                warn_singular_ratio=warn_singular_ratio, warn=warn)
    cad = np.asarray(cad_base_points, dtype=float)
    s = scale_correction(lin.base_points, cad)
    if not SCALE_RANGE[0] <= s <= SCALE_RANGE[1]:  # (an uncertain radius is a few %)
        raise CalibrationError(None, f"the estimated base is {s:.4g} times the CAD base: the "
                               f"leg radius ({radius:g} m) and the CAD base points (up to "
                               f"{float(np.abs(cad).max()):g} m from the origin) are not in "
                               "the same unit (millimetres for metres?): give both in metres")
    points = lin.base_points / s if correct_scale else lin.base_points
    T, _, rms = rigid_fit(points, cad)
    return CalibrationResult(points, T.apply(cad), T, s, correct_scale,
                             radius / s if correct_scale else float(radius), rms, lin)
