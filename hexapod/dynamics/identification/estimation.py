"""Weighted least squares of the base parameters, their standard errors, and physical
consistency (Gautier's IDIM-WLS).

1. Ordinary least squares on every leg's rows; each leg's residual variance
   ``sigma_i^2 = |rho_i|^2 / (N - r / 6)``;
2. the rows of leg ``i`` divided by ``sigma_i`` and the least squares solved again; the
   covariance ``s^2 (W_w^T W_w)^-1`` with ``s^2 = |rho_w|^2 / (6 N - r)`` (about 1), the
   standard error of every base parameter the square root of its diagonal;
3. the standard parameters rebuilt (:meth:`BaseParameters.standard`: the ones the forces
   cannot separate keep the prior, the robot file's) and checked: positive masses,
   non-negative drive parameters, a positive-definite platform tensor within the
   triangle inequality, legs' transverse inertias about their centres of mass
   non-negative. If that fails, the weighted least squares is solved again under those
   constraints (:func:`margins` ``>= 0``, SLSQP), the inseparable standard parameters free
   to move from the prior to a physical split, and :attr:`Estimate.consistency` says
   so. The standard errors are those of the unconstrained model's covariance at the
   estimate (a bound active at the truth makes them conservative).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np
import scipy.optimize

from hexapod.dynamics.drives import DriveParameters
from hexapod.dynamics.identification.base import BaseParameters
from hexapod.dynamics.identification.parameters import N_MECHANISM, STANDARD_NAMES, to_tables
from hexapod.dynamics.inertia import InertiaParameters, inertia_matrix
from hexapod.exceptions import IdentificationError, InertiaError

log = logging.getLogger(__name__)

#: How far inside the physical set the constrained solution is kept (margins' units).
_INSIDE = 1e-7


@dataclass
class Estimate:
    """A weighted least-squares estimate of the base parameters.

    Attributes:
        theta: (r,) base parameters.
        se: (r,) their standard errors.
        covariance: (r, r).
        sigma_legs: (6,) residual standard deviation of every leg's force [N].
        residuals: (N, 6) force residuals [N] (measured minus model).
        condition: Condition number of the weighted base regressor.
        relative_residual: ``|rho| / |f|`` of the unweighted residuals.
        standard: (n,) the standard parameters rebuilt (priors where not identifiable).
        consistency: What the physical-consistency step did (one sentence each).
        unconstrained: (r,) the weighted least squares before any constraint (equal to
            ``theta`` when none was needed).
        converged: False when the constrained solve did not converge (``theta`` is then
            where it stopped: no estimate to give as a robot file).
    """

    theta: np.ndarray
    se: np.ndarray
    covariance: np.ndarray
    sigma_legs: np.ndarray
    residuals: np.ndarray
    condition: float
    relative_residual: float
    standard: np.ndarray
    consistency: list[str] = field(default_factory=list)
    unconstrained: np.ndarray | None = None
    converged: bool = True


#: The smallest singular value of the column-scaled regressor, relative to its largest,
#: that leaves every base parameter determined: beyond a condition of 1e8 the normal
#: equations (condition squared) lose every digit and the covariance is noise (a record
#: of heave alone, condition 8.8e8, gave NaN standard errors).
MIN_SCALED_SINGULAR = 1e-8


def _solve(W: np.ndarray, y: np.ndarray) -> np.ndarray:
    return np.linalg.lstsq(W, y, rcond=None)[0]  # type: ignore[no-any-return]


def weighted_least_squares(Yb: np.ndarray, forces: np.ndarray, basis: BaseParameters,
                           prior: np.ndarray, template: InertiaParameters,
                           drives: DriveParameters, mask: np.ndarray | None = None,
                           constrain: bool = True, q_min: float | None = None) -> Estimate:
    """Estimate the base parameters (module docstring).

    Args:
        Yb: (N, 6, r) base regressor.
        forces: (N, 6) measured leg forces [N].
        basis: The base parameters.
        prior: (n,) standard parameters for what the forces cannot separate.
        template, drives: The robot file's tables (for the consistency check).
        mask: (N, 6) the leg equations to use (default: all), e.g. without the legs
            moving too slowly for the Coulomb model.
        constrain: Solve under the physical constraints when the estimate is not
            physical (False: only say so, e.g. for a coverage study of the intervals).
        q_min: The shortest leg length [m]: each leg part's centre of mass must lie
            on the leg, between its joints (``[0, q_min]`` from its hinge, as a robot
            file requires); None: not checked.

    Raises:
        IdentificationError: Too few samples, a rank-deficient regressor (the excitation
            does not excite every base parameter: the message names the weakest), or
            non-finite data.
    """
    n, _, r = Yb.shape
    if forces.shape != (n, 6):
        raise IdentificationError(f"forces: expected shape ({n}, 6), got {forces.shape}")
    keep = np.ones((n, 6), bool) if mask is None else np.asarray(mask, bool)
    W = Yb[keep]
    y = forces[keep]
    leg = np.nonzero(keep)[1]
    m = y.size
    if not (np.all(np.isfinite(W)) and np.all(np.isfinite(y))):
        raise IdentificationError("non-finite regressor or forces (a bad sample)")
    counts = np.bincount(leg, minlength=6)
    if m < 2 * r or np.any(counts < 2 * r / 6):
        raise IdentificationError(
            f"{m} leg equations (per leg {counts.tolist()}) for {r} base parameters: too "
            f"few, at least {2 * r} and {int(np.ceil(2 * r / 6))} per leg (the samples of a "
            "leg at rest or slower than the mask's speed, 2 mm/s by default, are left out "
            "for the Coulomb model): a longer or a livelier record")
    norms = np.maximum(np.linalg.norm(W, axis=0), 1e-300)
    sv = np.linalg.svd(W / norms, compute_uv=False)
    if sv[-1] < MIN_SCALED_SINGULAR * sv[0]:
        _, _, vt = np.linalg.svd(W / norms, full_matrices=False)
        weakest = basis.names[int(np.argmax(np.abs(vt[-1])))]
        cond = f"{sv[0] / sv[-1]:.3g}" if sv[-1] > 0 else "infinite"
        raise IdentificationError(f"the excitation leaves a base parameter undetermined "
                                  f"(condition {cond}); weakest: {weakest}")
    theta = _solve(W, y)
    rho = y - W @ theta
    dof = counts * (1 - r / m)
    sigma = np.sqrt(np.bincount(leg, rho**2, minlength=6) / dof)
    sigma = np.maximum(sigma, 1e-12 * max(float(np.abs(y).max()), 1e-300))
    Ww = W / sigma[leg, None]
    yw = y / sigma[leg]
    theta = _solve(Ww, yw)
    consistency: list[str] = []
    ok = True
    unconstrained = theta.copy()
    standard = basis.standard(theta, prior)
    problems = _physical_problems(standard, template, drives, q_min)
    if problems and not constrain:
        consistency.append("unconstrained estimate not physical (" + "; ".join(problems)
                           + "): not constrained (asked not to)")
    elif problems:
        consistency.append("unconstrained estimate not physical (" + "; ".join(problems)
                           + "): solved the least squares constrained to physical "
                           "parameters instead (SLSQP)")
        theta, standard, ok = _constrained(Ww, yw, theta, basis, prior, q_min)
        if not ok:
            consistency.append("the constrained solver did not converge")
        moved = [STANDARD_NAMES[j] for j in moved_from_prior(basis, standard, prior)]
        if moved:
            consistency.append("parameters the forces cannot separate moved from the robot "
                               "file's values to a physical split: " + ", ".join(moved))
        left = _physical_problems(standard, template, drives, q_min)
        if left:
            consistency.append("still not physical: " + "; ".join(left))
    else:
        consistency.append("physically consistent as estimated (positive masses, "
                           "non-negative drive parameters, positive-definite platform "
                           "tensor within the triangle inequality"
                           + (", centres of mass on the legs" if q_min is not None else "")
                           + "): no constraint active")
    rho_w = yw - Ww @ theta
    s2 = float(rho_w @ rho_w / (m - r))
    cov = s2 * np.linalg.inv(Ww.T @ Ww)
    rho = y - W @ theta
    residuals = np.full((n, 6), np.nan)
    residuals[keep] = rho
    return Estimate(theta=theta, se=np.sqrt(np.diag(cov)), covariance=cov,
                    sigma_legs=np.sqrt(np.bincount(leg, rho**2, minlength=6) / dof),
                    residuals=residuals, condition=float(np.linalg.cond(Ww)),
                    relative_residual=float(np.linalg.norm(rho) / np.linalg.norm(y)),
                    standard=standard, consistency=consistency, unconstrained=unconstrained,
                    converged=ok)


def moved_from_prior(basis: BaseParameters, standard: np.ndarray, prior: np.ndarray) -> list[int]:
    """The standard parameters the leg forces cannot separate (``basis.dependent``)
    whose value left the robot file's ``prior`` (the constrained fit moved them to a
    physical split); the others are kept at the prior."""
    return [int(j) for j in basis.dependent
            if abs(standard[j] - prior[j]) > 1e-9 * max(abs(prior[j]), 1.0)]


def _physical_problems(standard: np.ndarray, template: InertiaParameters,
                       drives: DriveParameters, q_min: float | None = None) -> list[str]:
    out = []
    d = standard[N_MECHANISM:]
    for k in np.flatnonzero(d < 0):
        out.append(f"{STANDARD_NAMES[N_MECHANISM + int(k)]} = {d[k]:.4g} < 0")
    for name in ("m_b", "m_r"):
        j = STANDARD_NAMES.index(name)
        if standard[j] < 0:
            out.append(f"{name} = {standard[j]:.4g} kg < 0")
    if q_min is not None:  # each part's centre of mass between the leg's joints
        for part, mass, first in (("body", standard[10], standard[11]),
                                  ("rod", standard[14], standard[15])):
            if mass > 0 and not 0.0 <= first / mass <= q_min:
                out.append(f"{part}_com = {first / mass:.4g} m outside the leg [0, "
                           f"{q_min:.4g}] m")
    try:
        to_tables(standard, template, drives)
    except InertiaError as exc:
        out.append(str(exc))
    return out


def margins(standard: np.ndarray, q_min: float | None = None) -> np.ndarray:
    """Physical-consistency margins of standard parameters, each ``>= 0`` when physical:
    the drive parameters, the platform's mass, the smallest principal moment of its
    tensor about the centre of mass and its triangle inequality (scaled by 10 to weigh
    like the masses), the legs' masses and axial inertias, their transverse inertias about
    their centres of mass (at least half the axial) and, given the shortest leg length
    ``q_min`` [m], each leg part's centre of mass on the leg: ``0 <= m d <= m q_min``
    (first moment ``m d``; divided by ``q_min``, in kg)."""
    th = np.asarray(standard, float)
    m = th[0]
    out = [*th[N_MECHANISM:], m]
    if m > 0:
        c = th[1:4] / m
        I_c = inertia_matrix(th[4:10]) - m * (c @ c * np.eye(3) - np.outer(c, c))
        w = np.linalg.eigvalsh(I_c)
        out += [10 * w[0], 10 * (w[0] + w[1] - w[2])]
    else:
        out += [m, m]
    mb, mdb, itb, iab, mr, mdr, itr, iar = th[10:18]
    out += [mb, mr, iab, iar]
    # transverse about the centre of mass at least half the axial (triangle inequality)
    out.append(10 * (itb - (mdb**2 / mb if mb > 0 else 0.0) - iab / 2))
    out.append(10 * (itr - (mdr**2 / mr if mr > 0 else 0.0) - iar / 2))
    if q_min is not None:
        out += [mdb / q_min, mb - mdb / q_min, mdr / q_min, mr - mdr / q_min]
    return np.array(out)


def _constrained(Ww: np.ndarray, yw: np.ndarray, theta: np.ndarray, basis: BaseParameters,
                 prior: np.ndarray, q_min: float | None = None
                 ) -> tuple[np.ndarray, np.ndarray, bool]:
    """The weighted least squares under :func:`margins` ``>= 0`` (SLSQP from the
    unconstrained solution). The standard parameters the forces cannot separate are free
    too (the fit does not depend on them), pulled to the prior by a tiny penalty: the
    physical split closest to the robot file's. Returns the base parameters, the
    standard ones and whether the solver converged.

    The cost is the distance from the unconstrained solution in the metric of the
    normal equations (the least squares' cost up to a constant), normalised, in variables
    scaled by their magnitudes (SLSQP needs both)."""
    r = theta.size
    H = Ww.T @ Ww
    x0 = np.concatenate([theta, prior[basis.dependent]])
    sx = np.maximum(np.abs(x0), 1e-4)
    Hs = H * np.outer(sx[:r], sx[:r])
    Hs /= max(float(np.linalg.norm(Hs, 2)), 1e-300)
    z_free = theta / sx[:r]
    z_prior = x0[r:] / sx[r:]
    penalty = 1e-8

    def standard(z: np.ndarray) -> np.ndarray:
        x = z * sx
        th = np.array(prior, dtype=float)
        th[basis.dependent] = x[r:]
        th[basis.independent] = x[:r] - basis.beta @ x[r:]
        return th

    def cost(z: np.ndarray) -> float:
        e = z[:r] - z_free
        d = z[r:] - z_prior
        return float(e @ Hs @ e) + penalty * float(d @ d)

    def grad(z: np.ndarray) -> np.ndarray:
        return np.concatenate([2 * Hs @ (z[:r] - z_free), 2 * penalty * (z[r:] - z_prior)])

    res = scipy.optimize.minimize(
        cost, x0 / sx, jac=grad, method="SLSQP",
        constraints=[{"type": "ineq",
                      "fun": lambda z: margins(standard(z), q_min) - _INSIDE}],
        options={"maxiter": 2000, "ftol": 1e-16})
    return res.x[:r] * sx[:r], standard(res.x), bool(res.success)
