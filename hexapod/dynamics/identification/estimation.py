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
   triangle inequality. If that fails, the bounded least squares
   (``scipy.optimize.lsq_linear``: the drive parameters and the platform's mass combination
   bounded below) is solved instead, and a tensor still not positive definite is
   projected onto the nearest one with principal moments ``>= 1e-9`` kg m^2 (both said
   in :attr:`Estimate.consistency`).
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


def _solve(W: np.ndarray, y: np.ndarray) -> np.ndarray:
    return np.linalg.lstsq(W, y, rcond=None)[0]  # type: ignore[no-any-return]


def weighted_least_squares(Yb: np.ndarray, forces: np.ndarray, basis: BaseParameters,
                           prior: np.ndarray, template: InertiaParameters,
                           drives: DriveParameters, mask: np.ndarray | None = None
                           ) -> Estimate:
    """Estimate the base parameters (module docstring).

    Args:
        Yb: (N, 6, r) base regressor.
        forces: (N, 6) measured leg forces [N].
        basis: The base parameters.
        prior: (n,) standard parameters for what the forces cannot separate.
        template, drives: The robot file's tables (for the consistency check).
        mask: (N, 6) the leg equations to use (default: all), e.g. without the legs
            moving too slowly for the Coulomb model.

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
        raise IdentificationError(f"{m} leg equations (per leg {counts.tolist()}) for {r} "
                                  "base parameters: too few")
    norms = np.maximum(np.linalg.norm(W, axis=0), 1e-300)
    sv = np.linalg.svd(W / norms, compute_uv=False)
    if sv[-1] < 1e-10 * sv[0]:
        _, _, vt = np.linalg.svd(W / norms)
        weakest = basis.names[int(np.argmax(np.abs(vt[-1])))]
        raise IdentificationError(f"the excitation leaves a base parameter undetermined "
                                  f"(condition {sv[0] / sv[-1]:.3g}); weakest: {weakest}")
    theta = _solve(W, y)
    rho = y - W @ theta
    dof = counts * (1 - r / m)
    sigma = np.sqrt(np.bincount(leg, rho**2, minlength=6) / dof)
    sigma = np.maximum(sigma, 1e-12 * max(float(np.abs(y).max()), 1e-300))
    Ww = W / sigma[leg, None]
    yw = y / sigma[leg]
    theta = _solve(Ww, yw)
    consistency: list[str] = []
    standard = basis.standard(theta, prior)
    problems = _physical_problems(standard, template, drives)
    if problems:
        consistency.append("unconstrained estimate not physical (" + "; ".join(problems)
                           + "): solved the bounded least squares instead")
        theta = _bounded(Ww, yw, theta, basis, prior)
        standard = basis.standard(theta, prior)
        standard, projected = _project_tensor(standard)
        if projected:
            consistency.append(projected)
        left = _physical_problems(standard, template, drives)
        if left:
            consistency.append("still not physical: " + "; ".join(left))
    else:
        consistency.append("physically consistent as estimated (positive masses, "
                           "non-negative drive parameters, positive-definite platform "
                           "tensor within the triangle inequality): no constraint active")
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
                    standard=standard, consistency=consistency)


def _physical_problems(standard: np.ndarray, template: InertiaParameters,
                       drives: DriveParameters) -> list[str]:
    out = []
    d = standard[N_MECHANISM:]
    for k in np.flatnonzero(d < 0):
        out.append(f"{STANDARD_NAMES[N_MECHANISM + k]} = {d[k]:.4g} < 0")
    for name in ("m_b", "m_r"):
        k = STANDARD_NAMES.index(name)
        if standard[k] < 0:
            out.append(f"{name} = {standard[k]:.4g} kg < 0")
    try:
        to_tables(standard, template, drives)
    except InertiaError as exc:
        out.append(str(exc))
    return out


def _bounded(Ww: np.ndarray, yw: np.ndarray, theta: np.ndarray, basis: BaseParameters,
             prior: np.ndarray) -> np.ndarray:
    """The least squares with the drive parameters non-negative and the platform mass
    combination (``m_p`` plus what regroups with it) above the regrouped prior's share."""
    r = theta.size
    lo, hi = np.full(r, -np.inf), np.full(r, np.inf)
    for i, k in enumerate(basis.independent):
        if k >= N_MECHANISM:
            lo[i] = 0.0
        elif STANDARD_NAMES[k] == "m_p":
            lo[i] = float(basis.beta[i] @ prior[basis.dependent]) + 1e-6
    res = scipy.optimize.lsq_linear(Ww, yw, bounds=(lo, hi), method="bvls")
    return res.x  # type: ignore[no-any-return]


def _project_tensor(standard: np.ndarray) -> tuple[np.ndarray, str]:
    """Project the platform tensor about its centre of mass onto principal moments
    ``>= 1e-9`` kg m^2 (and the triangle inequality), keeping its axes."""
    th = standard.copy()
    m = th[0]
    c = th[1:4] / m
    shift = m * (c @ c * np.eye(3) - np.outer(c, c))
    I_c = inertia_matrix(th[4:10]) - shift
    w, V = np.linalg.eigh(I_c)
    w2 = np.maximum(w, 1e-9)
    w2[2] = min(w2[2], w2[0] + w2[1])
    if np.allclose(w, w2):
        return th, ""
    I_new = V @ np.diag(w2) @ V.T + shift
    th[4:10] = [I_new[0, 0], I_new[1, 1], I_new[2, 2], I_new[0, 1], I_new[0, 2], I_new[1, 2]]
    return th, (f"platform tensor projected: principal moments {np.round(w, 9).tolist()} -> "
                f"{np.round(w2, 9).tolist()} kg m^2")
