"""QP variants of the vision laws with stroke and leg-speed limits (``MATH.md`` section 6).

Choose the twist ``tau`` minimising ``|L tau + lambda e|^2 + eps |tau|^2`` subject to

``q_min + margin <= q + dt J_inv tau <= q_max - margin`` and ``|J_inv tau| <= q_dot_max``,

then ``q_dot = J_inv tau``. Both constraints act on the same rows ``J_inv tau``, so
they merge into one pair of bounds per leg (each bound clipped to the speed
limit, so the problem stays feasible even when a leg starts inside the margin).
Solved with OSQP (1.x API), warm-started from the previous step. Away from the
limits (and with ``eps -> 0``) the solution is the classical ``-lambda L^+ e``; at
a limit the platform slides along it instead of one leg being saturated.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import osqp
import scipy.sparse as sp

from controllers.base import ControllerContext
from controllers.exceptions import OptionError
from controllers.laws import VisionLaw, check_number
from controllers.leg_direction import LegDirectionController
from controllers.leg_edge import LegEdgeController

log = logging.getLogger(__name__)

# Column-major upper triangle of a 6x6 matrix (the CSC order of OSQP's P).
_TRI_ROWS = np.array([i for j in range(6) for i in range(j + 1)])
_TRI_COLS = np.array([j for j in range(6) for _ in range(j + 1)])
_TRI_PTR = np.concatenate([[0], np.cumsum(np.arange(1, 7))])
_FULL_ROWS = np.tile(np.arange(6), 6)
_FULL_PTR = np.arange(0, 37, 6)


class LimitQP:
    """The OSQP problem of one controller (6 variables, 6 two-sided constraints).

    Args:
        regularization: ``eps`` of the objective (>= 0) [same units as ``L^T L``].
        eps_abs: OSQP absolute tolerance.
        eps_rel: OSQP relative tolerance.
        max_iter: OSQP iteration budget.
        active_tolerance: Distance to a bound [m/s] under which a constraint with a
            multiplier of the right sign is taken as active by the refinement.
    """

    def __init__(self, regularization: float = 1e-12, eps_abs: float = 1e-6,
                 eps_rel: float = 1e-6, max_iter: int = 4000,
                 active_tolerance: float = 1e-6) -> None:
        self.regularization = regularization
        self.active_tolerance = active_tolerance
        self.settings = {"verbose": False, "warm_starting": True, "polishing": False,
                         "eps_abs": eps_abs, "eps_rel": eps_rel, "max_iter": max_iter,
                         "check_termination": 10}
        self._solver: Any = None
        self._P = np.zeros((6, 6))
        self._eye_eps = regularization * np.eye(6)

    def reset(self) -> None:
        """Forget the previous problem (the next solve sets OSQP up again)."""
        self._solver = None

    def solve(self, N: np.ndarray, b: np.ndarray, lam: float, J: np.ndarray,
              lower: np.ndarray, upper: np.ndarray) -> tuple[np.ndarray | None, str]:
        """Solve for ``tau``.

        Args:
            N: (6, 6) ``L^T L`` of the stacked interaction matrix ``L``.
            b: (6,) ``L^T e`` with the stacked error ``e``.
            lam: Gain [1/s].
            J: (6, 6) inverse Jacobian.
            lower: (6,) lower bounds on ``J tau`` [m/s].
            upper: (6,) upper bounds on ``J tau`` [m/s].

        Returns:
            ``tau`` (None on failure) and the OSQP status (or the failure reason).
        """
        P = N + self._eye_eps
        P *= 2.0
        c = (2.0 * lam) * b
        if not (np.all(np.isfinite(P)) and np.all(np.isfinite(c)) and np.all(np.isfinite(J))
                and np.all(np.isfinite(lower)) and np.all(np.isfinite(upper))):
            return None, "non-finite QP data"
        if np.any(lower > upper):
            return None, "empty stroke window (lower bound above upper bound)"
        Px = P[_TRI_ROWS, _TRI_COLS]
        Ax = J.T.reshape(-1)
        try:
            if self._solver is None:
                solver = osqp.OSQP()
                solver.setup(sp.csc_matrix((Px, _TRI_ROWS, _TRI_PTR), shape=(6, 6)), c,
                             sp.csc_matrix((Ax.copy(), _FULL_ROWS, _FULL_PTR), shape=(6, 6)),
                             lower, upper, **self.settings)
                self._solver = solver
            else:
                self._solver.update(q=c, l=lower, u=upper, Px=Px, Ax=Ax)
            res = self._solver.solve(raise_error=False)
        except (ValueError, RuntimeError, osqp.OSQPException) as exc:
            self._solver = None
            return None, f"OSQP error: {exc}"
        status = res.info.status_val
        if status not in (osqp.SolverStatus.OSQP_SOLVED, osqp.SolverStatus.OSQP_SOLVED_INACCURATE):
            self._solver = None  # do not warm-start from a failed solve
            return None, f"QP not solved: OSQP status '{res.info.status}'"
        x = np.asarray(res.x, dtype=float)
        if x.shape != (6,) or not np.all(np.isfinite(x)):
            self._solver = None
            return None, f"QP returned a non-finite solution (status '{res.info.status}')"
        return self._refine(P, c, J, lower, upper, x, np.asarray(res.y, dtype=float)), \
            str(res.info.status)

    def _refine(self, P: np.ndarray, c: np.ndarray, J: np.ndarray, lower: np.ndarray,
                upper: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Solve the KKT system of the active set OSQP found (what OSQP's polishing does).

        ADMM stops at a tolerance; with the active set fixed, the equality-constrained
        problem is solved exactly (6 + k unknowns). Without active constraints this is
        the classical ``-P^-1 c``. The refined point is kept only if it is feasible
        and its multipliers have the right signs; otherwise OSQP's point is returned.
        (OSQP's own polisher prints to stdout even with ``verbose=False``.)
        """
        Jx = J @ x
        tol = self.active_tolerance
        at_up = (Jx >= upper - tol) & (y > 0)
        at_lo = (Jx <= lower + tol) & (y < 0)
        act = at_up | at_lo
        k = int(np.count_nonzero(act))
        try:
            if k == 0:
                xr = np.linalg.solve(P, -c)
                nu = np.zeros(0)
            else:
                Ja = J[act]
                K = np.zeros((6 + k, 6 + k))
                K[:6, :6] = P
                K[:6, 6:] = Ja.T
                K[6:, :6] = Ja
                rhs = np.concatenate([-c, np.where(at_up, upper, lower)[act]])
                sol = np.linalg.solve(K, rhs)
                xr, nu = sol[:6], sol[6:]
        except np.linalg.LinAlgError:
            return x
        Jr = J @ xr
        slack = 1e-9 * (1.0 + np.abs(upper - lower))
        feasible = bool(np.all(Jr <= upper + slack) and np.all(Jr >= lower - slack))
        # Multipliers: >= 0 on upper bounds, <= 0 on lower bounds (OSQP's convention).
        signs_ok = bool(np.all(nu[at_up[act]] >= -1e-12) and np.all(nu[at_lo[act]] <= 1e-12))
        if feasible and signs_ok and np.all(np.isfinite(xr)):
            return xr
        return x


class QPLaw(VisionLaw):
    """Mixin of the QP laws: replaces the pseudo-inverse of :class:`VisionLaw` by :class:`LimitQP`.

    Concrete classes call :meth:`_init_qp` from their constructor.
    """

    def _init_qp(self, regularization: float, stroke_margin: float | None,
                 max_speed: float | None, eps_abs: float, eps_rel: float,
                 max_iter: int) -> None:
        reg = check_number(self.name, "regularization", regularization, 0.0, strict=False)
        self.stroke_margin = (None if stroke_margin is None else
                              check_number(self.name, "stroke_margin", stroke_margin, 0.0,
                                           strict=False))
        self.max_speed = (None if max_speed is None else
                          check_number(self.name, "max_speed", max_speed))
        tol_abs = check_number(self.name, "eps_abs", eps_abs)
        tol_rel = check_number(self.name, "eps_rel", eps_rel, 0.0, strict=False)
        if isinstance(max_iter, bool) or not isinstance(max_iter, int) or max_iter < 1:
            raise OptionError(self.name, "max_iter", f"expected a positive integer, got "
                                                     f"{max_iter!r}")
        self.qp = LimitQP(reg, tol_abs, tol_rel, max_iter)
        self._lower = np.zeros(6)
        self._upper = np.zeros(6)

    def reset(self, context: ControllerContext) -> None:
        """As :meth:`VisionLaw.reset`, plus the limits (context defaults) and a fresh solver."""
        super().reset(context)
        q_min, q_max = context.stroke
        margin = context.stroke_margin if self.stroke_margin is None else self.stroke_margin
        if q_max - margin <= q_min + margin:
            raise OptionError(self.name, "stroke_margin",
                              f"{margin} m leaves no stroke in [{q_min}, {q_max}] m")
        self._q_lo = q_min + margin
        self._q_hi = q_max - margin
        self._vmax = float(context.max_speed if self.max_speed is None else self.max_speed)
        self.qp.reset()

    def _solve(self, N: np.ndarray, b: np.ndarray, lam: float, q: np.ndarray, J: np.ndarray
               ) -> tuple[np.ndarray, int, float, list[str], str | None]:
        w = np.linalg.eigvalsh(N)
        w_max = float(w[-1])
        rank = int(np.count_nonzero(w > (self.threshold ** 2) * w_max)) if w_max > 0 else 0
        cond = math.sqrt(w_max / w[0]) if w[0] > 0 else math.inf
        if rank < 6:
            return np.zeros(6), rank, cond, [], None
        inv_dt = 1.0 / self._dt
        vmax = self._vmax
        stroke_lo = (self._q_lo - q) * inv_dt
        stroke_hi = (self._q_hi - q) * inv_dt
        lo = np.clip(stroke_lo, -vmax, vmax, out=self._lower)
        hi = np.clip(stroke_hi, -vmax, vmax, out=self._upper)
        tau, status = self.qp.solve(N, b, lam, J, lo, hi)
        if tau is None:
            return np.zeros(6), rank, cond, [], status
        qdot = J @ tau
        tol = 1e-6 * vmax
        active: list[str] = []
        at_hi = np.flatnonzero(qdot >= hi - tol)
        at_lo = np.flatnonzero(qdot <= lo + tol)
        for i in at_hi:
            active.append(f"leg {int(i)} {'upper stroke' if stroke_hi[i] < vmax else 'speed'}")
        for i in at_lo:
            active.append(f"leg {int(i)} {'lower stroke' if stroke_lo[i] > -vmax else 'speed'}")
        if status != "solved":
            active.append(f"OSQP status '{status}'")
        return tau, rank, cond, active, None

    def _finish(self, qdot: np.ndarray) -> np.ndarray:
        """Clip the tolerance-sized violations of the bounds left by the solver."""
        return np.clip(qdot, self._lower, self._upper)



class LegEdgeQPController(QPLaw, LegEdgeController):
    """Leg-edge law as a QP with stroke (with a margin) and leg-speed limits (OSQP).

    Takes the options of :class:`~controllers.leg_edge.LegEdgeController` and the
    QP options ``regularization``, ``stroke_margin`` [m], ``max_speed`` [m/s],
    ``eps_abs``, ``eps_rel``, ``max_iter``.
    """

    name = "leg-edge-qp"

    def __init__(self, gain: float = 1.0, adaptive_gain: Sequence[float] | None = None,
                 interaction: str = "current", threshold: float = 1e-6, damping: float = 0.0,
                 edge_feature: str = "auto", regularization: float = 1e-12,
                 stroke_margin: float | None = None, max_speed: float | None = None,
                 eps_abs: float = 1e-6, eps_rel: float = 1e-6, max_iter: int = 4000) -> None:
        LegEdgeController.__init__(self, gain, adaptive_gain, interaction, threshold, damping,
                                   edge_feature)
        if damping:
            raise OptionError(self.name, "damping", "use 'regularization' with the QP law")
        self._init_qp(regularization, stroke_margin, max_speed, eps_abs, eps_rel, max_iter)


class LegDirectionQPController(QPLaw, LegDirectionController):
    """Leg-direction law as a QP with stroke (with a margin) and leg-speed limits (OSQP).

    Takes the options of :class:`~controllers.leg_direction.LegDirectionController`
    and the QP options ``regularization``, ``stroke_margin`` [m], ``max_speed``
    [m/s], ``eps_abs``, ``eps_rel``, ``max_iter``.
    """

    name = "leg-direction-qp"

    def __init__(self, gain: float = 1.0, adaptive_gain: Sequence[float] | None = None,
                 interaction: str = "current", threshold: float = 1e-6, damping: float = 0.0,
                 regularization: float = 1e-12, stroke_margin: float | None = None,
                 max_speed: float | None = None, eps_abs: float = 1e-6, eps_rel: float = 1e-6,
                 max_iter: int = 4000) -> None:
        LegDirectionController.__init__(self, gain, adaptive_gain, interaction, threshold,
                                        damping)
        if damping:
            raise OptionError(self.name, "damping", "use 'regularization' with the QP law")
        self._init_qp(regularization, stroke_margin, max_speed, eps_abs, eps_rel, max_iter)
