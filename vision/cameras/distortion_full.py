"""OpenCV's full lens distortion: rational, thin-prism and tilt terms (14 coefficients).

The model of ``cv2.projectPoints`` with the coefficient vector ``(k1, k2, p1, p2, k3, k4,
k5, k6, s1, s2, s3, s4, tau_x, tau_y)`` (8, 12 or 14 numbers: ``CALIB_RATIONAL_MODEL``,
``CALIB_THIN_PRISM_MODEL``, ``CALIB_TILTED_MODEL``). With ``r^2 = x^2 + y^2``::

    L   = (1 + k1 r^2 + k2 r^4 + k3 r^6) / (1 + k4 r^2 + k5 r^4 + k6 r^6)
    x'' = x L + 2 p1 x y + p2 (r^2 + 2 x^2) + s1 r^2 + s2 r^4
    y'' = y L + p1 (r^2 + 2 y^2) + 2 p2 x y + s3 r^2 + s4 r^4

then the tilt of the sensor (Scheimpflug): ``(x_d, y_d, 1) ~ T (x'', y'', 1)`` with
``T = [[R33, 0, -R13], [0, R33, -R23], [0, 0, 1]] R``, ``R = R_y(tau_y) R_x(tau_x)`` as in
OpenCV's ``computeTiltProjectionMatrix`` (``R_x = [[1, 0, 0], [0, c, s], [0, -s, c]]``,
``R_y = [[c, 0, -s], [0, 1, 0], [s, 0, c]]``).

The fold radius (first zero of ``det dD/dm`` along a direction, or a zero of the
rational denominator, whichever comes first) has no polynomial form once the tilt is
there: it is bracketed on a fine radial grid and refined by bisection
(:func:`fold_radius_by_sampling`, shared with :mod:`vision.cameras.radial`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from functools import lru_cache
from typing import Any

import numpy as np

from vision.cameras.lens import FOLD_DIRECTIONS, Lens
from vision.exceptions import CameraError

#: OpenCV's coefficient names, in order.
NAMES = ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6", "s1", "s2", "s3", "s4", "tau_x",
         "tau_y")
#: Radii of the fold search grid [normalised units]: fine near the centre, up to 100
#: (a ray 89.4 deg off the axis of a perspective camera).
FOLD_GRID = np.concatenate([np.linspace(0.0, 2.0, 241)[1:], np.geomspace(2.0, 100.0, 161)[1:]])


def tilt_matrix(tau_x: float, tau_y: float) -> np.ndarray:
    """OpenCV's ``computeTiltProjectionMatrix`` (3, 3) of the tilt angles [rad]."""
    cx, sx, cy, sy = math.cos(tau_x), math.sin(tau_x), math.cos(tau_y), math.sin(tau_y)
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cx, sx], [0.0, -sx, cx]])
    ry = np.array([[cy, 0.0, -sy], [0.0, 1.0, 0.0], [sy, 0.0, cy]])
    r = ry @ rx
    proj = np.array([[r[2, 2], 0.0, -r[0, 2]], [0.0, r[2, 2], -r[1, 2]], [0.0, 0.0, 1.0]])
    return np.asarray(proj @ r)


def fold_radius_by_sampling(det: Callable[[np.ndarray], np.ndarray], theta: np.ndarray,
                            grid: np.ndarray = FOLD_GRID) -> np.ndarray:
    """First radius where ``det`` (positive at the origin) stops being positive, along
    each direction ``theta`` (N,): the first grid interval where it does, refined by 60
    bisections. ``det(m)`` takes (N, k, 2) points and gives (N, k). inf if none."""
    th = np.atleast_1d(np.asarray(theta, dtype=float))
    u = np.stack([np.cos(th), np.sin(th)], -1)
    with np.errstate(all="ignore"):
        vals = det(grid[None, :, None] * u[:, None, :])
    bad = ~(vals > 0)
    hit = bad.any(axis=1)
    k = np.argmax(bad, axis=1)
    lo = np.where(k > 0, grid[np.maximum(k - 1, 0)], 0.0)
    hi = grid[k]
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        with np.errstate(all="ignore"):
            ok = det(mid[:, None, None] * u[:, None, :])[:, 0] > 0
        lo = np.where(ok, mid, lo)
        hi = np.where(ok, hi, mid)
    return np.where(hit, hi, np.inf)


class OpenCVLens(Lens):
    """OpenCV's 14-coefficient distortion (see the module docstring).

    Args:
        coefficients: 4, 5, 8, 12 or 14 numbers in OpenCV's order (missing ones zero).

    Attributes:
        coefficients: (14,) read-only.
    """

    names = NAMES

    def __init__(self, coefficients: Any) -> None:
        c = np.zeros(14)
        arr = np.asarray(coefficients, dtype=float).reshape(-1)
        c[: arr.size] = arr
        c.flags.writeable = False
        self.coefficients = c
        T = tilt_matrix(c[12], c[13])
        T.flags.writeable = False
        self.tilt = T

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, OpenCVLens):
            return NotImplemented
        return bool(np.array_equal(self.coefficients, other.coefficients))

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        terms = ", ".join(f"{n}={c:g}" for n, c in zip(NAMES, self.coefficients, strict=True)
                          if c != 0)
        return f"OpenCVLens({terms})"

    @property
    def is_radial(self) -> bool:
        """True with the radial terms only (no decentring, thin-prism or tilt term)."""
        c = self.coefficients
        return not (np.any(c[2:4]) or np.any(c[8:]))

    def _untilted(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, ...]:
        """``(x'', y'')`` and their derivatives ``(a11, a12, a21, a22)`` at ``(x, y)``."""
        k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4 = (float(v) for v in
                                                          self.coefficients[:12])
        r2 = x * x + y * y
        num = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        den = 1.0 + r2 * (k4 + r2 * (k5 + r2 * k6))
        dnum = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)  # d num / d r^2
        dden = k4 + r2 * (2.0 * k5 + 3.0 * k6 * r2)
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            L = num / den
            Lr = (dnum * den - num * dden) / (den * den)  # d L / d r^2
        xy = x * y
        px = s1 + 2.0 * s2 * r2  # d (s1 r^2 + s2 r^4) / d r^2
        py = s3 + 2.0 * s4 * r2
        xu = x * L + 2.0 * p1 * xy + p2 * (r2 + 2.0 * x * x) + r2 * (s1 + s2 * r2)
        yu = y * L + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * xy + r2 * (s3 + s4 * r2)
        a11 = L + 2.0 * x * x * Lr + 2.0 * p1 * y + 6.0 * p2 * x + 2.0 * x * px
        a12 = 2.0 * xy * Lr + 2.0 * p1 * x + 2.0 * p2 * y + 2.0 * y * px
        a21 = 2.0 * xy * Lr + 2.0 * p1 * x + 2.0 * p2 * y + 2.0 * x * py
        a22 = L + 2.0 * y * y * Lr + 6.0 * p1 * y + 2.0 * p2 * x + 2.0 * y * py
        return xu, yu, a11, a12, a21, a22

    def parts(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, ...]:
        """The map and its Jacobian ``(x_d, y_d, j11, j12, j21, j22)`` at ``(x, y)``."""
        xu, yu, a11, a12, a21, a22 = self._untilted(x, y)
        T = self.tilt
        if self.coefficients[12] == 0 and self.coefficients[13] == 0:
            return xu, yu, a11, a12, a21, a22
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            w = T[2, 0] * xu + T[2, 1] * yu + T[2, 2]
            inv = np.where(w != 0, 1.0 / w, 1.0)  # as OpenCV: no division by zero
            xd = (T[0, 0] * xu + T[0, 1] * yu + T[0, 2]) * inv
            yd = (T[1, 0] * xu + T[1, 1] * yu + T[1, 2]) * inv
            # d (x_d, y_d) / d (x'', y'') = (T[:2, :2] - md T[2, :2]) / w
            b11 = (T[0, 0] - xd * T[2, 0]) * inv
            b12 = (T[0, 1] - xd * T[2, 1]) * inv
            b21 = (T[1, 0] - yd * T[2, 0]) * inv
            b22 = (T[1, 1] - yd * T[2, 1]) * inv
        return (xd, yd, b11 * a11 + b12 * a21, b11 * a12 + b12 * a22,
                b21 * a11 + b22 * a21, b21 * a12 + b22 * a22)

    def apply(self, m: np.ndarray) -> np.ndarray:
        """Distorted normalised coordinates (..., 2) of undistorted ones ``m`` (..., 2)."""
        m = np.asarray(m, dtype=float)
        p = self.parts(m[..., 0], m[..., 1])
        return np.stack([p[0], p[1]], axis=-1)

    def jacobian(self, m: np.ndarray) -> np.ndarray:
        """``d m_d / d m`` (..., 2, 2) at undistorted normalised coordinates ``m`` (..., 2)."""
        m = np.asarray(m, dtype=float)
        _, _, j11, j12, j21, j22 = self.parts(m[..., 0], m[..., 1])
        return np.stack([np.stack([j11, j12], -1), np.stack([j21, j22], -1)], -2)

    def _det(self, m: np.ndarray) -> np.ndarray:
        """``det dD/dm``, NaN where the rational denominator is not positive (a pole)."""
        x, y = m[..., 0], m[..., 1]
        _, _, j11, j12, j21, j22 = self.parts(x, y)
        c = self.coefficients
        r2 = x * x + y * y
        den = 1.0 + r2 * (c[5] + r2 * (c[6] + r2 * c[7]))
        return np.where(den > 0, j11 * j22 - j12 * j21, np.nan)

    def fold_radius(self, theta: np.ndarray) -> np.ndarray:
        """First zero of ``det dD/dm`` (or of the rational denominator) along the
        directions ``theta`` (N,) [rad], by sampling and bisection; inf if none up to
        the end of :data:`FOLD_GRID`."""
        return fold_radius_by_sampling(self._det, theta)

    @property
    def _fold_table(self) -> tuple[np.ndarray, np.ndarray]:
        return _fold_table(tuple(float(c) for c in self.coefficients))

    def _radial_guess(self, md: np.ndarray) -> np.ndarray:
        """``md`` scaled along its direction until the radial factor ``r L(r)`` matches
        ``|md|`` (bisection inside the fold-free radius)."""
        rho = np.linalg.norm(md, axis=-1)
        hi = np.minimum(self.fold_free_radius(md), 1e3)
        lo = np.zeros(rho.shape)
        c = self.coefficients
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            r2 = mid * mid
            with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
                g = mid * (1.0 + r2 * (c[0] + r2 * (c[1] + r2 * c[4]))) / (
                    1.0 + r2 * (c[5] + r2 * (c[6] + r2 * c[7])))
            below = g < rho
            lo = np.where(below, mid, lo)
            hi = np.where(below, hi, mid)
        r = 0.5 * (lo + hi)
        with np.errstate(invalid="ignore", divide="ignore"):
            u = np.where(rho[:, None] > 0, md / rho[:, None], 0.0)
        return np.asarray(r[:, None] * u)


@lru_cache(maxsize=64)
def _fold_table(coefficients: tuple[float, ...]) -> tuple[np.ndarray, np.ndarray]:
    theta = np.linspace(-math.pi, math.pi, FOLD_DIRECTIONS, endpoint=False)
    radius = OpenCVLens(coefficients).fold_radius(theta)
    theta.flags.writeable = False
    radius.flags.writeable = False
    return theta, radius


def needs_full_model(coefficients: np.ndarray) -> bool:
    """Whether OpenCV coefficients (any length) have a nonzero term beyond ``k3``."""
    return bool(np.any(np.asarray(coefficients)[5:]))


def check_tilt(coefficients: np.ndarray, source: str | None) -> None:
    """The tilt angles are within (-90, 90) deg (``CameraError`` naming the field)."""
    c = np.asarray(coefficients)
    if c.size > 12 and not (abs(c[12]) < math.pi / 2 and abs(c[13]) < math.pi / 2):
        raise CameraError("distortion", f"tilt angles tau_x={c[12]:g}, tau_y={c[13]:g} rad "
                                        "must be within (-pi/2, pi/2)", source)
