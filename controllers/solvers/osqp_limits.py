"""The OSQP problem of the limit QP (6 twist variables, 6 two-sided bounds on ``J_inv tau``)
and its exact active-set refinement, compiled (``docs/math.md`` section 6).

Speed (the cost of a step is its number of Python and numpy calls): OSQP is set up
once per reset and each solve only updates the values of ``P``, ``A``, ``q``, ``l``,
``u``; the exact active-set refinement after OSQP is one compiled call
(:func:`refine_kernel`), tested equal to the numpy KKT solve.
"""

from __future__ import annotations

import logging
import math
from functools import lru_cache
from typing import Any

import casadi as ca
import numpy as np
import osqp
import scipy.sparse as sp

from controllers.law_algebra import cholesky_solve
from hexapod.compiled import CompiledFunction, Layout

log = logging.getLogger(__name__)

# Column-major upper triangle of a 6x6 matrix (the CSC order of OSQP's P).
_TRI_ROWS = np.array([i for j in range(6) for i in range(j + 1)])
_TRI_COLS = np.array([j for j in range(6) for _ in range(j + 1)])
_TRI_PTR = np.concatenate([[0], np.cumsum(np.arange(1, 7))])
_FULL_ROWS = np.tile(np.arange(6), 6)
_FULL_PTR = np.arange(0, 37, 6)
#: Default OSQP settings of the QP laws: ``(eps_abs, eps_rel, max_iter)``.
OSQP_DEFAULTS = (1e-6, 1e-6, 4000)
#: What :class:`LimitQP` uses of OSQP's compiled solver object (else the public API).
_EXT_API = ("update_data_vec", "update_data_mat", "solve", "info", "solution")


class LimitQP:
    """The OSQP problem of one controller (6 variables, 6 two-sided constraints).

    Args:
        regularization: ``eps`` of the objective (>= 0) [same units as ``L^T L``].
        eps_abs: OSQP absolute tolerance.
        eps_rel: OSQP relative tolerance.
        max_iter: OSQP iteration budget.
    """

    #: Distance to a bound [m/s] under which a constraint with a multiplier of the right
    #: sign is taken as active by the refinement.
    active_tolerance = 1e-6

    def __init__(self, regularization: float = 1e-12, eps_abs: float = 1e-6,
                 eps_rel: float = 1e-6, max_iter: int = 4000) -> None:
        self.regularization = regularization
        self.settings = {"verbose": False, "warm_starting": True, "polishing": False,
                         "eps_abs": eps_abs, "eps_rel": eps_rel, "max_iter": max_iter,
                         "check_termination": 10}
        self._solver: Any = None
        self._ext: Any = None
        self._eye_eps = regularization * np.eye(6)
        self._refine_in = np.zeros(REFINE_INPUTS.size)

    def __getstate__(self) -> dict[str, object]:
        """A copy's state, without OSQP's solver (not copyable: a copy sets OSQP up again
        at its next solve, cold, as after a failed solve; its solutions then agree with
        the original's within OSQP's tolerances, exactly where the active set's
        refinement applies)."""
        state = self.__dict__.copy()
        state["_solver"] = state["_ext"] = None
        return state

    def reset(self) -> None:
        """Forget the previous problem and set OSQP up again, on placeholder values (the
        sparsity, upper triangle of ``P`` and dense ``A``, is all a setup fixes)."""
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
        """``tau`` minimising ``|L tau + lam e|^2 + eps |tau|^2`` (``N = L^T L``, ``b =
        L^T e``, ``lam`` [1/s]) under ``lower <= J tau <= upper`` [m/s] (None on failure),
        and the OSQP status or the failure reason."""
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
            elif self._ext is None:
                self._solver.update(q=c, l=lower, u=upper, Px=Px, Ax=Ax)
            else:
                self._ext.update_data_vec(q=c, l=lower, u=upper)
                self._ext.update_data_mat(P_x=Px, P_i=None, A_x=Ax, A_i=None)
            ext = self._ext
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
        """Solve the KKT system of the active set OSQP found, exactly (what OSQP's
        polisher does, but it prints to stdout even with ``verbose=False``): one call of
        the compiled :func:`refine_kernel`. The refined point is kept only if it is
        feasible with multipliers of the right signs; otherwise OSQP's point is returned.
        """
        buf = self._refine_in
        buf[REFINE_INPUTS["P"]] = P.reshape(36)
        buf[REFINE_INPUTS["c"]] = c
        buf[REFINE_INPUTS["J"]] = J.reshape(36)
        buf[REFINE_INPUTS["lower"]] = lower
        buf[REFINE_INPUTS["upper"]] = upper
        buf[REFINE_INPUTS["x"]] = x
        buf[REFINE_INPUTS["y"]] = y
        buf[REFINE_INPUTS["tolerance"]] = self.active_tolerance
        out = refine_kernel().single(buf)
        return out[REFINE_OUTPUTS["x"]] if out[REFINE_OUTPUTS["accepted"]][0] == 1.0 else x


#: The refinement's input: ``P`` (6 x 6), ``c``, ``J`` (6 x 6, row-major), the bounds,
#: OSQP's ``x`` and ``y``, the active tolerance; its output: ``x`` and ``accepted``.
REFINE_INPUTS = Layout([("P", (6, 6)), ("c", 6), ("J", (6, 6)), ("lower", 6), ("upper", 6),
                        ("x", 6), ("y", 6), ("tolerance", 1)], "QP refinement input")
REFINE_OUTPUTS = Layout([("x", 6), ("accepted", 1)], "QP refinement output")


def _refine_function() -> ca.Function:
    """:meth:`LimitQP._refine` as one expression (:data:`REFINE_INPUTS` ->
    :data:`REFINE_OUTPUTS`: ``accepted`` is 1 when the refined ``x`` is feasible, with
    multipliers of the right signs, finite). With the active rows ``a`` (mask ``m``),
    the KKT system ``P x + J_a^T nu = -c``, ``J_a x = bound_a`` is solved by its Schur
    complement: ``S = J P^-1 J^T`` with the inactive rows and columns replaced by the
    identity and their right-hand side by zero (so their ``nu`` is 0), ``nu = S^-1
    (-(bound + J P^-1 c))`` on the active rows, ``x = -P^-1 (c + J^T nu)``.
    """
    v = ca.SX.sym("v", REFINE_INPUTS.size)
    b = REFINE_INPUTS.split(v)
    P = [[b["P"][6 * i + j] for j in range(6)] for i in range(6)]
    c = [b["c"][i] for i in range(6)]
    J = [[b["J"][6 * i + j] for j in range(6)] for i in range(6)]
    lo = [b["lower"][i] for i in range(6)]
    hi = [b["upper"][i] for i in range(6)]
    x = [b["x"][i] for i in range(6)]
    y = [b["y"][i] for i in range(6)]
    tol = b["tolerance"][0]
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
    return CompiledFunction(_refine_function(), inputs=REFINE_INPUTS, outputs=REFINE_OUTPUTS)
