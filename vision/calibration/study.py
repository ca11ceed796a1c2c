"""Errors against a known truth, the repeated calibration study of seed 001 and the per-trial
calibration of the benchmark.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any

import numpy as np

from hexapod.geometry import HexapodGeometry
from hexapod.kinematics import Transform
from vision.calibration.collect import (
    ConfigurationsSpec,
    collect_observations,
    collect_pixel_observations,
    rotation_noise,
)
from vision.calibration.data import CalibrationData
from vision.calibration.solve import (
    MIN_SINGULAR_RATIO,
    WARN_SINGULAR_RATIO,
    Method,
    Weight,
    calibrate_base_points,
)

log = logging.getLogger(__name__)

def point_errors(estimated: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Euclidean errors (..., 6) [m] of estimated points (..., 6, 3) against the truth."""
    return np.linalg.norm(np.asarray(estimated, float) - np.asarray(truth, float), axis=-1)


def error_summary(estimated: np.ndarray, truth: np.ndarray) -> dict[str, Any]:
    """Per-point and overall error statistics in millimetres (JSON-able).

    Args:
        estimated: (R, 6, 3) or (6, 3) estimates over R repetitions [m].
        truth: (6, 3) true points [m].

    Returns:
        ``median_error_mm`` and ``max_error_mm`` over all points and repetitions,
        ``per_point_median_mm`` / ``per_point_max_mm`` (6 each), the same for the
        largest absolute coordinate error (``*_component_*``, the measure of seed
        001), ``errors_mm`` (R x 6) and ``repetitions``.
    """
    est = np.asarray(estimated, float)
    if est.ndim == 2:
        est = est[None]
    d = est - np.asarray(truth, float)
    e = np.linalg.norm(d, axis=-1) * 1e3
    c = np.abs(d).max(axis=-1) * 1e3
    return {
        "repetitions": int(e.shape[0]),
        "median_error_mm": float(np.median(e)),
        "max_error_mm": float(np.max(e)),
        "per_point_median_mm": np.median(e, axis=0).tolist(),
        "per_point_max_mm": np.max(e, axis=0).tolist(),
        "median_component_error_mm": float(np.median(c)),
        "max_component_error_mm": float(np.max(c)),
        "per_point_max_component_mm": np.max(c, axis=0).tolist(),
        "errors_mm": e.tolist(),
    }


@dataclass(frozen=True)
class StudyResult:
    """Repeated calibrations at one noise level.

    Attributes:
        noise_deg: Rotation-noise amplitude [deg].
        estimates: (R, 6, 3) estimates [m].
        truth: (6, 3) true base points in the camera frame [m].
        smallest_singular_ratio: Worst conditioning over legs (noise-free system).
        method: Solver used.
    """

    noise_deg: float
    estimates: np.ndarray
    truth: np.ndarray
    smallest_singular_ratio: float
    method: str

    @property
    def errors(self) -> np.ndarray:
        """(R, 6) Euclidean errors [m]."""
        return point_errors(self.estimates, self.truth)

    @property
    def per_point_median(self) -> np.ndarray:
        """(6,) median error of each base point over the repetitions [m]."""
        return np.median(self.errors, axis=0)

    @property
    def per_point_max(self) -> np.ndarray:
        """(6,) maximal error of each base point over the repetitions [m]."""
        return np.max(self.errors, axis=0)

    def to_dict(self) -> dict[str, Any]:
        """JSON-able summary (millimetres)."""
        out = {"noise_deg": self.noise_deg, "method": self.method,
               "smallest_singular_ratio": self.smallest_singular_ratio}
        summary = error_summary(self.estimates, self.truth)
        summary.pop("errors_mm")
        out.update(summary)
        return out


def calibration_study(
    geometry: HexapodGeometry,
    camera_from_base: Transform | Any,
    noise_deg: float,
    repeats: int,
    rng: np.random.Generator | int | None = None,
    configurations: ConfigurationsSpec = "extremal",
    method: Method = "lstsq",
    weight: Weight = "tukey",
) -> StudyResult:
    """Repeat the calibration under rotation noise (seed 001, section 5.2).

    The configurations are fixed (the 64 extremal ones by default); each repetition
    draws new noise on every edge normal and solves again.

    Args:
        geometry: The true robot (also the nominal one: the radius is exact).
        camera_from_base: Transform or camera (see :func:`collect_observations`).
        noise_deg: Rotation-noise amplitude [deg].
        repeats: Number of repetitions.
        rng: Generator or seed.
        configurations: See :func:`configuration_poses`.
        method, weight: See :func:`calibrate_base_points`.
    """
    gen = np.random.default_rng(rng)
    exact = collect_observations(geometry, camera_from_base, configurations, rng=gen)
    T = camera_from_base if isinstance(camera_from_base, Transform) \
        else camera_from_base.camera_from_base
    truth = T.apply(geometry.base_points)
    ratio = float(calibrate_base_points(exact, geometry.leg_radius).singular_value_ratio.min())
    noise = rotation_noise(noise_deg)
    estimates = np.empty((repeats, 6, 3))
    for k in range(repeats):
        noisy = np.where(exact.edge_visible[..., None],
                         noise(np.nan_to_num(exact.normals), gen), np.nan)
        data = CalibrationData(noisy, exact.edge_visible, exact.lengths)
        estimates[k] = calibrate_base_points(data, geometry.leg_radius, method,
                                             weight).base_points
    return StudyResult(float(noise_deg), estimates, truth, ratio, method)


def simulated_observations(geometry: HexapodGeometry, camera: Any, calibration: Any,
                           noise: Any, rng: np.random.Generator) -> CalibrationData:
    """The calibration's observations simulated in a world, with the noise a study's
    calibration takes: the control images' pixel noise when the noise model is
    ``"pixel"`` and ``calibration.noise_deg`` is None (:func:`collect_pixel_observations`),
    else rotation noise of ``calibration.noise_deg`` [deg], or of the noise model's
    ``amplitude_deg`` (none for another model) (:func:`collect_observations`).

    Args:
        geometry: The TRUE robot.
        camera: The TRUE camera.
        calibration: The ``[calibration]`` settings (``configurations``, ``noise_deg``).
        noise: The ``[noise]`` settings (``model``, ``amplitude_deg``, the pixel model's
            ``pixel_sigma_px``, ``points_per_edge``, ``outlier_fraction``).
        rng: Generator (configurations and noise).
    """
    amplitude = calibration.noise_deg
    if amplitude is None and noise.model == "pixel":
        return collect_pixel_observations(geometry, camera, calibration.configurations,
                                          noise.pixel_sigma_px, noise.points_per_edge, rng,
                                          getattr(noise, "outlier_fraction", 0.0))
    if amplitude is None:
        amplitude = noise.amplitude_deg if noise.model == "rotation" else 0.0
    model = rotation_noise(float(amplitude)) if amplitude else None
    return collect_observations(geometry, camera, calibration.configurations, model, rng)


def calibrate_in_world(
    geometry: HexapodGeometry,
    camera: Any,
    calibration: Any,
    noise: Any,
    rng: np.random.Generator,
    data: CalibrationData | None = None,
) -> tuple[np.ndarray, dict[str, float]]:
    """Calibrate the base points in a simulated world (the benchmark's scenario option).

    Args:
        geometry: The TRUE robot (makes the images). The nominal leg radius is taken
            equal to it.
        camera: The TRUE camera (:class:`vision.cameras.Camera`; visibility and
            occlusions from :func:`vision.legs.observe_legs`).
        calibration: The scenario's ``[calibration]`` settings (attributes
            ``configurations`` = ``"extremal"`` or ``"random:N"``, ``solver`` =
            ``"lstsq"`` or ``"irls"``, ``noise_deg`` [deg] or None).
        noise: The scenario's ``[noise]`` settings (``model``, ``amplitude_deg``), used
            when ``calibration.noise_deg`` is None.
        rng: Generator (configurations and noise).
        data: Observations measured elsewhere (rendered images:
            :func:`vision.calibration.collect.collect_image_observations`), used as they
            are; None: simulated here with ``noise``.

    Returns:
        The estimated base points (6, 3) in the true camera frame [m], and a summary
        (``median_error_mm``, ``max_error_mm`` against the truth, per point,
        ``max_component_error_mm``, the largest error on one coordinate,
        ``min_singular_ratio``, ``ill_conditioned_legs`` (how many legs are below the
        warning threshold ``calibration.warn_singular_ratio``), ``outliers``,
        ``configurations``).

    Raises:
        CalibrationError: A leg below ``calibration.min_singular_ratio`` (or never seen).

    With the pixel noise model (and no ``noise_deg``) the calibration images get
    the same pixel noise as the control images (:func:`collect_pixel_observations`).
    """
    if data is None:
        data = simulated_observations(geometry, camera, calibration, noise, rng)
    res = calibrate_base_points(
        data, geometry.leg_radius, calibration.solver,
        min_singular_ratio=getattr(calibration, "min_singular_ratio", MIN_SINGULAR_RATIO),
        warn_singular_ratio=getattr(calibration, "warn_singular_ratio", WARN_SINGULAR_RATIO))
    truth = camera.camera_from_base.apply(geometry.base_points)
    err = point_errors(res.base_points, truth) * 1e3
    return res.base_points, {
        "median_error_mm": float(np.median(err)),
        "max_error_mm": float(np.max(err)),
        # seed 001's measure: the largest error on any coordinate of any point
        "max_component_error_mm": float(np.max(np.abs(res.base_points - truth))) * 1e3,
        "min_singular_ratio": float(res.singular_value_ratio.min()),
        "ill_conditioned_legs": float(len(res.ill_conditioned_legs)),
        "outliers": float(res.outliers.sum()),
        "configurations": float(data.n_configurations),
    }
