"""Central radial lens models as lens maps on the pinhole's normalised coordinates.

A central camera whose image is rotationally symmetric about the principal point maps a
ray at the angle ``theta`` from the optical axis to the normalised radius ``rho(theta)``
(the pixel is then ``K (rho (X, Y) / sqrt(X^2 + Y^2))``). For a ray in front of the
camera (``Z > 0``) with pinhole coordinates ``m = (X/Z, Y/Z)``, ``r = |m| = tan(theta)``,
so the model is the pinhole followed by the radial lens map ``D(m) = f(r) m`` with
``f(r) = rho(atan r) / r``: the form of :class:`vision.cameras.lens.Lens`, through which
the perspective pipeline (lines of the ideal image ``K m``, curves through the lens)
handles these lenses. The models:

- :class:`KannalaBrandt`: OpenCV's ``cv2.fisheye`` (Kalibr's ``pinhole-equi``),
  ``rho = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8)``, computed as
  ``cv2.fisheye.projectPoints`` does (``theta = atan(r)``).
- :class:`DoubleSphere` (Usenko, Demmel & Cremers, 3DV 2018; Kalibr's ``ds``),
  ``(xi, alpha)``: for ``X = (x, y, 1)``, ``d1 = |X|``, ``d2 = |(x, y, xi d1 + 1)|``,
  ``f = 1 / (alpha d2 + (1 - alpha) (xi d1 + 1))``.
- :class:`ExtendedUnified` (Khomutenko, Garcia & Martinet, RA-L 2016; Kalibr's
  ``eucm``), ``(alpha, beta)``: ``f = 1 / (alpha sqrt(beta r^2 + 1) + 1 - alpha)``.

Only rays in front of the camera are imaged (``Z > 0``, a field of view below 180 deg,
as ``cv2.fisheye``). The fold radius is where ``rho`` stops increasing (or its
denominator vanishes), the same in every direction; the inverse solves
``rho(theta) = |m_d|`` on ``[0, min(theta_fold, pi/2))`` by Newton's method safeguarded
by bisection (NaN beyond: no ray of the half-space in front maps there).
"""

from __future__ import annotations

import math
from abc import abstractmethod
from functools import lru_cache
from typing import Any

import numpy as np

from vision.cameras.lens import FOLD_DIRECTIONS, Lens
from vision.exceptions import CameraError

#: Incidence angles of the fold search grid [rad] (up to 90 deg).
THETA_GRID = np.linspace(0.0, 0.5 * math.pi, 4001)[1:]
#: Below this pinhole radius the factor is its limit at the centre (as cv2.fisheye).
SMALL_RADIUS = 1e-8


class RadialLens(Lens):
    """A central radial model as a lens map (see the module docstring).

    Attributes:
        coefficients: Read-only model parameters (the order of :attr:`names`).
    """

    def __init__(self, coefficients: Any, source: str | None = None) -> None:
        c = np.array(coefficients, dtype=float).reshape(-1)
        if c.size != len(self.names) or not np.all(np.isfinite(c)):
            raise CameraError("distortion", f"expected {len(self.names)} finite numbers "
                                            f"({', '.join(self.names)}), got {c.tolist()}",
                              source)
        self._check(c, source)
        c.flags.writeable = False
        self.coefficients = c

    def _check(self, c: np.ndarray, source: str | None) -> None:
        """Refuse parameters outside the model's range (``CameraError``)."""

    def __eq__(self, other: object) -> bool:
        if type(other) is not type(self):
            return NotImplemented
        return bool(np.array_equal(self.coefficients, other.coefficients))  # type: ignore[attr-defined]

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        terms = ", ".join(f"{n}={c:g}" for n, c in zip(self.names, self.coefficients,
                                                      strict=True))
        return f"{type(self).__name__}({terms})"

    @property
    def is_radial(self) -> bool:
        return True

    # ------------------------------------------------------------ the model
    @abstractmethod
    def rho(self, theta: np.ndarray) -> np.ndarray:
        """Normalised image radius of rays at the angles ``theta`` [rad] off the axis."""

    @abstractmethod
    def drho(self, theta: np.ndarray) -> np.ndarray:
        """``d rho / d theta``."""

    @abstractmethod
    def _factor(self, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``f(r)`` and ``f'(r) / r`` at pinhole radii ``r`` (finite at 0)."""

    # ------------------------------------------------------------ the map
    def apply(self, m: np.ndarray) -> np.ndarray:
        """``f(|m|) m`` (..., 2) of pinhole coordinates ``m`` (..., 2)."""
        m = np.asarray(m, dtype=float)
        f, _ = self._factor(np.hypot(m[..., 0], m[..., 1]))
        return m * f[..., None]

    def parts(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, ...]:
        """The map and its (symmetric) Jacobian ``f I + (f'/r) m m^T`` as arrays."""
        f, h = self._factor(np.hypot(x, y))
        j12 = h * x * y
        return x * f, y * f, f + h * x * x, j12, j12, f + h * y * y

    def jacobian(self, m: np.ndarray) -> np.ndarray:
        """``d m_d / d m`` (..., 2, 2)."""
        m = np.asarray(m, dtype=float)
        _, _, j11, j12, j21, j22 = self.parts(m[..., 0], m[..., 1])
        return np.stack([np.stack([j11, j12], -1), np.stack([j21, j22], -1)], -2)

    # ------------------------------------------------------------ folds, inverse
    @property
    def theta_max(self) -> float:
        """The largest incidence angle imaged one-to-one [rad]: the fold, or 90 deg."""
        return _fold_angle(type(self), tuple(float(c) for c in self.coefficients))

    @property
    def rho_max(self) -> float:
        """The normalised image radius at :attr:`theta_max` (inf for a pinhole-like
        model whose image is unbounded)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            v = float(self.rho(np.array([self.theta_max]))[0])
        return v if math.isfinite(v) and v > 0 else math.inf

    def fold_radius(self, theta: np.ndarray) -> np.ndarray:
        """Pinhole radius of the fold (the same in every direction ``theta``); inf when
        ``rho`` increases up to 90 deg."""
        t = self.theta_max
        r = math.tan(t) if t < 0.5 * math.pi else math.inf
        return np.full(np.atleast_1d(np.asarray(theta)).shape, r)

    @property
    def _fold_table(self) -> tuple[np.ndarray, np.ndarray]:
        theta = np.linspace(-math.pi, math.pi, FOLD_DIRECTIONS, endpoint=False)
        return theta, self.fold_radius(theta)

    def _radial_guess(self, md: np.ndarray) -> np.ndarray:
        return self.remove(md)

    def remove(self, md: np.ndarray) -> np.ndarray:
        """Pinhole coordinates ``m`` (..., 2) with ``apply(m) = md``: ``rho(theta) = |md|``
        solved on ``[0, theta_max)``; NaN where ``|md| >= rho_max`` (no pre-image in
        front of the camera) or ``md`` is not finite."""
        md = np.asarray(md, dtype=float)
        rho_d = np.hypot(md[..., 0], md[..., 1])
        t_max = self.theta_max
        ok = np.isfinite(rho_d) & (rho_d < self.rho_max)
        target = np.where(ok, rho_d, 0.0)
        lo = np.zeros(target.shape)
        hi = np.full(target.shape, t_max)
        # Start: the equidistant guess, inside the bracket.
        t = np.clip(target, 0.0, 0.5 * t_max)
        for _ in range(100):
            with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
                g = self.rho(t) - target
                dg = self.drho(t)
            lo = np.where(g <= 0, t, lo)
            hi = np.where(g > 0, t, hi)
            with np.errstate(invalid="ignore", divide="ignore"):
                nt = t - g / dg
            inside = np.isfinite(nt) & (nt > lo) & (nt < hi)
            nt = np.where(inside, nt, 0.5 * (lo + hi))
            step = np.abs(nt - t)
            t = nt
            if not np.any(step > 4e-16 * np.maximum(t, 1e-300)):
                break
        with np.errstate(invalid="ignore", divide="ignore"):
            scale = np.where(target > 0, np.tan(t) / np.where(target > 0, target, 1.0),
                             1.0 / float(self.drho(np.zeros(1))[0]))
        out = md * scale[..., None]
        return np.where(ok[..., None], out, np.nan)


@lru_cache(maxsize=64)
def _fold_angle(model: type[RadialLens], coefficients: tuple[float, ...]) -> float:
    """The first angle in ``(0, 90 deg)`` where ``drho`` or ``rho`` stops being positive
    (60 bisections in the first grid interval where it does), else 90 deg."""
    lens = model(coefficients)
    with np.errstate(all="ignore"):
        good = (lens.drho(THETA_GRID) > 0) & (lens.rho(THETA_GRID) > 0)
    if good.all():
        return 0.5 * math.pi
    k = int(np.argmin(good))
    lo = float(THETA_GRID[k - 1]) if k > 0 else 0.0
    hi = float(THETA_GRID[k])
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        with np.errstate(all="ignore"):
            ok = (lens.drho(np.array([mid])) > 0) & (lens.rho(np.array([mid])) > 0)
        lo, hi = (mid, hi) if bool(ok[0]) else (lo, mid)
    return lo


class KannalaBrandt(RadialLens):
    """OpenCV's fisheye model (``cv2.fisheye``), ``(k1, k2, k3, k4)``."""

    names = ("k1", "k2", "k3", "k4")

    @property
    def is_identity(self) -> bool:
        """Never: with zero coefficients the lens is equidistant, not a pinhole."""
        return False

    def rho(self, theta: np.ndarray) -> np.ndarray:
        k1, k2, k3, k4 = (float(c) for c in self.coefficients)
        t2 = theta * theta
        return np.asarray(theta * (1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4)))))

    def drho(self, theta: np.ndarray) -> np.ndarray:
        k1, k2, k3, k4 = (float(c) for c in self.coefficients)
        t2 = theta * theta
        return np.asarray(1.0 + t2 * (3.0 * k1 + t2 * (5.0 * k2 + t2 * (7.0 * k3
                                                                      + 9.0 * k4 * t2))))

    def _factor(self, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        k1, k2, k3, k4 = (float(c) for c in self.coefficients)
        small = r <= SMALL_RADIUS
        rr = np.where(small, 1.0, r)
        theta = np.arctan(rr)
        t2 = theta * theta
        t4 = t2 * t2
        t6 = t4 * t2
        t8 = t4 * t4
        theta_d = theta * (1.0 + k1 * t2 + k2 * t4 + k3 * t6 + k4 * t8)  # as OpenCV
        f = theta_d / rr
        h = (self.drho(theta) / (1.0 + rr * rr) - f) / (rr * rr)
        return np.where(small, 1.0, f), np.where(small, 2.0 * (k1 - 1.0 / 3.0), h)


class DoubleSphere(RadialLens):
    """The double sphere model, ``(xi, alpha)`` (Usenko et al. 2018; Kalibr ``ds``)."""

    names = ("xi", "alpha")

    def _check(self, c: np.ndarray, source: str | None) -> None:
        if not (-1.0 < c[0] < 1.0 and 0.0 <= c[1] <= 1.0):
            raise CameraError("distortion", f"double sphere needs -1 < xi < 1 and "
                                            f"0 <= alpha <= 1, got xi={c[0]:g}, "
                                            f"alpha={c[1]:g}", source)

    def rho(self, theta: np.ndarray) -> np.ndarray:
        xi, a = (float(c) for c in self.coefficients)
        s, c = np.sin(theta), np.cos(theta)
        d2 = np.sqrt(s * s + (xi + c) ** 2)
        return np.asarray(s / (a * d2 + (1.0 - a) * (xi + c)))

    def drho(self, theta: np.ndarray) -> np.ndarray:
        xi, a = (float(c) for c in self.coefficients)
        s, c = np.sin(theta), np.cos(theta)
        d2 = np.sqrt(s * s + (xi + c) ** 2)
        den = a * d2 + (1.0 - a) * (xi + c)
        return np.asarray((c * den + s * s * (a * xi / d2 + 1.0 - a)) / (den * den))

    def _factor(self, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        xi, a = (float(c) for c in self.coefficients)
        d1 = np.sqrt(r * r + 1.0)
        w = xi * d1 + 1.0
        d2 = np.sqrt(r * r + w * w)
        den = a * d2 + (1.0 - a) * w
        # d den / d r, divided by r: d1' = r / d1, d2' = (r + w xi d1') / d2.
        dden_r = a * (1.0 + w * xi / d1) / d2 + (1.0 - a) * xi / d1
        return 1.0 / den, -dden_r / (den * den)


class ExtendedUnified(RadialLens):
    """The extended unified model, ``(alpha, beta)`` (Khomutenko et al. 2016; Kalibr
    ``eucm``)."""

    names = ("alpha", "beta")

    @property
    def is_identity(self) -> bool:
        """The pinhole when ``alpha = 0`` (whatever ``beta``)."""
        return bool(self.coefficients[0] == 0)

    def _check(self, c: np.ndarray, source: str | None) -> None:
        if not (0.0 <= c[0] <= 1.0 and c[1] > 0.0):
            raise CameraError("distortion", f"extended unified needs 0 <= alpha <= 1 and "
                                            f"beta > 0, got alpha={c[0]:g}, beta={c[1]:g}",
                              source)

    def rho(self, theta: np.ndarray) -> np.ndarray:
        a, b = (float(c) for c in self.coefficients)
        s, c = np.sin(theta), np.cos(theta)
        return np.asarray(s / (a * np.sqrt(b * s * s + c * c) + (1.0 - a) * c))

    def drho(self, theta: np.ndarray) -> np.ndarray:
        a, b = (float(c) for c in self.coefficients)
        s, c = np.sin(theta), np.cos(theta)
        d = np.sqrt(b * s * s + c * c)
        den = a * d + (1.0 - a) * c
        dden = a * (b - 1.0) * s * c / d - (1.0 - a) * s
        return np.asarray((c * den - s * dden) / (den * den))

    def _factor(self, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        a, b = (float(c) for c in self.coefficients)
        d = np.sqrt(b * r * r + 1.0)
        den = a * d + 1.0 - a
        return 1.0 / den, -(a * b / d) / (den * den)
