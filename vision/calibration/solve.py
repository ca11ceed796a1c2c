"""The linear calibration of the base points (``docs/math.md`` section 7): one stacked
system per leg, least squares or IRLS, with its conditioning checked.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from vision.calibration.data import CalibrationData
from vision.exceptions import CalibrationError

log = logging.getLogger(__name__)

#: Default tuning constants (95 % efficiency under Gaussian noise) of the robust weights,
#: in units of the robust scale ``1.4826 * MAD`` of the residuals.
HUBER_K = 1.345
TUKEY_C = 4.685
#: Floor of the robust scale [m] (noise-free data have residuals of ~1e-17 m).
MIN_SCALE = 1e-12
#: Conditioning of a leg's system (smallest over largest singular value of its stacked
#: normals) below which the calibration warns: the point is poorly determined along one
#: direction (the viewing ray) and the noise is amplified about 1 / ratio times. The
#: weakest leg of the reference cases (reference robot, 15 mm legs, 64 extremal
#: configurations) has 0.0144 with the front camera and 0.054 with the omnidirectional
#: one; the default warns at a third of the former.
WARN_SINGULAR_RATIO = 5e-3
#: Conditioning below which the calibration refuses (:class:`CalibrationError`): ten
#: times weaker than the weakest reference case, i.e. ten times its noise amplification
#: (with 30 mm legs and the front camera, leg 4 has 0.0010, and its point came out up to
#: 75 mm wrong at 0.05 deg of noise).
MIN_SINGULAR_RATIO = 1.5e-3


Method = Literal["lstsq", "irls"]
Weight = Literal["huber", "tukey"]


@dataclass(frozen=True)
class BaseCalibration:
    """Result of :func:`calibrate_base_points` (all in the camera frame).

    Attributes:
        base_points: (6, 3) estimates of ``A_i`` [m].
        residuals: (N, 6, 2) ``n.A + r`` of each equation at the estimate [m]; NaN for
            hidden edges.
        weights: (N, 6, 2) final weights (1 for least squares; NaN for hidden edges).
        outliers: (N, 6, 2) equations flagged as outliers (IRLS): with Tukey, those
            beyond the threshold (weight 0); with Huber, those beyond the threshold
            times 4.685 / 1.345 (the Tukey rejection point; Huber still gives them the
            weight ``threshold / |r|``). All False for least squares.
        singular_values: (6, 3) singular values of each leg's stacked system
            (unweighted normals), largest first.
        equations: (6,) number of equations (visible edges) used per leg.
        configurations: (6,) number of configurations with a visible edge per leg.
        thresholds: (6,) robust thresholds [m] (NaN for least squares).
        iterations: (6,) IRLS iterations made (0 for least squares).
        method: ``"lstsq"`` or ``"irls"``.
        weight: The weight function (IRLS).
        radius: Leg radius used [m].
        warn_singular_ratio: The conditioning below which a leg counts as ill-conditioned.
    """

    base_points: np.ndarray
    residuals: np.ndarray
    weights: np.ndarray
    outliers: np.ndarray
    singular_values: np.ndarray
    equations: np.ndarray
    configurations: np.ndarray
    thresholds: np.ndarray
    iterations: np.ndarray
    method: str
    weight: str
    radius: float
    warn_singular_ratio: float = WARN_SINGULAR_RATIO

    @property
    def ill_conditioned_legs(self) -> list[int]:
        """Legs whose singular-value ratio is below :attr:`warn_singular_ratio`."""
        return [int(i) for i in np.flatnonzero(self.singular_value_ratio
                                               < self.warn_singular_ratio)]

    @property
    def smallest_singular_value(self) -> np.ndarray:
        """(6,) smallest singular value of each leg's system (dimensionless: unit normals)."""
        return self.singular_values[:, -1]

    @property
    def singular_value_ratio(self) -> np.ndarray:
        """(6,) smallest over largest singular value (1: perfectly conditioned)."""
        return self.singular_values[:, -1] / self.singular_values[:, 0]

    @property
    def residual_rms(self) -> np.ndarray:
        """(6,) RMS residual of each leg's equations [m] (outliers included)."""
        r = np.where(np.isfinite(self.residuals), self.residuals, 0.0)
        return np.sqrt(np.sum(r**2, axis=(0, 2)) / np.maximum(self.equations, 1))

    def to_dict(self) -> dict[str, Any]:
        """JSON-able summary (millimetres)."""
        return {
            "method": self.method,
            "weight": self.weight if self.method == "irls" else None,
            "leg_radius_mm": self.radius * 1e3,
            "base_points_mm": (self.base_points * 1e3).tolist(),
            "residual_rms_mm": (self.residual_rms * 1e3).tolist(),
            "smallest_singular_value": self.smallest_singular_value.tolist(),
            "singular_value_ratio": self.singular_value_ratio.tolist(),
            "warn_singular_ratio": self.warn_singular_ratio,
            "ill_conditioned_legs": self.ill_conditioned_legs,
            "singular_values": self.singular_values.tolist(),
            "equations": self.equations.tolist(),
            "configurations": self.configurations.tolist(),
            "outliers": self.outliers.sum(axis=(0, 2)).tolist(),
            "thresholds_mm": [None if not np.isfinite(x) else x * 1e3
                              for x in self.thresholds],
            "iterations": self.iterations.tolist(),
        }


def _robust_weights(r: np.ndarray, c: float, kind: str) -> np.ndarray:
    a = np.abs(r)
    if kind == "huber":
        return np.where(a <= c, 1.0, c / np.maximum(a, 1e-300))
    return np.where(a <= c, (1.0 - (a / c) ** 2) ** 2, 0.0)


def _irls(N: np.ndarray, b: np.ndarray, x0: np.ndarray, kind: str, threshold: float | None,
          max_iterations: int, tol: float) -> tuple[np.ndarray, np.ndarray, float, int]:
    """IRLS on ``N x = b``; Tukey starts from a Huber solution (its weights are not
    convex). Returns the solution, weights, threshold [m] and iterations."""
    x = x0
    it = 0
    phases = ["huber"] if kind == "huber" else ["huber", "tukey"]
    c = np.nan
    w = np.ones(len(b))
    for phase in phases:
        k = HUBER_K if phase == "huber" else TUKEY_C
        for _ in range(max_iterations):
            r = N @ x - b
            if threshold is None:
                scale = max(1.4826 * float(np.median(np.abs(r - np.median(r)))), MIN_SCALE)
                c = k * scale
            else:
                c = float(threshold)
            w = _robust_weights(r, c, phase)
            if np.count_nonzero(w > 0) < 3:
                break
            sw = np.sqrt(w)
            x_new = np.linalg.lstsq(N * sw[:, None], b * sw, rcond=None)[0]
            it += 1
            step = float(np.linalg.norm(x_new - x))
            x = x_new
            if step < tol:
                break
    w = _robust_weights(N @ x - b, c, phases[-1])
    return x, w, c, it


def calibrate_base_points(
    data: CalibrationData,
    radius: float,
    method: Method = "lstsq",
    weight: Weight = "tukey",
    threshold: float | None = None,
    min_singular_ratio: float = MIN_SINGULAR_RATIO,
    max_iterations: int = 50,
    tol: float = 1e-12,
    warn_singular_ratio: float = WARN_SINGULAR_RATIO,
    warn: bool = True,
) -> BaseCalibration:
    """Estimate the base points in the camera frame from leg-edge observations.

    For each leg, the visible edge normals ``n`` of every configuration are stacked
    into ``N A = -r 1`` and solved by least squares (``"lstsq"``) or by IRLS
    (``"irls"``) with Huber or Tukey weights on the residuals ``n.A + r`` [m].

    Robust threshold: ``threshold`` [m] if given, otherwise ``k * 1.4826 * MAD`` of
    the current residuals of the leg (``k = 1.345`` for Huber, ``4.685`` for Tukey,
    95 % efficiency under Gaussian noise). Tukey starts from the Huber solution.

    Tukey is the default: it gives gross outliers (a wrong edge) zero weight. Huber
    keeps a bounded pull from each of them, which the weakly observed depth of the
    point (along the viewing ray) amplifies: with 10 % of the normals rotated by 3 to
    10 deg (front camera, 0.01 deg noise), least squares is off by about 600 mm, Huber
    by 2 to 4 mm, Tukey by under 1 mm (``tests/vision/test_calibration.py``).

    Args:
        data: The observations.
        radius: Leg radius [m] (an error on it scales the estimates; see
            :func:`scale_correction`).
        method: ``"lstsq"`` or ``"irls"``.
        weight: ``"tukey"`` or ``"huber"`` (IRLS).
        threshold: Fixed robust threshold [m]; None for the MAD-based one.
        min_singular_ratio: A leg whose stacked system has smallest/largest singular
            value below this is refused (default :data:`MIN_SINGULAR_RATIO`).
        max_iterations: IRLS iteration budget per phase.
        tol: IRLS stop on the step norm [m].
        warn_singular_ratio: A leg below this ratio is logged as ill-conditioned (a
            warning) and listed by :meth:`BaseCalibration.ill_conditioned_legs`
            (default :data:`WARN_SINGULAR_RATIO`).
        warn: Log that warning (False: a caller that solves several candidates and
            reports the legs of the one it keeps, once).

    Returns:
        The :class:`BaseCalibration`.

    Raises:
        CalibrationError: A leg is seen in fewer than 2 configurations, or its system
            is too ill-conditioned (ratio below ``min_singular_ratio``: e.g. its
            directions nearly parallel, or only seen where its edges hardly turn).
        ValueError: Unknown method or weight, non-positive radius, bad thresholds.
    """
    if method not in ("lstsq", "irls"):
        raise ValueError(f"method: expected 'lstsq' or 'irls', got {method!r}")
    if weight not in ("huber", "tukey"):
        raise ValueError(f"weight: expected 'huber' or 'tukey', got {weight!r}")
    r = float(radius)
    if not np.isfinite(r) or r <= 0:
        raise ValueError(f"radius: must be positive and finite, got {radius!r} m")
    if threshold is not None and not threshold > 0:
        raise ValueError(f"threshold: must be positive, got {threshold!r} m")
    check_conditioning_thresholds(min_singular_ratio, warn_singular_ratio)
    n_conf = data.n_configurations
    points = np.empty((6, 3))
    residuals = np.full((n_conf, 6, 2), np.nan)
    weights = np.full((n_conf, 6, 2), np.nan)
    outliers = np.zeros((n_conf, 6, 2), dtype=bool)
    svals = np.empty((6, 3))
    n_eq = np.zeros(6, dtype=int)
    n_cfg = np.zeros(6, dtype=int)
    thresholds = np.full(6, np.nan)
    iterations = np.zeros(6, dtype=int)
    for leg in range(6):
        vis = data.edge_visible[:, leg, :]
        n_cfg[leg] = int(np.count_nonzero(vis.any(axis=1)))
        n_eq[leg] = int(np.count_nonzero(vis))
        N = data.normals[:, leg, :, :][vis]
        if n_cfg[leg] < 2:
            raise CalibrationError(
                leg, f"seen in {n_cfg[leg]} configuration(s) with a visible edge "
                f"({n_eq[leg]} equations); at least 2 configurations with different leg "
                "directions are needed", equations=int(n_eq[leg]),
                configurations=int(n_cfg[leg]))
        s = np.linalg.svd(N, compute_uv=False)
        s = np.pad(s, (0, 3 - len(s)))
        svals[leg] = s
        if s[2] < min_singular_ratio * s[0]:
            raise CalibrationError(
                leg, f"ill-conditioned (singular-value ratio {s[2] / s[0]:.2e} < "
                f"{min_singular_ratio:.2e}, the hard limit): its {n_cfg[leg]} configurations "
                f"do not determine the point (singular values {s[0]:.3e}, {s[1]:.3e}, "
                f"{s[2]:.3e}); add configurations where this leg is seen at other "
                "inclinations", singular_values=s,
                equations=int(n_eq[leg]), configurations=int(n_cfg[leg]))
        if s[2] < warn_singular_ratio * s[0] and warn:  # (listed in the result either way)
            log.warning("calibration: leg %d is ill-conditioned (singular-value ratio %.2e < "
                        "%.2e): its base point is poorly determined along one direction and "
                        "the noise is amplified about %.0f times", leg, s[2] / s[0],
                        warn_singular_ratio, s[0] / max(s[2], 1e-300))
        b = np.full(len(N), -r)
        x = np.linalg.lstsq(N, b, rcond=None)[0]
        w = np.ones(len(N))
        if method == "irls":
            x, w, thresholds[leg], iterations[leg] = _irls(N, b, x, weight, threshold,
                                                           max_iterations, tol)
            limit = thresholds[leg] * (1.0 if weight == "tukey" else TUKEY_C / HUBER_K)
            outliers[:, leg, :][vis] = np.abs(N @ x - b) > limit
        points[leg] = x
        residuals[:, leg, :][vis] = N @ x - b
        weights[:, leg, :][vis] = w
    return BaseCalibration(points, residuals, weights, outliers, svals, n_eq, n_cfg,
                           thresholds, iterations, method, weight, r, warn_singular_ratio)


def check_conditioning_thresholds(min_singular_ratio: float, warn_singular_ratio: float) -> None:
    """Check ``0 <= min_singular_ratio <= warn_singular_ratio < 1``.

    Raises:
        ValueError: Naming the threshold and its value.
    """
    for name, value in (("min_singular_ratio", min_singular_ratio),
                        ("warn_singular_ratio", warn_singular_ratio)):
        if not (isinstance(value, int | float) and np.isfinite(value) and 0 <= value < 1):
            raise ValueError(f"{name}: must be in [0, 1), got {value!r}")
    if min_singular_ratio > warn_singular_ratio:
        raise ValueError(f"min_singular_ratio ({min_singular_ratio}) must not exceed "
                         f"warn_singular_ratio ({warn_singular_ratio})")
