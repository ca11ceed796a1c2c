"""Solving the predictive problems, for both predictive families (the velocity MPCs of
:mod:`controllers.mpc.controller`, the force MPCs of :mod:`controllers.force_mpc`):

- the dense QP (:func:`solve_qp`: the unconstrained minimiser when it satisfies every
  row, else DAQP generated to C, or ``casadi.conic`` without a C compiler);
- the Gauss-Newton SQP iterations (:func:`run_sqp`) on a compiled kernel's QP data;
- :class:`PredictiveLaw`: the options, warm start, counters and fallback they share.
"""

from __future__ import annotations

import logging
import math
import subprocess
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np

from controllers.base import Command, Controller, ControllerContext, Observation
from controllers.law_tools import check_count, check_flag, check_weights
from controllers.mpc.problem import ProblemSpec
from hexapod.compiled import CompiledFunction, Layout

log = logging.getLogger(__name__)


@dataclass
class SolveStats:
    """Counters of the solves since the last reset.

    Attributes:
        steps: Steps that reached the solver.
        fallbacks: Steps that fell back to the held one-step law.
        unconverged: Steps that applied an unconverged SQP iterate.
        total_sqp_iterations: SQP iterations, summed over the steps.
        reasons: Fallback reasons and how often each occurred.
    """

    steps: int = 0
    fallbacks: int = 0
    unconverged: int = 0
    total_sqp_iterations: int = 0
    reasons: dict[str, int] = field(default_factory=dict)

    def fallback(self, reason: str) -> None:
        """Count a step that fell back, and its reason."""
        self.fallbacks += 1
        self.reasons[reason] = self.reasons.get(reason, 0) + 1


@dataclass
class QPResult:
    """One QP solve.

    Attributes:
        step: (6 N,) ``delta U``, or None on failure.
        status: The solver's return status (text).
        multipliers: (rows,) multipliers of the rows (sign: >0 at an upper bound).
    """

    step: np.ndarray | None
    status: str
    multipliers: np.ndarray | None


#: Visibility rows kept by :func:`solve_qp` (the others are checked afterwards).
SCREENED_VISIBILITY_ROWS = 48


#: DAQP's primal feasibility tolerance (its default, 1e-6, let an "optimal" force plan
#: lie 0.02 N outside its bounds and a velocity plan 1e-5 m/s above its speed limit, on
#: the MPCs' badly scaled Hessians; at 1e-10 they lie within 3e-14).
DAQP_PRIMAL_TOL = 1e-10
#: How far a solution may lie outside its rows, relative to ``1 + |C| |d|`` (the size of
#: the terms of each row's sum, so that the same problem in other units is judged the
#: same): beyond, the solve is refused whatever the solver's status says.
ROW_TOLERANCE = 1e-9


@lru_cache(maxsize=32)
def qp_solver(variables: int, rows: int) -> ca.Function:
    """DAQP through ``casadi.conic`` for a dense QP of this size (status checked by the caller)."""
    return ca.conic("hexapod_mpc_qp", "daqp",
                    {"h": ca.Sparsity.dense(variables, variables),
                     "a": ca.Sparsity.dense(rows, variables)},
                    {"error_on_fail": False, "daqp": {"primal_tol": DAQP_PRIMAL_TOL}})


def outside_rows(C: np.ndarray, x: np.ndarray, lba: np.ndarray, uba: np.ndarray) -> float:
    """How far ``C x`` lies outside ``[lba, uba]`` beyond :data:`ROW_TOLERANCE`, relative
    to ``1 + |C| |x|`` row by row (0: inside; infinite where a row or ``x`` is NaN)."""
    v = C @ x
    raw = np.maximum(lba - v, v - uba)
    over = np.flatnonzero(~(raw <= ROW_TOLERANCE))  # (NaN too; a row's size is >= 1)
    if not len(over):  # the common case: no row's size needed
        return 0.0
    worst = float(np.max(raw[over] / (1.0 + np.abs(C[over]) @ np.abs(x))))
    return math.inf if math.isnan(worst) else max(worst - ROW_TOLERANCE, 0.0)


class CompiledQP:
    """DAQP generated to C by CasADi, called on preallocated buffers (``casadi.conic``'s
    Python interface costs several hundred microseconds per call, for a solve of about a
    hundred), linked against the CasADi wheel's ``libdaqp.so``. A call that returns
    non-zero is a solve DAQP did not finish as optimal.

    Raises:
        OSError: No compiler, or the DAQP library or headers are missing (the caller
            uses the ``casadi.conic`` path instead).
    """

    def __init__(self, variables: int, rows: int) -> None:
        n, m = variables, rows
        inputs = Layout([("H", (n, n)), ("g", n), ("C", (m, n)), ("lba", m), ("uba", m)],
                        f"QP {n} x {m} input")
        outputs = Layout([("x", n), ("multipliers", m), ("cost", 1)], f"QP {n} x {m} output")
        vin = ca.MX.sym("v", inputs.size)
        P = inputs.split(vin)
        sol = qp_solver(n, m)(h=ca.reshape(P["H"], n, n), g=P["g"],
                              a=ca.reshape(P["C"], n, m).T, lba=P["lba"], uba=P["uba"])
        f = ca.Function(f"hexapod_mpc_daqp_{n}_{m}", [vin],
                        [ca.vertcat(sol["x"], sol["lam_a"], sol["cost"])])
        casadi_dir = Path(ca.__file__).resolve().parent
        lib_daqp = casadi_dir / "libdaqp.so"
        include = casadi_dir / "include"
        if not lib_daqp.exists() or not (include / "daqp" / "api.h").exists():
            raise OSError(f"DAQP library or headers not found in {casadi_dir}")
        #: The compiled solver (its C function, layouts and library).
        self.function = CompiledFunction(f, inputs=inputs, outputs=outputs,
                                         flags=("-O2", f"-I{include}"), preload=(lib_daqp,))
        if not self.function.compiled:
            raise OSError(f"{self.function.name}: not compiled")
        self._bound = self.function.bind()
        self._x = outputs["x"]
        self._multipliers = outputs["multipliers"]

    def solve(self, H: np.ndarray, g: np.ndarray, C: np.ndarray, lba: np.ndarray,
              uba: np.ndarray) -> QPResult:
        """Solve ``min 1/2 d^T H d + g^T d`` s.t. ``lba <= C d <= uba`` (sizes of this solver)."""
        v = self._bound.inputs
        v["H"][:] = H
        v["g"][:] = g
        v["C"][:] = C
        v["lba"][:] = lba
        v["uba"][:] = uba
        if self._bound.call():
            return QPResult(None, "QP not solved: DAQP did not reach an optimal solution", None)
        y = self._bound.y
        step = y[self._x].copy()
        if not math.isfinite(float(step.sum())):
            return QPResult(None, "QP returned a non-finite solution", None)
        return QPResult(step, "optimal", y[self._multipliers].copy())


@lru_cache(maxsize=32)
def compiled_qp(variables: int, rows: int) -> CompiledQP | None:
    """The compiled DAQP of this size, or None when it cannot be built (logged once)."""
    try:
        return CompiledQP(variables, rows)
    except (OSError, subprocess.SubprocessError, RuntimeError) as exc:
        log.warning("compiled DAQP unavailable (%s); using casadi.conic (slower)", exc)
        return None


def daqp(H: np.ndarray, g: np.ndarray, C: np.ndarray, lba: np.ndarray, uba: np.ndarray,
         compiled: bool) -> QPResult:
    """Solve ``min 1/2 d^T H d + g^T d`` s.t. ``lba <= C d <= uba`` with DAQP: generated to
    C (:func:`compiled_qp`) when ``compiled`` and it can be built, else ``casadi.conic``."""
    qp = compiled_qp(len(g), len(lba)) if compiled else None
    res = qp.solve(H, g, C, lba, uba) if qp is not None else _conic(H, g, C, lba, uba)
    if res.step is not None and (excess := outside_rows(C, res.step, lba, uba)):
        return QPResult(None, f"QP not solved: DAQP's solution ({res.status}) lies outside "
                              f"its rows by {excess + ROW_TOLERANCE:.2g} (relative)", None)
    return res


def _conic(H: np.ndarray, g: np.ndarray, C: np.ndarray, lba: np.ndarray, uba: np.ndarray
           ) -> QPResult:
    """The QP by DAQP through ``casadi.conic`` (its status checked)."""
    solver = qp_solver(len(g), len(lba))
    try:
        out = solver(h=H, g=g, a=C, lba=lba, uba=uba)
    except RuntimeError as exc:  # casadi reports solver errors as RuntimeError
        return QPResult(None, f"QP solver error: {exc}", None)
    stats = solver.stats()
    status = str(stats.get("return_status", "unknown"))
    if not stats.get("success", False):
        return QPResult(None, f"QP not solved: DAQP status {status}", None)
    x = np.asarray(out["x"], dtype=float).reshape(-1)
    if not np.all(np.isfinite(x)):
        return QPResult(None, "QP returned a non-finite solution", None)
    return QPResult(x, status, np.asarray(out["lam_a"], dtype=float).reshape(-1))


def solve_qp(H: np.ndarray, g: np.ndarray, C: np.ndarray, lba: np.ndarray, uba: np.ndarray,
             compiled: bool, spec: ProblemSpec | None = None) -> QPResult:
    """Solve ``min 1/2 d^T H d + g^T d`` s.t. ``lba <= C d <= uba``: the unconstrained
    minimiser ``-H^-1 g`` when it satisfies every row (the optimum of the strictly convex
    QP), else DAQP (:func:`daqp`), first on the visibility rows of ``spec`` reduced to
    the :data:`SCREENED_VISIBILITY_ROWS` of smallest slack at ``d = 0`` (DAQP's cost
    grows with the rows): a solution that satisfies every row is the full QP's optimum.
    """
    try:
        x = -np.linalg.solve(H, g)
    except np.linalg.LinAlgError:
        x = None
    if x is not None:
        v = C @ x
        if (v >= lba).all() and (v <= uba).all() and math.isfinite(float(x.sum())):
            return QPResult(x, "unconstrained optimum", np.zeros(len(lba)))
    if spec is not None and spec.visibility:
        # all rows but the visibility ones, and the visibility rows of smallest slack
        sr, N = spec.stage_rows, spec.horizon
        idx = np.arange(N * sr).reshape(N, sr)
        vis = idx[:, sr - 48:].reshape(-1)
        other = np.concatenate([idx[:, :sr - 48].reshape(-1), np.arange(N * sr, len(lba))])
        slack = np.minimum(uba[vis], -lba[vis])
        best = vis[np.argpartition(slack, SCREENED_VISIBILITY_ROWS)[:SCREENED_VISIBILITY_ROWS]]
        keep = np.sort(np.concatenate([other, best]))
        res = daqp(H, g, C[keep], lba[keep], uba[keep], compiled)
        if (res.step is not None and res.multipliers is not None
                and not outside_rows(C, res.step, lba, uba)):
            lam = np.zeros(len(lba))
            lam[keep] = res.multipliers
            return QPResult(res.step, res.status + " (screened rows)", lam)
    return daqp(H, g, C, lba, uba, compiled)


def merit(out: np.ndarray, o: dict[str, slice], mu: float) -> tuple[float, float]:
    """L1 merit ``cost / 2 + mu * violation`` and the violation at the point of a kernel
    output. The kernel's ``cost`` is a sum of squares ``|r|^2``, twice the scale of its
    Gauss-Newton QP's objective ``1/2 d^T H d + g^T d`` (``H = J^T J``, ``g = J^T r``): halved,
    its slope along a step ``d`` is ``g^T d`` and a penalty ``mu`` above the QP's largest
    multiplier makes the merit exact."""
    viol = float(np.maximum(out[o["lba"]], 0.0).sum() + np.maximum(-out[o["uba"]], 0.0).sum())
    return 0.5 * float(out[o["cost"]][0]) + mu * viol, viol


#: A QP's data ``(H, g, C, lba, uba)``.
QPArrays = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]

#: Steps tried by the line search (1, 1/2, ... 1/32 of the QP's step).
LINE_SEARCH_TRIALS = 6


def run_sqp(evaluate: Callable[[np.ndarray], np.ndarray | str],
            qp_data: Callable[[np.ndarray, np.ndarray], QPArrays],
            U: np.ndarray, max_iter: int, tolerance: float, compiled: bool, *,
            floor: float = 1e-3, spec: ProblemSpec | None = None,
            merit_rows: dict[str, slice] | None = None, one_qp: bool = False,
            time_limit: float | None = None
            ) -> tuple[np.ndarray | None, bool, str, QPResult | None, int]:
    """Gauss-Newton SQP from ``U`` (the warm start), with a backtracking line search on
    the L1 merit ``cost / 2 + mu * violation`` (:func:`merit`) when ``merit_rows`` are
    given (else full steps).

    Converged when the first move (the only one applied) steps by ``|delta U_0|_inf <=
    tolerance * max(|U_0|_inf, floor)``. The last allowed iteration takes the full QP
    step (an unconverged result satisfies the linearised constraints of its last QP).

    Args:
        evaluate: The kernel's output at a ``U``, or why it failed.
        qp_data: The QP (:data:`QPArrays`) of an output at its ``U``.
        U: (6 N,) the starting point [m/s, rad/s or N].
        max_iter: Iteration limit (0: no QP is solved).
        tolerance: Relative tolerance on the first move (``floor``: the smallest
            ``|U_0|_inf`` it is relative to).
        compiled: Use DAQP generated to C (else ``casadi.conic``).
        spec: The velocity MPC's problem structure (visibility rows screened).
        merit_rows: The output's ``cost``, ``lba`` and ``uba`` slices (line search).
        one_qp: Converged after one QP (the local model: its QP is the problem).
        time_limit: Seconds after which the iterations stop, or None.

    Returns:
        ``U`` (None on failure or timeout: the status says why), converged, the status,
        the last QP result and the SQP iterations.
    """
    status = "iteration limit 0: no QP solved"
    last: QPResult | None = None
    t_start = time.perf_counter()
    if max_iter == 0:
        return None, False, status, None, 0
    out = evaluate(U)
    mu = 0.0
    for it in range(1, max_iter + 1):
        if isinstance(out, str):
            return None, False, out, last, it
        if not math.isfinite(float(out.sum())):
            return None, False, "non-finite QP data (prediction failed)", last, it
        H, g, C, lba, uba = qp_data(out, U)
        res = solve_qp(H, g, C, lba, uba, compiled, spec)
        last = res
        if res.step is None or res.multipliers is None:
            return None, False, res.status, last, it
        d = res.step
        size = float(np.abs(d[:6]).max())
        if one_qp or size <= tolerance * max(float(np.abs(U[:6] + d[:6]).max()), floor):
            return U + d, True, f"converged in {it} SQP iteration{'s' if it > 1 else ''}", \
                last, it
        status = f"not converged in {it} SQP iterations (last step {size:.2g})"
        if it == max_iter:  # stop on a QP solution: the linearised rows hold there
            return U + d, False, status, last, it
        if merit_rows is None:  # the full step
            U = U + d
            out = evaluate(U)
        else:
            mu = max(mu, 1.1 * float(np.abs(res.multipliers).max()) + 1e-9)
            merit0, viol0 = merit(out, merit_rows, mu)
            slope = float(g @ d) - mu * viol0  # directional derivative of the merit
            alpha = 1.0
            for trial in range(LINE_SEARCH_TRIALS):
                if trial:
                    alpha *= 0.5
                out = evaluate(U + alpha * d)
                if isinstance(out, str):
                    return None, False, out, last, it
                value, _ = merit(out, merit_rows, mu)
                if value <= merit0 + 1e-4 * alpha * min(slope, 0.0) or not math.isfinite(
                        merit0):
                    break
            U = U + alpha * d  # the point of ``out``, the next QP's (the last tried if none
            # decreased the merit enough)
        if time_limit is not None and time.perf_counter() - t_start > time_limit:
            return None, False, f"time limit {time_limit} s exceeded after {it} SQP " \
                "iterations", last, it
    return U, False, status, last, max_iter


class PredictiveLaw(Controller):
    """Base of the predictive controllers (velocity MPC :class:`~controllers.mpc.
    controller.MPCLaw`, force MPC :class:`~controllers.force_mpc.controller.ForceMPCLaw`):
    the options they share, the plan's warm start ``_U`` (6 N,), the solve counters
    :attr:`stats` and the fallback to the held one-step law :attr:`law`."""

    law: Any
    context: ControllerContext | None = None
    #: What a fallback's note (``"<note>: <reason>"``) starts with.
    fallback_note = "mpc fallback"

    def _check_options(self, horizon: int, error_weight: float, terminal_weight: float,
                       weights: tuple[tuple[str, float], tuple[str, float]], compiled: bool
                       ) -> tuple[float, float]:
        """Check and set the horizon (1 to 50 periods), its error weights and ``compiled``;
        return the two ``weights`` ``(option, value)`` checked (one positive: a strictly
        convex QP).

        Raises:
            OptionError: Naming the option out of range.
        """
        self.horizon = check_count(self.name, "horizon", horizon, 1, 50)
        self.error_weight, self.terminal_weight = check_weights(
            self.name, ("error_weight", error_weight), ("terminal_weight", terminal_weight),
            "no error to minimise")
        self.compiled = check_flag(self.name, "compiled", compiled)
        self._restart()
        return check_weights(self.name, *weights,
                             "the QP needs one of them to be strictly convex")

    def _restart(self) -> None:
        """A new trial: the counters at zero, the warm start at rest."""
        self.stats = SolveStats()
        self._U = np.zeros(6 * self.horizon)

    @staticmethod
    def _shift(U: np.ndarray) -> np.ndarray:
        """The warm start of the next period: the moves shifted by one, the last repeated."""
        return np.concatenate([U[6:], U[-6:]])

    def _fallback(self, observation: Observation, reason: str) -> Command:
        """The held law's command this period, noting why."""
        self.stats.fallback(reason)
        log.debug("%s: falling back to %s: %s", self.name, self.law.name, reason)
        cmd = self.law_step(observation)
        cmd.notes = [*cmd.notes, f"{self.fallback_note}: {reason}"]
        return cmd

    def law_step(self, observation: Observation) -> Command:
        """The held law's command of one observation (its batch of one)."""
        return self.law.step(observation)  # type: ignore[no-any-return]
