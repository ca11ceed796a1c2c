"""QP variants of the vision laws with stroke and leg-speed limits (``docs/math.md`` section 6).

Choose the twist ``tau`` minimising ``|L tau + lambda e|^2 + eps |tau|^2`` subject to

``q_min + margin <= q + dt J_inv tau <= q_max - margin`` and ``|J_inv tau| <= q_dot_max``,

then ``q_dot = J_inv tau``. Both constraints act on the same rows ``J_inv tau``, so
they merge into one pair of bounds per leg (each bound clipped to the speed
limit, so the problem stays feasible even when a leg starts inside the margin).
Solved with OSQP (1.x API), warm-started from the previous step. Away from the
limits (and with ``eps -> 0``) the solution is the classical ``-lambda L^+ e``; at
a limit the platform slides along it instead of one leg being saturated.

Speed (the cost of a step is its number of Python and numpy calls):

- when the unconstrained optimum (from the compiled law core,
  :mod:`controllers.law_kernel`, solved with ``eps`` as the damping) clears every
  bound, it is the QP optimum and OSQP is not called (:meth:`QPLaw._solve`;
  default OSQP settings only, so that chosen settings always take effect);
- OSQP is set up once per :meth:`QPLaw.reset` and each solve only updates the
  values of ``P``, ``A``, ``q``, ``l``, ``u``, through OSQP's compiled solver object
  when it has the expected methods (the Python wrapper's bookkeeping, kept for
  derivatives, costs some 15 microseconds per solve);
- the exact active-set refinement after OSQP is one compiled call
  (:func:`refine_kernel`), tested equal to the numpy KKT solve.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import casadi as ca
import numpy as np
import osqp
import scipy.sparse as sp

from controllers.base import ControllerContext
from controllers.exceptions import OptionError
from controllers.law_kernel import LawResult, cholesky_solve
from controllers.laws import VisionLaw, check_number, solve_normal_damped
from controllers.leg_direction import LegDirectionController
from controllers.leg_edge import LegEdgeController
from hexapod.compiled import CompiledFunction

log = logging.getLogger(__name__)

# Column-major upper triangle of a 6x6 matrix (the CSC order of OSQP's P).
_TRI_ROWS = np.array([i for j in range(6) for i in range(j + 1)])
_TRI_COLS = np.array([j for j in range(6) for _ in range(j + 1)])
_TRI_PTR = np.concatenate([[0], np.cumsum(np.arange(1, 7))])
_FULL_ROWS = np.tile(np.arange(6), 6)
_FULL_PTR = np.arange(0, 37, 6)
#: Default OSQP settings of the QP laws: ``(eps_abs, eps_rel, max_iter)``.
_OSQP_DEFAULTS = (1e-6, 1e-6, 4000)
#: What :class:`LimitQP` uses of OSQP's compiled solver object (else the public API).
_EXT_API = ("update_data_vec", "update_data_mat", "solve", "info", "solution")


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
        self._ext: Any = None
        self._P = np.zeros((6, 6))
        self._eye_eps = regularization * np.eye(6)
        self._refine_in = np.zeros(103)

    def reset(self) -> None:
        """Forget the previous problem and set OSQP up again, on placeholder values.

        The sparsity (upper triangle of ``P``, dense ``A``) is all a setup fixes;
        every :meth:`solve` then only updates the values (``P``, ``A``, ``q``, ``l``,
        ``u``) and warm-starts, and a step that needs no QP (see
        :meth:`QPLaw._solve`) costs nothing here.
        """
        self._solver = None
        try:
            self._setup(np.eye(6)[_TRI_ROWS, _TRI_COLS], np.zeros(6), np.eye(6).reshape(-1),
                        -np.ones(6), np.ones(6))
        except (ValueError, RuntimeError, osqp.OSQPException) as exc:  # set up again later
            log.warning("OSQP setup failed: %s", exc)
            self._solver = None

    def _setup(self, Px: np.ndarray, c: np.ndarray, Ax: np.ndarray, lower: np.ndarray,
               upper: np.ndarray) -> None:
        solver = osqp.OSQP()
        solver.setup(sp.csc_matrix((Px, _TRI_ROWS, _TRI_PTR), shape=(6, 6)), c,
                     sp.csc_matrix((Ax.copy(), _FULL_ROWS, _FULL_PTR), shape=(6, 6)),
                     lower, upper, **self.settings)
        self._solver = solver
        # The compiled solver object under the Python wrapper, when it has the expected
        # methods: updating and solving through it skips the wrapper's bookkeeping
        # (kept for derivatives, unused here), about 15 us per solve.
        ext = getattr(solver, "_solver", None)
        self._ext = ext if all(hasattr(ext, a) for a in _EXT_API) else None

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
        # A finite sum means finite entries (inf or NaN anywhere makes it non-finite);
        # the exact test runs only when the sum is not finite.
        if not math.isfinite(P.sum() + c.sum() + J.sum() + lower.sum() + upper.sum()) and not (
                np.all(np.isfinite(P)) and np.all(np.isfinite(c)) and np.all(np.isfinite(J))
                and np.all(np.isfinite(lower)) and np.all(np.isfinite(upper))):
            return None, "non-finite QP data"
        if (lower > upper).any():
            return None, "empty stroke window (lower bound above upper bound)"
        Px = P[_TRI_ROWS, _TRI_COLS]
        Ax = J.T.reshape(-1)
        try:
            if self._solver is None:
                self._setup(Px, c, Ax, lower, upper)
                ext = self._ext
            else:
                ext = self._ext
                if ext is None:
                    self._solver.update(q=c, l=lower, u=upper, Px=Px, Ax=Ax)
                else:
                    ext.update_data_vec(q=c, l=lower, u=upper)
                    ext.update_data_mat(P_x=Px, P_i=None, A_x=Ax, A_i=None)
            if ext is None:
                res = self._solver.solve(raise_error=False)
                info, sol = res.info, res
            else:
                ext.solve()
                info, sol = ext.info, ext.solution
        except (ValueError, RuntimeError, osqp.OSQPException) as exc:
            self._solver = None
            return None, f"OSQP error: {exc}"
        status = info.status_val
        if status not in (osqp.SolverStatus.OSQP_SOLVED, osqp.SolverStatus.OSQP_SOLVED_INACCURATE):
            self._solver = None  # do not warm-start from a failed solve
            return None, f"QP not solved: OSQP status '{info.status}'"
        x = np.array(sol.x, dtype=float)
        if x.shape != (6,) or not math.isfinite(x.sum()):
            self._solver = None
            return None, f"QP returned a non-finite solution (status '{info.status}')"
        return self._refine(P, c, J, lower, upper, x, np.array(sol.y, dtype=float)), \
            str(info.status)

    def _refine(self, P: np.ndarray, c: np.ndarray, J: np.ndarray, lower: np.ndarray,
                upper: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Solve the KKT system of the active set OSQP found (what OSQP's polishing does).

        ADMM stops at a tolerance; with the active set fixed, the equality-constrained
        problem is solved exactly. Without active constraints this is the classical
        ``-P^-1 c``. The refined point is kept only if it is feasible and its
        multipliers have the right signs; otherwise OSQP's point is returned. (OSQP's
        own polisher prints to stdout even with ``verbose=False``.) One call of the
        compiled :func:`refine_kernel`.
        """
        buf = self._refine_in
        buf[0:36] = P.reshape(36)
        buf[36:42] = c
        buf[42:78] = J.reshape(36)
        buf[78:84] = lower
        buf[84:90] = upper
        buf[90:96] = x
        buf[96:102] = y
        buf[102] = self.active_tolerance
        out = refine_kernel().single(buf)
        return out[:6] if out[6] == 1.0 else x


def _refine_function() -> ca.Function:
    """:meth:`LimitQP._refine` as one expression.

    Input (103): ``P`` (6 x 6), ``c``, ``J`` (6 x 6, row-major), lower, upper, OSQP's
    ``x`` and ``y``, the active tolerance. Output (7): the refined ``x`` and 1 when it
    is accepted (feasible, multipliers of the right signs, finite), else 0.

    With the active rows ``a`` (mask ``m``), the KKT system ``P x + J_a^T nu = -c``,
    ``J_a x = bound_a`` is solved by its Schur complement: ``S = J P^-1 J^T`` with the
    inactive rows and columns replaced by the identity and their right-hand side by
    zero (so their ``nu`` is 0), ``nu = S^-1 (-(bound + J P^-1 c))`` on the active
    rows, ``x = -P^-1 (c + J^T nu)``.
    """
    v = ca.SX.sym("v", 103)
    P = [[v[6 * i + j] for j in range(6)] for i in range(6)]
    c = [v[36 + i] for i in range(6)]
    J = [[v[42 + 6 * i + j] for j in range(6)] for i in range(6)]
    lo = [v[78 + i] for i in range(6)]
    hi = [v[84 + i] for i in range(6)]
    x = [v[90 + i] for i in range(6)]
    y = [v[96 + i] for i in range(6)]
    tol = v[102]
    Jx = [sum((J[i][k] * x[k] for k in range(1, 6)), J[i][0] * x[0]) for i in range(6)]
    at_up = [ca.logic_and(Jx[i] >= hi[i] - tol, y[i] > 0) for i in range(6)]
    at_lo = [ca.logic_and(Jx[i] <= lo[i] + tol, y[i] < 0) for i in range(6)]
    m = [ca.if_else(ca.logic_or(at_up[i], at_lo[i]), 1.0, 0.0) for i in range(6)]
    bound = [ca.if_else(at_up[i], hi[i], lo[i]) for i in range(6)]
    # P^-1 J^T (columns) and P^-1 c.
    PiJt = [cholesky_solve(P, [J[i][k] for k in range(6)]) for i in range(6)]  # P^-1 J_i
    Pic = cholesky_solve(P, c)
    S = [[ca.SX(0.0)] * 6 for _ in range(6)]
    for i in range(6):
        for j in range(6):
            sij = sum((J[i][k] * PiJt[j][k] for k in range(1, 6)), J[i][0] * PiJt[j][0])
            S[i][j] = m[i] * m[j] * sij + (1.0 - m[i] if i == j else 0.0)
    JPic = [sum((J[i][k] * Pic[k] for k in range(1, 6)), J[i][0] * Pic[0]) for i in range(6)]
    rhs = [-m[i] * (bound[i] + JPic[i]) for i in range(6)]
    nu = cholesky_solve(S, rhs)
    xr = [-(Pic[k] + sum((PiJt[i][k] * nu[i] for i in range(1, 6)), PiJt[0][k] * nu[0]))
          for k in range(6)]
    ok = ca.SX(1.0)
    for i in range(6):
        Jr = sum((J[i][k] * xr[k] for k in range(1, 6)), J[i][0] * xr[0])
        slack = 1e-9 * (1.0 + ca.fabs(hi[i] - lo[i]))
        ok = ca.logic_and(ok, ca.logic_and(Jr - slack <= hi[i], Jr + slack >= lo[i]))
        # Multipliers: >= 0 on upper bounds, <= 0 on lower bounds (OSQP's convention).
        ok = ca.logic_and(ok, ca.logic_or(ca.logic_not(at_up[i]), nu[i] >= -1e-12))
        ok = ca.logic_and(ok, ca.logic_or(ca.logic_not(at_lo[i]), nu[i] <= 1e-12))
        ok = ca.logic_and(ok, xr[i] - xr[i] == 0)  # finite
    out = ca.vertcat(*xr, ca.if_else(ok, 1.0, 0.0))
    return ca.Function("hexapod_qp_refine", [v], [out])


@lru_cache(maxsize=1)
def refine_kernel() -> CompiledFunction:
    """The compiled active-set refinement of :class:`LimitQP`."""
    return CompiledFunction(_refine_function())


@dataclass(frozen=True)
class StrokeWindow:
    """The limits of the QP laws for one trial (``docs/math.md`` section 6).

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
    """The bounds on the leg velocities ``J_inv tau`` of one period (one definition for
    the QP law, its batched rows and the predictive controller's first move).

    Reaching ``lower``/``upper`` within the period, each clipped to the speed limit so
    that the window is never empty. Works on one trial (scalars, ``q`` (6,)) and on a
    batch (``(n, 1)`` columns, ``q`` (n, 6)).

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


class QPLaw(VisionLaw):
    """Mixin of the QP laws: replaces the pseudo-inverse of :class:`VisionLaw` by :class:`LimitQP`.

    Concrete classes call :meth:`_init_qp` from their constructor.
    """

    def _init_qp(self, regularization: float, stroke_margin: float | None,
                 max_speed: float | None, eps_abs: float, eps_rel: float,
                 max_iter: int, shortcut: bool | None = None) -> None:
        if shortcut is None:  # auto: OSQP always runs when its settings were chosen
            shortcut = (eps_abs, eps_rel, max_iter) == _OSQP_DEFAULTS
        self.shortcut = bool(shortcut)
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
        #: This trial's limits.
        self.window = StrokeWindow(q_min + margin, q_max - margin,
                                   float(context.max_speed if self.max_speed is None
                                         else self.max_speed), self._dt)
        self.qp.reset()

    def _batch_reset_extra(self) -> None:
        super()._batch_reset_extra()
        windows = [t.window for t in self._trials]
        self._b_lo = np.array([w.lower for w in windows])[:, None]
        self._b_hi = np.array([w.upper for w in windows])[:, None]
        self._b_inv_dt = np.array([1.0 / w.dt for w in windows])[:, None]
        self._b_vmax = np.array([w.max_speed for w in windows])[:, None]
        self._b_shortcut = np.array([t.shortcut for t in self._trials], dtype=bool)

    def _batch_accept(self, trials: np.ndarray, q: np.ndarray, qdot: np.ndarray
                      ) -> np.ndarray:
        """Rows whose unconstrained optimum clears every bound (as :meth:`_solve`)."""
        vmax = self._b_vmax[trials]
        _, _, lo, hi = velocity_bounds(q, self._b_lo[trials], self._b_hi[trials], vmax,
                                       self._b_inv_dt[trials])
        tol2 = 2.0 * (1e-6 * vmax[:, 0])
        with np.errstate(invalid="ignore"):
            return (self._b_shortcut[trials] & ((qdot - lo).min(axis=1) > tol2)
                    & ((hi - qdot).min(axis=1) > tol2))

    def _damping2(self) -> float:
        """The compiled core solves ``(L^T L + eps I) tau = -lambda L^T e``: the
        unconstrained optimum of the QP objective."""
        return self.qp.regularization

    def _solve(self, N: np.ndarray, b: np.ndarray, lam: float, q: np.ndarray, J: np.ndarray,
               pre: LawResult | None) -> tuple[np.ndarray, int, float, list[str], str | None,
                                               np.ndarray | None]:
        """The QP, or its unconstrained optimum when that satisfies every bound.

        The objective is strictly convex, so when the unconstrained minimiser
        ``-lambda (L^T L + eps I)^-1 L^T e`` (the classical command for ``eps -> 0``)
        satisfies every bound it is the QP optimum: it is returned, with the
        diagnostics of a solve without active constraint, and OSQP is not called.
        It must clear every bound by twice the tolerance under which the
        diagnostics call a constraint active (``1e-6 q_dot_max``); otherwise OSQP
        solves the QP (and its active set is refined exactly, :meth:`LimitQP._refine`).
        """
        if pre is not None:
            rank, cond, tau, qdot = pre.rank, pre.condition, pre.tau, pre.qdot
        else:
            x, rank, cond = solve_normal_damped(N, b, self.threshold, self.qp.regularization)
            tau = x * -lam
            qdot = J @ tau
        if rank < 6:
            return np.zeros(6), rank, cond, [], None, None
        w = self.window
        vmax = w.max_speed
        stroke_lo, stroke_hi, lo, hi = velocity_bounds(q, w.lower, w.upper, vmax, 1.0 / w.dt)
        self._lower, self._upper = lo, hi  # for _finish
        tol = 1e-6 * vmax
        if self.shortcut and (qdot - lo).min() > 2.0 * tol and (hi - qdot).min() > 2.0 * tol:
            return tau, rank, cond, [], None, qdot  # NaN fails the comparisons
        solved, status = self.qp.solve(N, b, lam, J, lo, hi)
        if solved is None:
            return np.zeros(6), rank, cond, [], status, None
        tau = solved
        qdot = J @ tau
        active: list[str] = []
        at_hi = np.flatnonzero(qdot >= hi - tol)
        at_lo = np.flatnonzero(qdot <= lo + tol)
        for i in at_hi:
            active.append(f"leg {int(i)} {'upper stroke' if stroke_hi[i] < vmax else 'speed'}")
        for i in at_lo:
            active.append(f"leg {int(i)} {'lower stroke' if stroke_lo[i] > -vmax else 'speed'}")
        if status != "solved":
            active.append(f"OSQP status '{status}'")
        return tau, rank, cond, active, None, None

    def _finish(self, qdot: np.ndarray) -> np.ndarray:
        """Clip the tolerance-sized violations of the bounds left by the solver."""
        return np.minimum(np.maximum(qdot, self._lower), self._upper)  # np.clip, faster



class LegEdgeQPController(QPLaw, LegEdgeController):
    """Leg-edge law as a QP with stroke (with a margin) and leg-speed limits (OSQP).

    Takes the options of :class:`~controllers.leg_edge.LegEdgeController` and the
    QP options ``regularization``, ``stroke_margin`` [m], ``max_speed`` [m/s],
    ``eps_abs``, ``eps_rel``, ``max_iter``, and ``shortcut`` (skip OSQP when the
    unconstrained optimum satisfies every bound, see :meth:`QPLaw._solve`; default:
    only with the default OSQP settings, so that chosen settings always take effect).
    """

    name = "leg-edge-qp"

    def __init__(self, gain: float = 1.0, adaptive_gain: Sequence[float] | None = None,
                 interaction: str = "current", threshold: float = 1e-6, damping: float = 0.0,
                 edge_feature: str = "auto", regularization: float = 1e-12,
                 stroke_margin: float | None = None, max_speed: float | None = None,
                 eps_abs: float = 1e-6, eps_rel: float = 1e-6, max_iter: int = 4000,
                 shortcut: bool | None = None, compiled: bool = True) -> None:
        LegEdgeController.__init__(self, gain, adaptive_gain, interaction, threshold, damping,
                                   edge_feature, compiled)
        if damping:
            raise OptionError(self.name, "damping", "use 'regularization' with the QP law")
        self._init_qp(regularization, stroke_margin, max_speed, eps_abs, eps_rel, max_iter,
                      shortcut)


class LegDirectionQPController(QPLaw, LegDirectionController):
    """Leg-direction law as a QP with stroke (with a margin) and leg-speed limits (OSQP).

    Takes the options of :class:`~controllers.leg_direction.LegDirectionController`
    and the QP options ``regularization``, ``stroke_margin`` [m], ``max_speed``
    [m/s], ``eps_abs``, ``eps_rel``, ``max_iter``, and ``shortcut`` (skip OSQP when
    the unconstrained optimum satisfies every bound, see :meth:`QPLaw._solve`;
    default: only with the default OSQP settings).
    """

    name = "leg-direction-qp"

    def __init__(self, gain: float = 1.0, adaptive_gain: Sequence[float] | None = None,
                 interaction: str = "current", threshold: float = 1e-6, damping: float = 0.0,
                 regularization: float = 1e-12, stroke_margin: float | None = None,
                 max_speed: float | None = None, eps_abs: float = 1e-6, eps_rel: float = 1e-6,
                 max_iter: int = 4000, shortcut: bool | None = None, compiled: bool = True) -> None:
        LegDirectionController.__init__(self, gain, adaptive_gain, interaction, threshold,
                                        damping, compiled)
        if damping:
            raise OptionError(self.name, "damping", "use 'regularization' with the QP law")
        self._init_qp(regularization, stroke_margin, max_speed, eps_abs, eps_rel, max_iter,
                      shortcut)
