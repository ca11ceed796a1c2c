"""The limit QP solver (``docs/math.md`` section 6, "QP variant"): both limits act on the
rows ``J_inv tau``, one pair of bounds per leg (:func:`velocity_bounds`). Solved with
OSQP (:class:`~controllers.solvers.osqp_limits.LimitQP`, warm-started), unless the
unconstrained optimum (the compiled law core's) clears every bound with the default
OSQP settings: it is then the QP optimum (:meth:`LimitQPSolver.solve`,
:mod:`controllers.law_rows`, the same test in C).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from controllers.base import ControllerContext
from controllers.exceptions import OptionError
from controllers.law_kernel import LawResult
from controllers.law_tools import check_count, check_flag, check_number
from controllers.solvers.base import Solved, Solver
from controllers.solvers.osqp_limits import OSQP_DEFAULTS, LimitQP


@dataclass(frozen=True)
class StrokeWindow:
    """The limits of the QP laws for one trial.

    Attributes:
        lower: Lowest leg length allowed, ``q_min + margin`` [m].
        upper: Highest leg length allowed, ``q_max - margin`` [m].
        max_speed: Leg speed limit [m/s].
        dt: Control period [s].
    """

    lower: float
    upper: float
    max_speed: float
    dt: float


def velocity_bounds(q: np.ndarray, lower: Any, upper: Any, max_speed: Any, inv_dt: Any
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The bounds on the leg velocities ``J_inv tau`` of one period (the QP solver's, its
    batched rows' and the predictive controller's first move's): reaching ``lower`` /
    ``upper`` within the period, clipped to the speed limit (never an empty window). One
    trial (scalars, ``q`` (6,)) or a batch (``(n, 1)`` columns, ``q`` (n, 6)).

    Returns:
        The stroke rates ``(lower - q) / dt`` and ``(upper - q) / dt`` [m/s], and the
        bounds ``lo``, ``hi`` [m/s].
    """
    stroke_lo = (lower - q) * inv_dt
    stroke_hi = (upper - q) * inv_dt
    # np.clip, without its Python wrapper (a few microseconds each).
    lo = np.minimum(np.maximum(stroke_lo, -max_speed), max_speed)
    hi = np.minimum(np.maximum(stroke_hi, -max_speed), max_speed)
    return stroke_lo, stroke_hi, lo, hi


class LimitQPSolver(Solver):
    """The QP with stroke (with a margin) and leg-speed limits.

    Args:
        controller: The controller's name (for option errors).
        threshold: Relative singular-value threshold (rank test).
        regularization: ``eps`` (>= 0).
        stroke_margin: Distance kept from the stroke limits [m] (None: the context's).
        max_speed: Leg speed limit [m/s] (None: the geometry's).
        eps_abs: OSQP absolute tolerance.
        eps_rel: OSQP relative tolerance.
        max_iter: OSQP iteration budget.
        shortcut: Skip OSQP when the unconstrained optimum satisfies every bound (None:
            only with the default OSQP settings, so that chosen settings take effect).
        damping: The law's pseudo-inverse damping option, refused unless 0 (the QP has
            ``regularization``).

    Raises:
        OptionError: An option out of range, named.
    """

    core_acceptance = "bounds"

    def __init__(self, controller: str, threshold: float = 1e-6,
                 regularization: float = 1e-12, stroke_margin: float | None = None,
                 max_speed: float | None = None, eps_abs: float = 1e-6, eps_rel: float = 1e-6,
                 max_iter: int = 4000, shortcut: bool | None = None,
                 damping: float = 0.0) -> None:
        name = controller
        if damping:
            raise OptionError(name, "damping", "use 'regularization' with the QP law")
        if shortcut is not None:
            check_flag(name, "shortcut", shortcut)
        if shortcut is None:  # auto: OSQP always runs when its settings were chosen
            shortcut = (eps_abs, eps_rel, max_iter) == OSQP_DEFAULTS
        self.threshold = threshold
        self.shortcut = check_flag(name, "shortcut", shortcut)
        reg = check_number(name, "regularization", regularization, 0.0, strict=False)
        self.stroke_margin = (None if stroke_margin is None else
                              check_number(name, "stroke_margin", stroke_margin, 0.0,
                                           strict=False))
        self.max_speed = (None if max_speed is None else
                          check_number(name, "max_speed", max_speed))
        tol_abs = check_number(name, "eps_abs", eps_abs)
        tol_rel = check_number(name, "eps_rel", eps_rel, 0.0, strict=False)
        #: The OSQP problem (set up once per reset, then updated and warm-started).
        self.qp = LimitQP(reg, tol_abs, tol_rel, check_count(name, "max_iter", max_iter, 1))
        #: This trial's limits (after its reset).
        self.window = StrokeWindow(0.0, 0.0, 0.0, 1.0)
        self._lower = np.zeros(6)
        self._upper = np.zeros(6)

    @property
    def damping2(self) -> float:
        """The compiled core solves ``(L^T L + eps I) tau = -lambda L^T e``: the
        unconstrained optimum of the QP objective."""
        return self.qp.regularization

    def reset(self, context: ControllerContext, controller: str, dt: float) -> None:
        """The limits (context defaults) and a fresh OSQP problem.

        Raises:
            OptionError: The stroke margin leaves no stroke.
        """
        q_min, q_max = context.stroke
        margin = context.stroke_margin if self.stroke_margin is None else self.stroke_margin
        if q_max - margin <= q_min + margin:
            raise OptionError(controller, "stroke_margin",
                              f"{margin} m leaves no stroke in [{q_min}, {q_max}] m")
        self.window = StrokeWindow(q_min + margin, q_max - margin,
                                   float(context.max_speed if self.max_speed is None
                                         else self.max_speed), dt)
        self.qp.reset()

    def solve(self, N: np.ndarray, b: np.ndarray, lam: float, q: np.ndarray, J: np.ndarray,
              pre: LawResult) -> Solved:
        """The QP, or its unconstrained optimum ``-lambda (L^T L + eps I)^-1 L^T e`` (the
        compiled core's ``pre``; the objective is strictly convex) when that clears
        every bound by twice the tolerance under which the diagnostics call a constraint
        active (``1e-6 q_dot_max``); otherwise OSQP solves it (its active set refined
        exactly, :meth:`LimitQP._refine`)."""
        rank, cond, tau, qdot = pre.rank, pre.condition, pre.tau, pre.qdot
        if rank < 6:
            return np.zeros(6), rank, cond, [], None, None
        w = self.window
        vmax = w.max_speed
        stroke_lo, stroke_hi, lo, hi = velocity_bounds(q, w.lower, w.upper, vmax, 1.0 / w.dt)
        self._lower, self._upper = lo, hi  # for finish
        tol = 1e-6 * vmax
        if self.shortcut and (qdot - lo).min() > 2.0 * tol and (hi - qdot).min() > 2.0 * tol:
            return tau, rank, cond, [], None, qdot  # NaN fails the comparisons
        solved, status = self.qp.solve(N, b, lam, J, lo, hi)
        if solved is None:
            return np.zeros(6), rank, cond, [], status, None
        tau = solved
        qdot = J @ tau
        active = [f"leg {int(i)} {'upper stroke' if stroke_hi[i] < vmax else 'speed'}"
                  for i in np.flatnonzero(qdot >= hi - tol)]
        active += [f"leg {int(i)} {'lower stroke' if stroke_lo[i] > -vmax else 'speed'}"
                   for i in np.flatnonzero(qdot <= lo + tol)]
        if status != "solved":
            active.append(f"OSQP status '{status}'")
        return tau, rank, cond, active, None, None

    def finish(self, qdot: np.ndarray) -> np.ndarray:
        """Clip the tolerance-sized violations of the bounds left by the solver."""
        return np.minimum(np.maximum(qdot, self._lower), self._upper)  # np.clip, faster
