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

from __future__ import annotations

import itertools
import json
import logging
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from hexapod.exceptions import ConfigFileError, ShapeError
from hexapod.geometry import HexapodGeometry
from hexapod.kinematics import Transform, legs_in_frame
from hexapod.workspace import extremal_configurations, sample_poses
from vision import noise as vision_noise
from vision.exceptions import CalibrationError
from vision.legs import leg_edges

log = logging.getLogger(__name__)

#: A noise model on edge normals: ``(normals (..., 3), rng) -> noisy normals``.
NoiseFunction = Callable[[np.ndarray, np.random.Generator], np.ndarray]

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
#: Tolerance on the norm of the normals read from a file.
UNIT_TOLERANCE = 1e-6

FILE_FORMAT = "hexapod-leg-edge-observations"


# ============================================================================
# Observations
# ============================================================================


@dataclass(frozen=True)
class CalibrationData:
    """Leg-edge observations over N robot configurations (all in the camera frame).

    Attributes:
        normals: (N, 6, 2, 3) unit edge normals (convention of :func:`vision.legs.leg_edges`);
            any value (e.g. NaN) where the edge is not visible.
        edge_visible: (N, 6, 2) whether each edge was observed.
        lengths: (N, 6) measured leg lengths [m] (not used by the linear system; kept
            with the images they go with).
        source: File the data were read from, if any.
    """

    normals: np.ndarray
    edge_visible: np.ndarray
    lengths: np.ndarray
    source: str | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        n = np.asarray(self.normals, dtype=float)
        if n.ndim != 4 or n.shape[1:] != (6, 2, 3):
            raise ShapeError("normals", "shape (N, 6, 2, 3)", n.shape)
        vis = np.asarray(self.edge_visible, dtype=bool)
        if vis.shape != n.shape[:3]:
            raise ShapeError("edge_visible", f"shape {n.shape[:3]}", vis.shape)
        q = np.asarray(self.lengths, dtype=float)
        if q.shape != n.shape[:2]:
            raise ShapeError("lengths", f"shape {n.shape[:2]}", q.shape)
        vis = vis & np.all(np.isfinite(n), axis=-1)
        object.__setattr__(self, "normals", n)
        object.__setattr__(self, "edge_visible", vis)
        object.__setattr__(self, "lengths", q)

    @property
    def n_configurations(self) -> int:
        """Number of configurations N."""
        return int(self.normals.shape[0])

    def take(self, indices: Sequence[int] | np.ndarray) -> CalibrationData:
        """The observations of some configurations (in the given order)."""
        idx = np.asarray(indices, dtype=int)
        return CalibrationData(self.normals[idx], self.edge_visible[idx], self.lengths[idx],
                               self.source)

    # --------------------------------------------------------------- files
    def to_dict(self) -> dict[str, Any]:
        """JSON-able file representation (hidden edges as ``null``, lengths in mm)."""
        normals: list[Any] = np.where(self.edge_visible[..., None], self.normals,
                                      np.nan).tolist()
        normals = _nan_to_none(normals)
        return {
            "format": FILE_FORMAT,
            "version": 1,
            "normals": normals,
            "edge_visible": self.edge_visible.tolist(),
            "lengths_mm": (self.lengths * 1e3).tolist(),
        }

    def save(self, path: str | Path) -> None:
        """Save to ``.json`` or ``.npz`` (by the suffix), lengths in millimetres."""
        p = Path(path)
        if p.suffix == ".json":
            p.write_text(json.dumps(self.to_dict()))
        elif p.suffix == ".npz":
            np.savez(p, normals=self.normals, edge_visible=self.edge_visible,
                     lengths_mm=self.lengths * 1e3)
        else:
            raise ConfigFileError(str(p), "unknown file type; use .json or .npz")

    @classmethod
    def from_dict(cls, table: Mapping[str, Any], path: str = "<dict>") -> CalibrationData:
        """Build from the file representation.

        Keys: ``normals`` (N x 6 x 2 x 3, ``null`` (or three) for a hidden edge), ``lengths_mm``
        (N x 6) and optionally ``edge_visible`` (N x 6 x 2 booleans; default: the
        edges whose normal is given), ``format`` and ``version``.

        Raises:
            ConfigFileError: Missing, misspelt or malformed field (named in the message).
        """
        from hexapod.config import check_keys

        check_keys(table, ("format", "version", "normals", "edge_visible", "lengths_mm"), path,
                   required=("normals", "lengths_mm"))
        if "format" in table and table["format"] != FILE_FORMAT:
            raise ConfigFileError(path, f"expected '{FILE_FORMAT}', got {table['format']!r}",
                                  key="format")
        normals = _read_array(table, "normals", path, allow_none=True)
        if normals.ndim != 4 or normals.shape[1:] != (6, 2, 3) or normals.shape[0] == 0:
            raise ConfigFileError(path, f"expected shape (N, 6, 2, 3) with N >= 1, got "
                                  f"{normals.shape}", key="normals")
        lengths = _read_array(table, "lengths_mm", path) * 1e-3
        if lengths.shape != normals.shape[:2]:
            raise ConfigFileError(path, f"expected shape {normals.shape[:2]} (one length per "
                                  f"leg and configuration), got {lengths.shape}",
                                  key="lengths_mm")
        if not np.all(np.isfinite(lengths)):
            raise ConfigFileError(path, "contains NaN or inf", key="lengths_mm")
        given = np.all(np.isfinite(normals), axis=-1)
        if "edge_visible" in table:
            raw = table["edge_visible"]
            visible = np.asarray(raw)
            if visible.dtype != bool or visible.shape != normals.shape[:3]:
                raise ConfigFileError(path, f"expected booleans of shape {normals.shape[:3]}",
                                      key="edge_visible")
            missing = np.argwhere(visible & ~given)
            if len(missing):
                k, i, j = missing[0]
                raise ConfigFileError(path, f"configuration {k} leg {i} edge {j} is marked "
                                      "visible but has no finite normal", key="normals")
        else:
            visible = given
        norms = np.linalg.norm(np.where(visible[..., None], normals, 0.0), axis=-1)
        bad = np.argwhere(visible & (np.abs(norms - 1.0) > UNIT_TOLERANCE))
        if len(bad):
            k, i, j = bad[0]
            raise ConfigFileError(path, f"configuration {k} leg {i} edge {j}: normal of norm "
                                  f"{norms[k, i, j]:.6g}, expected a unit vector",
                                  key="normals")
        return cls(normals, visible, lengths, source=path)

    @classmethod
    def load(cls, path: str | Path) -> CalibrationData:
        """Load observations from a ``.json`` or ``.npz`` file (see :meth:`from_dict`).

        Raises:
            ConfigFileError: Missing or unreadable file, unknown type, bad field.
        """
        p = Path(path)
        if not p.exists():
            raise ConfigFileError(str(p), "file not found")
        if p.suffix == ".json":
            try:
                table = json.loads(p.read_text())
            except json.JSONDecodeError as exc:
                raise ConfigFileError(str(p), f"not valid JSON: {exc}") from None
            if not isinstance(table, dict):
                raise ConfigFileError(str(p), "expected a JSON object at the top level")
            return cls.from_dict(table, str(p))
        if p.suffix == ".npz":
            try:
                with np.load(p, allow_pickle=False) as npz:
                    table = {k: npz[k] for k in npz.files}
            except (OSError, ValueError) as exc:
                raise ConfigFileError(str(p), f"not a readable NPZ file: {exc}") from None
            if "edge_visible" in table:
                table["edge_visible"] = np.asarray(table["edge_visible"])
            return cls.from_dict(table, str(p))
        raise ConfigFileError(str(p), "unknown file type; use .json or .npz")


def _nan_to_none(x: Any) -> Any:
    if isinstance(x, list):
        return [_nan_to_none(v) for v in x]
    if isinstance(x, float) and not np.isfinite(x):
        return None
    return x


def _read_array(table: Mapping[str, Any], key: str, path: str,
                allow_none: bool = False) -> np.ndarray:
    value = table[key]
    if allow_none and isinstance(value, list):
        value = _none_to_nan(value, 3)
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ConfigFileError(path, "expected a regular nested array of numbers",
                              key=key) from None
    if not allow_none and not np.all(np.isfinite(arr)):
        raise ConfigFileError(path, "contains NaN or inf", key=key)
    return arr


def _none_to_nan(x: Any, depth: int) -> Any:
    """Replace ``null`` by NaN; a ``null`` in place of a normal (``depth == 0``) stands
    for the three coordinates of a hidden edge."""
    if isinstance(x, list):
        return [_none_to_nan(v, depth - 1) for v in x]
    if x is None:
        return [np.nan] * 3 if depth == 0 else np.nan
    return x


def rotation_noise(amplitude_deg: float) -> NoiseFunction:
    """The rotation noise of the seeds (``docs/math.md`` section 8) as a noise function.

    Each unit vector is rotated about an axis uniform on the sphere by an angle
    uniform in ``[0, amplitude]`` (:func:`vision.noise.rotation_noise`).

    Args:
        amplitude_deg: Maximal rotation angle [deg].
    """

    amplitude = np.deg2rad(float(amplitude_deg))

    def apply(normals: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        return vision_noise.rotation_noise(normals, amplitude, rng)

    return apply


ConfigurationsSpec = str | tuple[str, int]


def configuration_poses(
    geometry: HexapodGeometry,
    configurations: ConfigurationsSpec = "extremal",
    rng: np.random.Generator | int | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Platform poses (base frame) of a calibration set.

    Args:
        geometry: The robot.
        configurations: ``"extremal"`` (the reachable ones of the 64 configurations
            with every leg at a stroke limit), ``("random", N)`` or ``"random:N"``
            (N uniform poses inside the strokes).
        rng: Generator or seed (random configurations).

    Returns:
        Rotations (N, 3, 3) and translations (N, 3) [m].
    """
    if isinstance(configurations, str) and configurations.startswith("random:"):
        try:
            configurations = ("random", int(configurations.split(":", 1)[1]))
        except ValueError:
            raise ValueError(f"configurations: expected 'random:N', got {configurations!r}"
                             ) from None
    if configurations == "extremal":
        ext = extremal_configurations(geometry)
        if not ext.reachable.all():
            log.warning("calibration: %d extremal configurations unreachable: %s",
                        len(ext.unreachable_indices), ext.unreachable_indices)
        return ext.rotations[ext.reachable], ext.translations[ext.reachable]
    if (isinstance(configurations, tuple) and len(configurations) == 2
            and configurations[0] == "random"):
        n = int(configurations[1])
        if n < 2:
            raise ValueError(f"configurations: need at least 2 random configurations, got {n}")
        return sample_poses(geometry, n, rng=rng)
    raise ValueError(f"configurations: expected 'extremal', ('random', N) or 'random:N', "
                     f"got {configurations!r}")


def collect_observations(
    geometry: HexapodGeometry,
    camera_from_base: Transform | Any,
    configurations: ConfigurationsSpec = "extremal",
    noise: NoiseFunction | None = None,
    rng: np.random.Generator | int | None = None,
    poses: tuple[np.ndarray, np.ndarray] | None = None,
) -> CalibrationData:
    """Simulate the leg-edge observations of a calibration run with the true geometry.

    Args:
        geometry: The TRUE robot (its leg radius makes the edges).
        camera_from_base: The true camera pose, a :class:`Transform` (every existing
            edge is observed), or a :class:`vision.cameras.Camera` (visibility from
            :func:`vision.legs.observe_legs`: image bounds and occlusions).
        configurations: See :func:`configuration_poses`.
        noise: Applied to the normals, ``(normals, rng) -> normals`` (e.g.
            :func:`rotation_noise`); None for exact observations.
        rng: Generator or seed (random configurations and noise).
        poses: Explicit platform poses ``(rotations (N, 3, 3), translations (N, 3))``
            in the base frame (overrides ``configurations``).

    Returns:
        The observations.
    """
    gen = np.random.default_rng(rng)
    R, t = poses if poses is not None else configuration_poses(geometry, configurations, gen)
    if isinstance(camera_from_base, Transform):
        legs = legs_in_frame(geometry, R, t, camera_from_base)
        normals, exists = leg_edges(legs.base_points, legs.directions, geometry.leg_radius)
        visible = np.broadcast_to(exists[..., None], normals.shape[:-1])
        lengths = legs.lengths
    else:
        from vision.legs import observe_legs

        obs = observe_legs(camera_from_base, geometry, R, t)
        normals, visible, lengths = obs.normals, obs.edge_visible, obs.lengths
    if noise is not None:
        normals = np.where(visible[..., None], noise(np.nan_to_num(normals), gen), np.nan)
    return CalibrationData(normals, visible, lengths)


def collect_pixel_observations(
    geometry: HexapodGeometry,
    camera: Any,
    configurations: ConfigurationsSpec,
    sigma_px: float,
    points_per_edge: int,
    rng: np.random.Generator | int | None = None,
    outlier_fraction: float = 0.0,
) -> CalibrationData:
    """Like :func:`collect_observations` with pixel noise on points along each edge.

    Each visible edge is measured by fitting its normal to ``points_per_edge``
    pixels with Gaussian noise ``sigma_px`` (see :mod:`vision.pixel_measure`).
    """
    from vision.legs import observe_legs
    from vision.pixel_measure import normals_from_noisy_pixels

    gen = np.random.default_rng(rng)
    R, t = configuration_poses(geometry, configurations, gen)
    obs = observe_legs(camera, geometry, R, t)
    normals, visible = normals_from_noisy_pixels(camera, camera, obs, sigma_px,
                                                 max(int(points_per_edge), 2), gen,
                                                 outlier_fraction)
    return CalibrationData(normals, visible, obs.lengths)


# ============================================================================
# Solving
# ============================================================================

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
        if s[2] < warn_singular_ratio * s[0]:
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


# ============================================================================
# Rigid fit and scale
# ============================================================================


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
) -> CalibrationResult:
    """Linear calibration, optional scale correction and rigid fit of the CAD base.

    Args:
        data: The observations.
        radius: Nominal leg radius [m].
        cad_base_points: (6, 3) CAD base points in the base frame [m].
        method, weight, threshold, min_singular_ratio, warn_singular_ratio: See
            :func:`calibrate_base_points`.
        correct_scale: Divide the estimates by :func:`scale_correction` (use it when
            the leg radius is uncertain; with the right radius it only adds noise).

    Returns:
        The :class:`CalibrationResult`.
    """
    lin = calibrate_base_points(data, radius, method, weight, threshold, min_singular_ratio,
                                warn_singular_ratio=warn_singular_ratio)
    cad = np.asarray(cad_base_points, dtype=float)
    s = scale_correction(lin.base_points, cad)
    points = lin.base_points / s if correct_scale else lin.base_points
    T, _, rms = rigid_fit(points, cad)
    return CalibrationResult(points, T.apply(cad), T, s, correct_scale,
                             radius / s if correct_scale else float(radius), rms, lin)


# ============================================================================
# Reports and the seed-001 study
# ============================================================================


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


def calibrate_in_world(
    geometry: HexapodGeometry,
    camera: Any,
    calibration: Any,
    noise: Any,
    rng: np.random.Generator,
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

    Returns:
        The estimated base points (6, 3) in the true camera frame [m], and a summary
        (``median_error_mm``, ``max_error_mm`` against the truth,
        ``min_singular_ratio``, ``ill_conditioned_legs`` (how many legs are below the
        warning threshold ``calibration.warn_singular_ratio``), ``outliers``,
        ``configurations``).

    Raises:
        CalibrationError: A leg below ``calibration.min_singular_ratio`` (or never seen).

    With the pixel noise model (and no ``noise_deg``) the calibration images get
    the same pixel noise as the control images (:func:`collect_pixel_observations`).
    """
    amplitude = calibration.noise_deg
    if amplitude is None and noise.model == "pixel":
        data = collect_pixel_observations(geometry, camera, calibration.configurations,
                                          noise.pixel_sigma_px, noise.points_per_edge, rng,
                                          getattr(noise, "outlier_fraction", 0.0))
    else:
        if amplitude is None:
            amplitude = noise.amplitude_deg if noise.model == "rotation" else 0.0
        model = rotation_noise(float(amplitude)) if amplitude else None
        data = collect_observations(geometry, camera, calibration.configurations, model, rng)
    res = calibrate_base_points(
        data, geometry.leg_radius, calibration.solver,
        min_singular_ratio=getattr(calibration, "min_singular_ratio", MIN_SINGULAR_RATIO),
        warn_singular_ratio=getattr(calibration, "warn_singular_ratio", WARN_SINGULAR_RATIO))
    truth = camera.camera_from_base.apply(geometry.base_points)
    err = point_errors(res.base_points, truth) * 1e3
    return res.base_points, {
        "median_error_mm": float(np.median(err)),
        "max_error_mm": float(np.max(err)),
        "min_singular_ratio": float(res.singular_value_ratio.min()),
        "ill_conditioned_legs": float(len(res.ill_conditioned_legs)),
        "outliers": float(res.outliers.sum()),
        "configurations": float(data.n_configurations),
    }
