"""Base parameters: the combinations of standard parameters the leg forces determine.

Standard practice (Gautier 1991): stack the regressor at many random states, choose
``r`` independent columns ``W_1`` (the rank), then ``W_1 theta_1 + W_2 theta_2 = W_1
(theta_1 + beta theta_2)`` with ``W_2 = W_1 beta``: the base parameters are
``theta_b = theta_1 + beta theta_2``, each named as that combination. Columns that are
zero at every state (parameters that do not enter, e.g. the legs' axial inertias) fall
in ``theta_2`` with no effect.

The independent columns are the first ones, in a fixed order of preference
(:data:`PREFERENCE`: the platform's, then the rods', the bodies', the drives'), that add
to the rank (Gram-Schmidt on the unit-norm columns). A QR with column pivoting chose
among columns of equal norm by rounding: the same robot gave ``m_p + 6 m_r`` or
``m_r + 0.167 m_p`` with the seed of the states, or with its points rounded at 1e-13 m
through a file, and the robot file written from the estimate split the masses
differently (a platform of 1.45 kg or 2.0 kg for the same data).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hexapod.dynamics.identification.parameters import STANDARD_NAMES, unit
from hexapod.dynamics.identification.regressor import regressor
from hexapod.geometry import HexapodGeometry
from hexapod.se3 import exp_so3
from hexapod.workspace import home_pose

#: Threshold on the part of a unit-norm column outside the span of those chosen before
#: it, for it to add to the rank.
RANK_TOLERANCE = 1e-8
#: The standard parameters in the order the base parameters prefer them as independent:
#: the platform's, the rods', the bodies', then the drives'.
PREFERENCE = (tuple(range(10))
              + tuple(STANDARD_NAMES.index(n) for n in ("m_r", "md_r", "It_r", "Ia_r", "m_b",
                                                        "md_b", "It_b", "Ia_b"))
              + tuple(range(18, len(STANDARD_NAMES))))
#: A coefficient of ``beta`` below this is rounding and dropped from the names.
COEFFICIENT_TOLERANCE = 1e-9


@dataclass(frozen=True)
class BaseParameters:
    """The base parameters of a mechanism.

    Attributes:
        independent: (r,) indices of the standard parameters kept (``theta_1``).
        dependent: (n - r,) the others (``theta_2``).
        beta: (r, n - r) ``theta_b = theta_1 + beta theta_2``.
        names: (r,) each base parameter as a combination of standard ones.
        unidentifiable: Standard parameters that enter no base parameter at all
            (their columns are zero: they do not enter the dynamics).
    """

    independent: np.ndarray
    dependent: np.ndarray
    beta: np.ndarray
    names: tuple[str, ...]
    unidentifiable: tuple[str, ...]

    @property
    def size(self) -> int:
        """Number of base parameters."""
        return int(self.independent.size)

    def of(self, theta: np.ndarray) -> np.ndarray:
        """The base parameters (r,) of standard parameters ``theta``."""
        th = np.asarray(theta, float)
        return th[self.independent] + self.beta @ th[self.dependent]  # type: ignore[no-any-return]

    def columns(self, Y: np.ndarray) -> np.ndarray:
        """The base regressor: the independent columns of a standard regressor (..., n)."""
        return Y[..., self.independent]

    def standard(self, theta_base: np.ndarray, prior: np.ndarray) -> np.ndarray:
        """A standard vector with base parameters ``theta_base``: the dependent ones keep
        ``prior`` (e.g. the robot file's), the independent ones absorb the rest."""
        th = np.array(prior, dtype=float)
        th[self.independent] = theta_base - self.beta @ th[self.dependent]
        return th


def random_states(geometry: HexapodGeometry, n: int, rng: np.random.Generator
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``n`` random states about the home pose: poses (+-20 mm, +-10 deg), twists and
    accelerations (the rank does not depend on their magnitude)."""
    R0, t0 = home_pose(geometry)
    R = exp_so3(np.deg2rad(10.0) * rng.uniform(-1, 1, (n, 3))) @ R0
    t = t0 + 0.02 * rng.uniform(-1, 1, (n, 3))
    twist = np.concatenate([0.05 * rng.standard_normal((n, 3)),
                            0.5 * rng.standard_normal((n, 3))], axis=1)
    acc = np.concatenate([rng.standard_normal((n, 3)), 10 * rng.standard_normal((n, 3))],
                         axis=1)
    return R, t, twist, acc


def _combination(k: int, beta_row: np.ndarray, dependent: np.ndarray) -> str:
    terms = [STANDARD_NAMES[k]]
    for coef, j in zip(beta_row, dependent, strict=True):
        if abs(coef) > COEFFICIENT_TOLERANCE:
            u_k, u_j = unit(STANDARD_NAMES[k]), unit(STANDARD_NAMES[j])
            scale = f" [{u_k}/{u_j}]" if u_k != u_j else ""
            size = f"{abs(coef):.6g}"  # (a coefficient of 1 is not written)
            factor = "" if size == "1" and not scale else f"{size}{scale} "
            terms.append(f"{'+' if coef > 0 else '-'} {factor}{STANDARD_NAMES[j]}")
    return " ".join(terms)


def base_parameters(geometry: HexapodGeometry, samples: int = 400, seed: int = 0
                    ) -> BaseParameters:
    """The base parameters of ``geometry`` by a numerical QR (module docstring).

    Args:
        geometry: The robot (points, gravity).
        samples: Random states stacked.
        seed: Their generator's seed.
    """
    R, t, twist, acc = random_states(geometry, samples, np.random.default_rng(seed))
    Y, _, _ = regressor(geometry, R, t, twist, acc)
    W = Y.reshape(-1, Y.shape[-1])
    norms = np.linalg.norm(W, axis=0)
    zero = norms <= 1e-12 * norms.max()
    V = W / np.where(zero, 1.0, norms)
    basis = np.zeros((V.shape[0], 0))
    chosen = []
    for j in PREFERENCE:  # the first that add to the rank (Gram-Schmidt, twice)
        if zero[j]:
            continue
        r = V[:, j] - basis @ (basis.T @ V[:, j])
        r -= basis @ (basis.T @ r)
        size = float(np.linalg.norm(r))
        if size > RANK_TOLERANCE:
            basis = np.column_stack([basis, r / size])
            chosen.append(j)
    independent = np.array(sorted(chosen), int)
    rank = independent.size
    dependent = np.array([j for j in range(W.shape[1]) if j not in set(independent)], int)
    # beta from the unscaled columns: W_2 = W_1 beta  (exact for a rank-deficient W)
    W1, W2 = W[:, independent], W[:, dependent]
    beta = np.linalg.lstsq(W1, W2, rcond=None)[0] if dependent.size else np.zeros((rank, 0))
    beta[np.abs(beta) < COEFFICIENT_TOLERANCE] = 0.0
    names = tuple(_combination(k, beta[i], dependent) for i, k in enumerate(independent))
    unidentifiable = tuple(STANDARD_NAMES[j] for j in dependent if zero[j])
    return BaseParameters(independent, dependent, beta, names, unidentifiable)
