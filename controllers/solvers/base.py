"""The solver interface: a solver turns one period's stacked tasks
(:class:`~controllers.law_tools.TaskStep`: ``L^T L``, ``L^T e``, the gain, ``J_inv``) and
the measured lengths into a twist and its diagnostics, never seeing the controller that
built them; per-trial constants (the QP's stroke window) come from :meth:`Solver.reset`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from controllers.base import ControllerContext
from controllers.law_kernel import LawResult

#: A solve: ``tau`` (6,), rank, condition, active constraints, refusal reason (or None),
#: and the final ``q_dot`` (6,) when already computed and checked finite (None: the
#: law computes ``finish(J tau)`` and checks it).
Solved = tuple[np.ndarray, int, float, list[str], str | None, np.ndarray | None]


class Solver:
    """Base of the solvers: the identity :meth:`finish`, no per-trial constants.

    Attributes:
        threshold: Relative singular-value threshold of the rank test.
    """

    threshold: float = 1e-6
    #: What the batched step (:mod:`controllers.law_rows`) takes of the compiled core's
    #: classical solution without calling :meth:`solve`: ``"core"`` (it is this solver's
    #: answer at full rank), ``"bounds"`` (it is where it clears the limit QP's bounds)
    #: or ``"none"`` (every row is solved by :meth:`solve`). A subclass that defines its
    #: own :meth:`solve` or :meth:`finish` and not this gets ``"none"``: the compiled
    #: shortcut of the class it extends would pass over its code.
    core_acceptance: str = "none"

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        own = vars(cls)
        if ("solve" in own or "finish" in own) and "core_acceptance" not in own:
            cls.core_acceptance = "none"

    @property
    def damping2(self) -> float:
        """``mu^2`` the compiled law core adds to the eigenvalues of ``L^T L`` (its
        classical solution is then this solver's unconstrained one)."""
        return 0.0

    def reset(self, context: ControllerContext, controller: str, dt: float) -> None:
        """Per-trial constants from the context (nothing by default).

        Args:
            context: The trial's context.
            controller: The controller's name (for errors).
            dt: Control period [s].
        """

    def solve(self, N: np.ndarray, b: np.ndarray, lam: float, q: np.ndarray, J: np.ndarray,
              pre: LawResult) -> Solved:
        """The twist from ``N = L^T L`` (6, 6), ``b = L^T e`` (6,), the gain ``lam``
        [1/s], the lengths ``q`` (6,) [m] and ``J_inv`` (6, 6); ``pre`` is the compiled
        core's result of the period."""
        raise NotImplementedError

    def finish(self, qdot: np.ndarray) -> np.ndarray:
        """Last touch on the leg velocities [m/s] (identity)."""
        return qdot
