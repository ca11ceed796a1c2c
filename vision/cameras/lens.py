"""The common base of the lens maps (:class:`Lens`) and the fold check of a camera.

A lens maps the normalised coordinates ``m`` of a camera's projection
(:mod:`vision.cameras.projection`) to distorted ones ``m_d = D(m)``; the pixel is then
``K m_d``. Each lens gives its map, its Jacobian, the radius of its first fold along a
direction (the first zero of ``det dD/dm``) and a starting point of the inverse; this
base inverts it (:meth:`Lens.remove`: Newton's method kept inside the fold-free region
around the principal point) and :func:`check_no_fold_in_image` refuses a lens whose fold
curve enters the image, so that every pixel has one pre-image on the principal sheet.

The lenses: :class:`vision.cameras.distortion.RadialTangential` (OpenCV's five
coefficients, Mei's four), :class:`vision.cameras.distortion_full.OpenCVLens` (OpenCV's
14 coefficients), :mod:`vision.cameras.radial` (the central radial models: Kannala-Brandt,
double sphere, extended unified).
"""

from __future__ import annotations

import logging
import math
from abc import ABC, abstractmethod

import numpy as np

from vision.exceptions import DistortionError

log = logging.getLogger(__name__)

#: Directions of the fold-curve sampling (the fold radius is exact along each).
FOLD_DIRECTIONS = 1024
#: Iteration limit of the Newton inverse.
MAX_NEWTON_ITERATIONS = 60


class Lens(ABC):
    """A lens map ``m -> m_d`` of normalised coordinates (see the module docstring).

    Attributes:
        coefficients: Read-only coefficients (the model's order).
    """

    coefficients: np.ndarray
    #: Names of the coefficients, in order (for the messages).
    names: tuple[str, ...] = ()

    @property
    def is_identity(self) -> bool:
        """True when the map is the identity (the ideal lens)."""
        return not np.any(self.coefficients)

    @property
    def is_radial(self) -> bool:
        """True when the map keeps the rotational symmetry about the principal point."""
        return False

    @abstractmethod
    def apply(self, m: np.ndarray) -> np.ndarray:
        """Distorted normalised coordinates (..., 2) of undistorted ones ``m`` (..., 2)."""

    @abstractmethod
    def jacobian(self, m: np.ndarray) -> np.ndarray:
        """``d m_d / d m`` (..., 2, 2) at undistorted normalised coordinates ``m`` (..., 2)."""

    @abstractmethod
    def fold_radius(self, theta: np.ndarray) -> np.ndarray:
        """First zero of ``det dD/dm`` along the directions ``theta`` (N,) [rad]: (N,)
        radii [normalised units], inf where the map does not fold."""

    @property
    @abstractmethod
    def _fold_table(self) -> tuple[np.ndarray, np.ndarray]:
        """Fold radius on :data:`FOLD_DIRECTIONS` directions: (theta, radius) (cached)."""

    @abstractmethod
    def _radial_guess(self, md: np.ndarray) -> np.ndarray:
        """Start (N, 2) of :meth:`remove` for distorted points ``md`` (N, 2), inside the
        fold-free region."""

    def parts(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, ...]:
        """The map ``(x_d, y_d)`` at ``(x, y)`` and its Jacobian ``(j11, j12, j21, j22)``
        as separate arrays (the detectors' form)."""
        m = np.stack([x, y], -1)
        md = self.apply(m)
        J = self.jacobian(m)
        return (md[..., 0], md[..., 1], J[..., 0, 0], J[..., 0, 1], J[..., 1, 0],
                J[..., 1, 1])

    def fold_free_radius(self, m: np.ndarray) -> np.ndarray:
        """A lower bound of the fold radius (...) in the direction of ``m`` (..., 2).

        The minimum of the tabulated fold radius at the two neighbouring directions of
        :data:`FOLD_DIRECTIONS`, less 0.1 %: points closer to the origin are in the
        fold-free region (up to the curvature of the fold curve between two samples).
        """
        radius = self._fold_table[1]
        with np.errstate(invalid="ignore"):
            t = np.nan_to_num(np.arctan2(m[..., 1], m[..., 0]))
        step = 2.0 * math.pi / FOLD_DIRECTIONS
        i = np.floor((t + math.pi) / step).astype(np.intp) % FOLD_DIRECTIONS
        j = (i + 1) % FOLD_DIRECTIONS
        return np.asarray(np.minimum(radius[i], radius[j]) * 0.999)

    def remove(self, md: np.ndarray) -> np.ndarray:
        """Undistorted coordinates ``m`` (..., 2) with ``apply(m) = md`` (..., 2).

        Newton's method from ``m = md`` with a backtracking line search on ``|D(m) - md|``
        that keeps the iterates in the fold-free region around the origin, so the
        solution is the pre-image on the principal sheet (the one cameras see).
        Converged to the rounding of ``D`` (residual below ``1e-15 max(1, |md|)``).

        Returns:
            (..., 2), NaN where ``md`` is not finite or the iteration did not converge
            (no pre-image in the fold-free region: beyond the fold curve).
        """
        md = np.asarray(md, dtype=float)
        if self.is_identity:
            return md.copy()
        shape = md.shape
        target = md.reshape(-1, 2)
        ok = np.all(np.isfinite(target), axis=-1)
        m = np.where(ok[:, None], target, 0.0)
        scale = np.maximum(1.0, np.linalg.norm(m, axis=-1))
        m = self._radial_guess(m)
        F = self.apply(m) - target
        res = np.linalg.norm(F, axis=-1)
        done = ok & (res <= 1e-15 * scale)
        active = ok & ~done
        for _ in range(MAX_NEWTON_ITERATIONS):
            if not active.any():
                break
            idx = np.flatnonzero(active)
            mi, fi, ri = m[idx], F[idx], res[idx]
            J = self.jacobian(mi)
            det = J[:, 0, 0] * J[:, 1, 1] - J[:, 0, 1] * J[:, 1, 0]
            with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
                step = np.stack([J[:, 1, 1] * fi[:, 0] - J[:, 0, 1] * fi[:, 1],
                                 J[:, 0, 0] * fi[:, 1] - J[:, 1, 0] * fi[:, 0]], -1) / det[:, None]
            tiny = np.linalg.norm(step, axis=-1) <= 1e-14 * np.maximum(
                1.0, np.linalg.norm(mi, axis=-1))
            t = np.ones(idx.size)
            accepted = np.zeros(idx.size, dtype=bool)
            for _ in range(50):
                trial = mi - t[:, None] * step
                with np.errstate(invalid="ignore", over="ignore"):
                    Ft = self.apply(trial) - target[idx]
                    rt = np.linalg.norm(Ft, axis=-1)
                    inside = np.linalg.norm(trial, axis=-1) < self.fold_free_radius(trial)
                good = ~accepted & inside & ((rt < ri) | (tiny & np.isfinite(rt)))
                mi[good], fi[good], ri[good] = trial[good], Ft[good], rt[good]
                accepted |= good
                if accepted.all():
                    break
                t *= 0.5
            m[idx], F[idx], res[idx] = mi, fi, ri
            fin = tiny | (ri <= 1e-15 * scale[idx])
            # No decrease possible: converged if at the rounding floor of D, else failed.
            floor = ~accepted & (ri <= 1e-12 * scale[idx])
            done[idx[fin | floor]] = True
            active[idx[fin | ~accepted]] = False
        out = np.where(done[:, None], m, np.nan)
        return out.reshape(shape)


def _clip_segments(a: np.ndarray, b: np.ndarray, lo: np.ndarray, hi: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Liang-Barsky clipping of the segments a-b (N, 2) by the box [lo, hi]: whether
    they meet it and the parameters ``t0 <= t1`` of the part inside."""
    d = b - a
    t0 = np.zeros(a.shape[0])
    t1 = np.ones(a.shape[0])
    hit = np.ones(a.shape[0], dtype=bool)
    for k in range(2):
        for p, q in ((-d[:, k], a[:, k] - lo[k]), (d[:, k], hi[k] - a[:, k])):
            parallel = p == 0
            hit &= ~(parallel & (q < 0))
            with np.errstate(invalid="ignore", divide="ignore"):
                r = q / p
            t0 = np.where(~parallel & (p < 0), np.maximum(t0, r), t0)
            t1 = np.where(~parallel & (p > 0), np.minimum(t1, r), t1)
    return hit & (t0 <= t1), t0, t1


def _arc_enters(distortion: Lens, K: np.ndarray, theta0: float, step: float,
                lo: np.ndarray, hi: np.ndarray, diag: float, levels: int) -> bool:
    """Whether the fold curve between the directions ``theta0`` and ``theta0 + step``
    enters the image: 64 exact fold points between them, their chords tested, a long
    chord across the image refined again (``levels`` times at most; then it counts)."""
    th = theta0 + step * np.linspace(0.0, 1.0, 65)
    r = distortion.fold_radius(th)
    if not np.all(np.isfinite(r)):
        return True  # the curve leaves the sampled branch: keep the coarse verdict
    pix = distortion.apply(r[:, None] * np.stack([np.cos(th), np.sin(th)], -1))
    pix = pix @ K[:2, :2].T + K[:2, 2]
    inside = np.all((pix >= lo) & (pix <= hi), axis=-1)
    if inside.any():
        return True
    hit, _, _ = _clip_segments(pix[:-1], pix[1:], lo, hi)
    for j in np.flatnonzero(hit):
        if levels <= 1 or np.linalg.norm(pix[j + 1] - pix[j]) <= diag:
            return True
        if _arc_enters(distortion, K, float(th[j]), step / 64, lo, hi, diag, levels - 1):
            return True
    return False


def check_no_fold_in_image(distortion: Lens, K: np.ndarray, width: int,
                           height: int, domain_radius: float = math.inf,
                           source: str | None = None) -> None:
    """Refuse a distortion whose fold curve enters the image.

    The fold radius is computed along :data:`FOLD_DIRECTIONS` directions of the
    undistorted plane (first positive root of the Jacobian determinant, tangential
    terms included: :meth:`Lens.fold_radius`), the fold points are mapped to pixels with
    the distortion and ``K``, and each point and each segment between neighbouring
    points is tested against the image ``[-0.5, w - 0.5] x [-0.5, h - 0.5]`` (corners
    included; a chord longer than the image diagonal between two points outside it is
    resampled finely before it counts). Folds
    beyond ``domain_radius`` (no ray maps there: the unified model with ``xi > 1``)
    are ignored.

    Raises:
        DistortionError: With the fold point deepest inside the image.
    """
    if distortion.is_identity:
        return
    theta, radius = distortion._fold_table
    fin = np.isfinite(radius) & (radius < domain_radius)
    if not fin.any():
        return
    r = np.where(fin, radius, 0.0)
    with np.errstate(invalid="ignore", over="ignore"):
        md = distortion.apply(r[:, None] * np.stack([np.cos(theta), np.sin(theta)], -1))
        pix = md @ K[:2, :2].T + K[:2, 2]
    # A fold at a pole of a rational lens is imaged at infinity: not in the image.
    fin &= np.all(np.isfinite(pix), axis=-1)
    pix = np.where(fin[:, None], pix, 0.0)
    lo = np.array([-0.5, -0.5])
    hi = np.array([width - 0.5, height - 0.5])
    nxt = np.roll(np.arange(theta.size), -1)
    # Neighbouring fold points on the same branch of the curve (no jump of the radius).
    pair = fin & fin[nxt] & (np.abs(r - r[nxt]) <= 0.1 * np.minimum(r, r[nxt]))
    hit, t0, t1 = _clip_segments(pix, pix[nxt], lo, hi)
    hit &= pair
    # A chord much longer than the image between two far fold points says nothing of the
    # curve between them: sample it finely there.
    diag = math.hypot(width, height)
    far = ~np.all((pix >= lo) & (pix <= hi), axis=-1)
    step = 2.0 * math.pi / theta.size
    for k in np.flatnonzero(hit & far & far[nxt]
                            & (np.linalg.norm(pix[nxt] - pix, axis=-1) > diag)):
        hit[k] = _arc_enters(distortion, K, float(theta[k]), step, lo, hi, diag, 3)
    t = np.where(hit, 0.5 * (t0 + t1), 0.0)
    # Isolated fold points in the image (next to a jump of the radius) count too.
    hit |= fin & np.all((pix >= lo) & (pix <= hi), axis=-1)
    if not hit.any():
        return
    # The evidence: the fold point, computed exactly, in the direction of the middle of
    # the part inside the image of the segment that goes deepest into it.
    p_mid = pix + t[:, None] * (pix[nxt] - pix)
    depth = np.minimum(p_mid - lo, hi - p_mid).min(axis=-1)
    i = int(np.argmax(np.where(hit, depth, -np.inf)))
    th = np.array([theta[i] + t[i] * step])
    r_i = float(distortion.fold_radius(th)[0])
    if not math.isfinite(r_i):  # the root left between the samples: keep the sample
        th, r_i = theta[i:i + 1], float(r[i])
    md_i = distortion.apply(r_i * np.stack([np.cos(th), np.sin(th)], -1))[0]
    p_i = K[:2, :2] @ md_i + K[:2, 2]
    err = DistortionError(
        distortion.coefficients, r_i, float(np.linalg.norm(md_i)),
        float(np.linalg.norm(p_i - K[:2, 2])), (float(p_i[0]), float(p_i[1])), source)
    log.debug("%s", err)
    raise err
