"""Lens distortion with OpenCV's radial-tangential model (Brown-Conrady).

The map acts on normalised image coordinates ``m = (x, y)`` (``x = X/Z, y = Y/Z`` for a
perspective camera; the point of the unified model's normalised plane for Mei's model)
and gives the distorted normalised coordinates ``m_d``; the pixel is then ``K m_d``.
With ``r^2 = x^2 + y^2`` and ``L = 1 + k1 r^2 + k2 r^4 + k3 r^6``::

    x_d = x L + 2 p1 x y + p2 (r^2 + 2 x^2)
    y_d = y L + p1 (r^2 + 2 y^2) + 2 p2 x y

This is the model of ``cv2.projectPoints`` with the coefficient vector
``(k1, k2, p1, p2[, k3])`` and of ``cv::omnidir`` (Mei's model, ``(k1, k2, p1, p2)``,
``k3 = 0``). The rational (``k4..k6``), thin-prism (``s1..s4``) and tilt terms of
OpenCV's longer vectors are :class:`vision.cameras.distortion_full.OpenCVLens`.

The inverse has no closed form: :meth:`Lens.remove <vision.cameras.lens.Lens.remove>`
solves ``D(m) = m_d`` by Newton's method inside the fold-free region around the
principal point (the star-shaped region bounded, along each direction from the origin,
by the first zero of the Jacobian determinant ``det dD/dm``, found here exactly from
the roots of a polynomial). :func:`vision.cameras.lens.check_no_fold_in_image` verifies
that the image of that boundary (the fold curve) stays outside the image, so that every
pixel has exactly one pre-image there.
"""

from __future__ import annotations

import math
from functools import lru_cache
from typing import Any

import numpy as np

from vision.cameras.lens import FOLD_DIRECTIONS, Lens
from vision.exceptions import CameraError


def _poly_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Products of polynomials (N, n) x (N, m) -> (N, n + m - 1), lowest degree first."""
    out = np.zeros((a.shape[0], a.shape[1] + b.shape[1] - 1))
    for i in range(a.shape[1]):
        out[:, i:i + b.shape[1]] += a[:, i:i + 1] * b
    return out


class RadialTangential(Lens):
    """OpenCV's radial-tangential distortion ``(k1, k2, p1, p2, k3)`` of normalised coordinates.

    Args:
        coefficients: 4 or 5 numbers in OpenCV's order ``(k1, k2, p1, p2[, k3])``
            (``k3 = 0`` when 4 are given), or None for no distortion.
        source: File the coefficients were read from (for the messages).

    Attributes:
        coefficients: (5,) read-only ``(k1, k2, p1, p2, k3)``.
    """

    names = ("k1", "k2", "p1", "p2", "k3")

    def __init__(self, coefficients: Any = None, source: str | None = None) -> None:
        self.coefficients = parse_coefficients(coefficients, (4, 5), source)

    @property
    def is_radial(self) -> bool:
        """True without decentring terms (``p1 = p2 = 0``)."""
        return not np.any(self.coefficients[2:4])

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, RadialTangential):
            return NotImplemented
        return bool(np.array_equal(self.coefficients, other.coefficients))

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        k1, k2, p1, p2, k3 = self.coefficients
        return f"RadialTangential(k1={k1:g}, k2={k2:g}, p1={p1:g}, p2={p2:g}, k3={k3:g})"

    # ------------------------------------------------------------------ the map
    def apply(self, m: np.ndarray) -> np.ndarray:
        """Distorted normalised coordinates (..., 2) of undistorted ones ``m`` (..., 2)."""
        m = np.asarray(m, dtype=float)
        k1, k2, p1, p2, k3 = self.coefficients
        x, y = m[..., 0], m[..., 1]
        r2 = x * x + y * y
        L = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        xy2 = 2.0 * x * y
        xd = x * L + p1 * xy2 + p2 * (r2 + 2.0 * x * x)
        yd = y * L + p1 * (r2 + 2.0 * y * y) + p2 * xy2
        return np.stack([xd, yd], axis=-1)

    def jacobian(self, m: np.ndarray) -> np.ndarray:
        """``d m_d / d m`` (..., 2, 2) at undistorted normalised coordinates ``m`` (..., 2)."""
        m = np.asarray(m, dtype=float)
        k1, k2, p1, p2, k3 = self.coefficients
        x, y = m[..., 0], m[..., 1]
        r2 = x * x + y * y
        L = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        M = 2.0 * k1 + r2 * (4.0 * k2 + 6.0 * k3 * r2)  # dL/dx = M x, dL/dy = M y
        j11 = L + x * x * M + 2.0 * p1 * y + 6.0 * p2 * x
        j12 = x * y * M + 2.0 * p1 * x + 2.0 * p2 * y
        j22 = L + y * y * M + 6.0 * p1 * y + 2.0 * p2 * x
        return np.stack([np.stack([j11, j12], -1), np.stack([j12, j22], -1)], -2)

    def parts(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, ...]:
        """:meth:`apply` and :meth:`jacobian` without stacking: ``(x_d, y_d, j11, j12,
        j21, j22)`` (the Jacobian is symmetric: ``j21`` is ``j12``)."""
        k1, k2, p1, p2, k3 = (float(v) for v in self.coefficients)
        r2 = x * x + y * y
        L = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        M = 2.0 * k1 + r2 * (4.0 * k2 + 6.0 * k3 * r2)
        xy2 = 2.0 * x * y
        xd = x * L + p1 * xy2 + p2 * (r2 + 2.0 * x * x)
        yd = y * L + p1 * (r2 + 2.0 * y * y) + p2 * xy2
        j11 = L + x * x * M + 2.0 * p1 * y + 6.0 * p2 * x
        j12 = x * y * M + 2.0 * p1 * x + 2.0 * p2 * y
        j22 = L + y * y * M + 6.0 * p1 * y + 2.0 * p2 * x
        return xd, yd, j11, j12, j12, j22

    # ------------------------------------------------------------------ folds
    def fold_radius(self, theta: np.ndarray) -> np.ndarray:
        """First zero of ``det dD/dm`` along the directions ``theta`` (N,) [rad].

        Along ``m = r (cos theta, sin theta)`` the determinant is a polynomial in ``r``
        of degree 12 (``k3 != 0``), 8 (``k2 != 0``), 4 (``k1 != 0``) or 2; its
        smallest positive real root is found from the companion matrix and polished
        by Newton's method.

        Returns:
            (N,) radii [normalised units], inf where the map does not fold.
        """
        th = np.atleast_1d(np.asarray(theta, dtype=float))
        k1, k2, p1, p2, k3 = self.coefficients
        c, s = np.cos(th), np.sin(th)
        n = th.shape[0]
        Lc = np.zeros((n, 7))
        Lc[:, 0], Lc[:, 2], Lc[:, 4], Lc[:, 6] = 1.0, k1, k2, k3
        RM = np.zeros((n, 7))  # r^2 M(r)
        RM[:, 2], RM[:, 4], RM[:, 6] = 2.0 * k1, 4.0 * k2, 6.0 * k3
        a11 = Lc + (c * c)[:, None] * RM
        a22 = Lc + (s * s)[:, None] * RM
        a12 = (c * s)[:, None] * RM
        a11[:, 1] += 2.0 * p1 * s + 6.0 * p2 * c
        a22[:, 1] += 6.0 * p1 * s + 2.0 * p2 * c
        a12[:, 1] += 2.0 * p1 * c + 2.0 * p2 * s
        det = _poly_mul(a11, a22) - _poly_mul(a12, a12)  # (n, 13), det(0) = 1
        degree = 12 if k3 != 0 else 8 if k2 != 0 else 4 if k1 != 0 else 2
        coef = det[:, : degree + 1]
        if degree == 2:
            a, b = coef[:, 2], coef[:, 1]  # a r^2 + b r + 1
            with np.errstate(invalid="ignore", divide="ignore"):
                disc = b * b - 4.0 * a
                sq = np.sqrt(np.where(disc >= 0, disc, np.nan))
                # Stable forms of the two roots: 2 / (-b -+ sq).
                roots = np.stack([2.0 / (-b - sq), 2.0 / (-b + sq),
                                  np.where(a == 0, -1.0 / b, np.nan)], -1)
            roots = np.where(np.isfinite(roots) & (roots > 0), roots, np.inf)
            return np.asarray(roots.min(axis=-1))
        lead = coef[:, degree]
        comp = np.zeros((n, degree, degree))
        comp[:, 1:, :-1] = np.eye(degree - 1)
        comp[:, :, -1] = -coef[:, :degree] / lead[:, None]
        z = np.linalg.eigvals(comp)
        real = np.abs(z.imag) <= 1e-6 * np.maximum(1.0, np.abs(z))
        r = np.where(real & (z.real > 0), z.real, np.inf)
        # Newton polish of every candidate on the polynomial itself.
        dcoef = coef[:, 1:] * np.arange(1, degree + 1)
        for _ in range(4):
            fin = np.isfinite(r)
            rr = np.where(fin, r, 0.0)
            f = _polyval(coef, rr)
            df = _polyval(dcoef, rr)
            with np.errstate(invalid="ignore", divide="ignore"):
                step = np.where(fin & (df != 0), f / df, 0.0)
            r = np.where(fin, rr - step, np.inf)
        r = np.where(r > 0, r, np.inf)
        return np.asarray(r.min(axis=-1))

    @property
    def _fold_table(self) -> tuple[np.ndarray, np.ndarray]:
        """Fold radius on :data:`FOLD_DIRECTIONS` directions: (theta, radius)."""
        return _fold_table(tuple(float(c) for c in self.coefficients))

    # ------------------------------------------------------------------ inverse
    def _radial_guess(self, md: np.ndarray) -> np.ndarray:
        """Start of :meth:`remove`: the radial part inverted along the direction of ``md``.

        Solves ``r L(r) = |md|`` by Newton's method safeguarded by bisection on
        ``[0, fold-free radius)`` (``r L(r)`` increases there), then returns
        ``r md / |md|`` (N, 2).
        """
        k1, k2, _, _, k3 = self.coefficients
        rho = np.linalg.norm(md, axis=-1)
        lo = np.zeros(rho.shape)
        hi = self.fold_free_radius(md)
        r = np.minimum(rho, 0.5 * hi)
        for _ in range(30):
            r2 = r * r
            g = r * (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))) - rho
            dg = 1.0 + r2 * (3.0 * k1 + r2 * (5.0 * k2 + 7.0 * k3 * r2))
            lo = np.where(g < 0, r, lo)
            hi = np.where(g > 0, r, hi)
            with np.errstate(invalid="ignore", divide="ignore"):
                nr = r - g / dg
            bisect = np.where(np.isfinite(hi), 0.5 * (lo + hi), 2.0 * r + 1e-3)
            ok = np.isfinite(nr) & (dg > 0) & (nr > lo) & (nr < hi)
            nr = np.where(ok, nr, bisect)
            if np.all(np.abs(nr - r) <= 1e-12 * np.maximum(r, 1e-300)):
                r = nr
                break
            r = nr
        with np.errstate(invalid="ignore", divide="ignore"):
            u = np.where(rho[:, None] > 0, md / rho[:, None], 0.0)
        return np.asarray(r[:, None] * u)


@lru_cache(maxsize=64)
def _fold_table(coefficients: tuple[float, ...]) -> tuple[np.ndarray, np.ndarray]:
    """The fold radius of a coefficient set on :data:`FOLD_DIRECTIONS` directions (cached:
    about 50 ms for a 5-coefficient set)."""
    theta = np.linspace(-math.pi, math.pi, FOLD_DIRECTIONS, endpoint=False)
    radius = RadialTangential(coefficients).fold_radius(theta)
    theta.flags.writeable = False
    radius.flags.writeable = False
    return theta, radius


def _polyval(coef: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Values of polynomials (N, d+1) (lowest degree first) at r (N, k)."""
    out = np.zeros(r.shape)
    for i in range(coef.shape[1] - 1, -1, -1):
        out = out * r + coef[:, i:i + 1]
    return out


def parse_coefficients(coefficients: Any, lengths: tuple[int, ...],
                       source: str | None = None, names: str = "k1, k2, p1, p2[, k3]"
                       ) -> np.ndarray:
    """Distortion coefficients as a read-only vector, zero-padded to the longest of the
    ``lengths`` and at least 5 (OpenCV's ``(k1, k2, p1, p2, k3[, ...])``).

    Args:
        coefficients: None (no distortion) or a sequence of ``lengths`` numbers.
        lengths: The accepted lengths (``(4, 5)`` perspective, ``(4,)`` unified).
        source: File the coefficients come from (for the message).
        names: The coefficient names, for the message.

    Raises:
        CameraError: Wrong length, not numbers, NaN or inf (field ``"distortion"``).
    """
    out = np.zeros(max(5, *lengths))
    if coefficients is not None:
        try:
            arr = np.array(coefficients, dtype=float)
        except (TypeError, ValueError):
            raise CameraError("distortion", f"expected {_lengths(lengths)} numbers "
                              f"({names}), got {coefficients!r}", source) from None
        if arr.ndim != 1 or arr.shape[0] not in lengths:
            raise CameraError("distortion", f"expected {_lengths(lengths)} numbers "
                              f"({names}), got shape {arr.shape}", source)
        if not np.all(np.isfinite(arr)):
            raise CameraError("distortion", f"contains NaN or inf: {arr.tolist()}", source)
        out[: arr.shape[0]] = arr
    out.flags.writeable = False
    return out


def _lengths(lengths: tuple[int, ...]) -> str:
    return " or ".join(str(n) for n in lengths)
