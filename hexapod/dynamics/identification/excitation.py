"""The excitation trajectory: a finite Fourier series, optimised for the identification.

The platform's six coordinates ``p = (t - t_home [m], phi [rad])`` (``R = exp([phi]x)``
about the home orientation) follow Swevers' periodic series of period ``T = 1 / f0``,

    p_j(t) = s * sum_k ( a_jk sin(k w t) - b_jk (cos(k w t) - 1) ) / (k w),

faded in over its first period by a quintic step (the robot starts at rest at home).
The shape ``(a, b)`` is chosen by a stochastic search (a fixed number of random
starts, each refined by a (1+1) evolution strategy) to minimise the condition number of the
base regressor (columns scaled to unit norm, stacked over one period), each candidate
scaled by ``s`` to the largest amplitude that keeps every leg within its stroke (minus
a margin), below a fraction of the speed limit and of the force limit (forces from the
robot file's parameters).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np

from hexapod.dynamics.identification.base import BaseParameters
from hexapod.dynamics.identification.parameters import standard_vector
from hexapod.dynamics.identification.regressor import regressor
from hexapod.exceptions import IdentificationError
from hexapod.geometry import HexapodGeometry
from hexapod.se3 import exp_so3
from hexapod.workspace import home_pose

log = logging.getLogger(__name__)

#: Fundamental frequency [Hz] and number of harmonics of the default series.
BASE_FREQUENCY_HZ = 0.2
HARMONICS = 5
#: Fractions of the stroke margin, speed limit and force limit the excitation may use.
STROKE_MARGIN = 0.005
SPEED_FRACTION = 0.8
FORCE_FRACTION = 0.8
#: Design samples per period.
DESIGN_SAMPLES = 100
#: Relative size of the rotation coordinates [rad per m] in a random shape.
ROTATION_WEIGHT = 3.0


@dataclass
class Excitation:
    """A Fourier excitation.

    Attributes:
        a, b: (6, H) coefficients [m/s or rad/s] (already scaled).
        base_frequency: ``f0`` [Hz].
        condition: Condition number of the scaled base regressor over one period.
        limits: Largest leg excursion beyond mid-stroke [m], leg speed [m/s] and force
            [N] over one period (design model).
    """

    a: np.ndarray
    b: np.ndarray
    base_frequency: float
    condition: float
    limits: dict[str, float]

    @property
    def period(self) -> float:
        """[s]."""
        return 1.0 / self.base_frequency

    def coordinates(self, time_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``p``, ``p_dot``, ``p_ddot`` (N, 6) of the periodic series (no fade)."""
        return series(self.a, self.b, self.base_frequency, time_s)

    def poses(self, geometry: HexapodGeometry, time_s: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
        """Platform poses ``R`` (N, 3, 3), ``t`` (N, 3) [m] with the fade-in."""
        p, _, _ = self.coordinates(time_s)
        x = np.clip(np.asarray(time_s, float) / self.period, 0.0, 1.0)[:, None]
        p = p * x**3 * (10 - 15 * x + 6 * x**2)
        R0, t0 = home_pose(geometry)
        return exp_so3(p[:, 3:]) @ R0, t0 + p[:, :3]

    def to_dict(self) -> dict[str, object]:
        """A JSON-ready description."""
        return {"base_frequency_hz": self.base_frequency, "harmonics": int(self.a.shape[1]),
                "a": self.a.tolist(), "b": self.b.tolist(), "condition": self.condition,
                "limits": self.limits}


def legs(R: np.ndarray, t: np.ndarray, A: np.ndarray, E: np.ndarray
         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Leg lengths (n, 6) [m], unit vectors (n, 6, 3) and platform arms ``r_i = R eB_i``
    (n, 6, 3) [m] of poses ``R`` (n, 3, 3), ``t`` (n, 3) [m], base points ``A`` and
    platform points ``E`` (n, 6, 3) [m]."""
    r = np.einsum("nij,nkj->nki", R, E)
    leg = t[:, None, :] + r - A
    q = np.linalg.norm(leg, axis=-1)
    return q, leg / q[..., None], r


def series(a: np.ndarray, b: np.ndarray, f0: float, time_s: np.ndarray
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The series' value, rate and acceleration (N, 6) at ``time_s`` (N,) [s]."""
    t = np.asarray(time_s, float)[:, None, None]
    k = np.arange(1, a.shape[1] + 1)[None, None, :]
    w = 2 * np.pi * f0 * k
    s, c = np.sin(w * t), np.cos(w * t)
    p = np.sum((a * s - b * (c - 1)) / w, axis=-1)
    pd = np.sum(a * c + b * s, axis=-1)
    pdd = np.sum(w * (-a * s + b * c), axis=-1)
    return p, pd, pdd


def _design(geometry: HexapodGeometry, a: np.ndarray, b: np.ndarray, f0: float,
            times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                        np.ndarray]:
    """Poses, twist and acceleration at the design instants (small-angle rates)."""
    p, pd, pdd = series(a, b, f0, times)
    R0, t0 = home_pose(geometry)
    return exp_so3(p[:, 3:]) @ R0, t0 + p[:, :3], pd, pdd, p


def _measure(geometry: HexapodGeometry, a: np.ndarray, b: np.ndarray, f0: float,
             times: np.ndarray, basis: BaseParameters, prior: np.ndarray
             ) -> tuple[float, dict[str, float], float]:
    """Condition number, limits used, and the worst fraction of any limit (>1: violated)."""
    R, t, tw, acc, _ = _design(geometry, a, b, f0, times)
    n = times.size
    q, _, _ = legs(R, t, np.broadcast_to(geometry.base_points, (n, 6, 3)),
                   np.broadcast_to(geometry.platform_points, (n, 6, 3)))
    q_min, q_max = geometry.stroke
    half = 0.5 * (q_max - q_min) - STROKE_MARGIN  # > 0: check_room
    excursion = float(np.abs(q - 0.5 * (q_min + q_max)).max())
    try:
        Y, qd, _ = regressor(geometry, R, t, tw, acc)
    except Exception:  # a singular pose: unusable
        return np.inf, {}, np.inf
    speed = float(np.abs(qd).max())
    force = float(np.abs(Y @ prior).max())
    limit = float(np.min(geometry.drives.force_limit))
    worst = max(excursion / half, speed / (SPEED_FRACTION * geometry.max_speed),
                force / (FORCE_FRACTION * limit))
    W = basis.columns(Y).reshape(-1, basis.size)
    W = W / np.maximum(np.linalg.norm(W, axis=0), 1e-300)
    cond = float(np.linalg.cond(W))
    return cond, {"excursion_m": excursion, "speed_m_s": speed, "force_n": force}, worst


def _scaled(geometry: HexapodGeometry, a: np.ndarray, b: np.ndarray, f0: float,
            times: np.ndarray, basis: BaseParameters, prior: np.ndarray
            ) -> tuple[float, np.ndarray, np.ndarray, dict[str, float]]:
    """Scale a shape to the largest amplitude within the limits (bisection)."""
    lo, hi = 0.0, 1.0
    while _measure(geometry, hi * a, hi * b, f0, times, basis, prior)[2] < 1 and hi < 1e6:
        lo, hi = hi, 2 * hi
    for _ in range(8):
        mid = 0.5 * (lo + hi)
        if _measure(geometry, mid * a, mid * b, f0, times, basis, prior)[2] < 1:
            lo = mid
        else:
            hi = mid
    s = 0.98 * lo
    cond, limits, _ = _measure(geometry, s * a, s * b, f0, times, basis, prior)
    return cond, s * a, s * b, limits


def check_room(geometry: HexapodGeometry) -> None:
    """Refuse a robot whose stroke leaves the excitation no room: the legs at the
    excitation's centre (the home pose) must lie :data:`STROKE_MARGIN` inside the stroke
    with room to move (else every amplitude breaks the stroke, and the amplitude search,
    never bounded by it, drove the legs past the end stops).

    Raises:
        IdentificationError: Naming the robot file, the stroke and the home lengths.
    """
    R, t = home_pose(geometry)
    q = legs(R[None], t[None], geometry.base_points[None],
             geometry.platform_points[None])[0][0]
    lo, hi = geometry.stroke[0] + STROKE_MARGIN, geometry.stroke[1] - STROKE_MARGIN
    if not (lo < hi and np.all(q > lo) and np.all(q < hi)):
        where = geometry.source or geometry.name
        raise IdentificationError(
            f"{where}: stroke [{geometry.stroke[0] * 1e3:.3f}, {geometry.stroke[1] * 1e3:.3f}] "
            f"mm: no room for an excitation {STROKE_MARGIN * 1e3:g} mm inside it around the "
            f"home pose's legs ({np.round(q * 1e3, 3).tolist()} mm)")


def optimise(geometry: HexapodGeometry, basis: BaseParameters, seed: int = 0,
             candidates: int = 16, base_frequency: float = BASE_FREQUENCY_HZ,
             harmonics: int = HARMONICS) -> Excitation:
    """The excitation of smallest condition number among ``candidates`` (a quarter of
    them random starts, the rest steps of the evolution strategy from the best): the
    same seed gives the same excitation whatever the machine's load.

    Args:
        geometry: The robot file (limits, and the prior parameters for the forces).
        basis: Its base parameters.
        seed: Seed of the search.
        candidates: Shapes tried (at least 2; each costs about 20 regressor evaluations
            of 100 samples).
        base_frequency: ``f0`` [Hz].
        harmonics: Harmonics of the series.
    """
    check_room(geometry)
    rng = np.random.default_rng(seed)
    prior = standard_vector(geometry.inertia, geometry.drives)
    times = np.arange(DESIGN_SAMPLES) / (DESIGN_SAMPLES * base_frequency)
    weight = np.array([1.0, 1, 1, ROTATION_WEIGHT, ROTATION_WEIGHT, ROTATION_WEIGHT])[:, None]

    def draw() -> tuple[np.ndarray, np.ndarray]:
        return (weight * rng.standard_normal((6, harmonics)),
                weight * rng.standard_normal((6, harmonics)))

    start = time.perf_counter()
    best: tuple[float, np.ndarray, np.ndarray, dict[str, float]] | None = None
    starts = 0
    n_starts = max(1, candidates // 4)
    while starts < n_starts:
        a, b = draw()
        cand = _scaled(geometry, a, b, base_frequency, times, basis, prior)
        starts += 1
        if best is None or cand[0] < best[0]:
            best = cand
    assert best is not None
    if not np.isfinite(best[0]):  # no amplitude within the limits: the robot cannot move
        _, used, _ = _measure(geometry, 1e-9 * best[1], 1e-9 * best[2], base_frequency, times,
                              basis, prior)
        limit = float(np.min(geometry.drives.force_limit))
        raise IdentificationError(
            f"{geometry.source or geometry.name}: no excitation within the robot file's "
            f"limits: at rest its legs need {used.get('force_n', np.nan):.0f} N, above "
            f"{FORCE_FRACTION:.0%} of the force limit {limit:g} N ([drives] force_limit, "
            "[inertia])" if used.get("force_n", 0.0) >= FORCE_FRACTION * limit else
            f"{geometry.source or geometry.name}: no excitation within the robot file's "
            "limits (stroke, max_speed_mm_s, [drives] force_limit): every amplitude breaks "
            "one of them")
    step = 0.3
    tries = 0
    while starts + tries < max(candidates, 2):
        scale = np.sqrt(np.sum(best[1] ** 2 + best[2] ** 2))
        da, db = draw()
        norm = np.sqrt(np.sum(da**2 + db**2))
        a = best[1] + step * scale * da / norm
        b = best[2] + step * scale * db / norm
        cand = _scaled(geometry, a, b, base_frequency, times, basis, prior)
        tries += 1
        if cand[0] < best[0]:
            best = cand
            step = min(step * 1.5, 1.0)
        else:
            step = max(step * 0.9, 0.01)
    log.info("excitation: condition %.4g after %d random starts and %d steps (%.1f s)",
             best[0], starts, tries, time.perf_counter() - start)
    return Excitation(best[1], best[2], base_frequency, best[0], best[3])
