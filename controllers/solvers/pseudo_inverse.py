"""The classical law's solver: ``tau = -lambda L^+ e`` with a singular-value threshold and
an optional damping, ``(L^T L + mu^2 I)^-1 L^T e`` (``docs/math.md`` section 6); the
adaptive gain ``lambda`` comes with the tasks (:class:`~controllers.law_tools.Gain`)."""

from __future__ import annotations

import numpy as np

from controllers.law_kernel import LawResult
from controllers.solvers.base import Solved, Solver


class DampedPseudoInverse(Solver):
    """``tau = -lambda (L^T L + mu^2 I)^+ L^T e`` over the singular values above threshold.

    Args:
        threshold: Relative singular-value threshold (rank test).
        damping: Damping ``mu``.
    """

    core_acceptance = "core"

    def __init__(self, threshold: float = 1e-6, damping: float = 0.0) -> None:
        self.threshold = threshold
        self.damping = damping

    @property
    def damping2(self) -> float:
        """``mu^2``."""
        return self.damping * self.damping

    def solve(self, N: np.ndarray, b: np.ndarray, lam: float, q: np.ndarray, J: np.ndarray,
              pre: LawResult) -> Solved:
        """The classical solution: the compiled core's."""
        qdot = self.finish(pre.qdot) if pre.qdot_finite else None
        return pre.tau, pre.rank, pre.condition, [], None, qdot
