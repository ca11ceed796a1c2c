"""The per-step numeric core of the vision laws, compiled to C (one call per step).

A ``step`` of a vision law is a few hundred floating-point operations spread
over some sixty numpy calls; on this scale the cost is the calls, not the
arithmetic. The core of the common case (every feature visible, CURRENT
interaction) is therefore written once as a CasADi SX expression, generated
to C, compiled by the system C compiler and called through :mod:`ctypes` on
preallocated buffers by :class:`hexapod.compiled.CompiledFunction` (the
technique of :mod:`hexapod.fk`; the CasADi virtual machine evaluates the same
expression when there is no compiler). One call, a few microseconds, computes:

- the feature part (one per feature kind): the stacked error ``e`` and the
  normal equations ``N = L^T L``, ``b = L^T e`` (``docs/math.md`` section 6), and the
  leg directions the inverse Jacobian needs;
- the law part, shared by every feature kind (:func:`law_tail`): the adaptive
  gain ``lambda(|e|_inf)``; the eigen-decomposition of the 6 x 6 ``N`` by a fixed
  number of cyclic Jacobi sweeps (unrolled: exact to rounding for a symmetric
  6 x 6 matrix), hence the rank (eigenvalues above ``threshold^2 w_max``), the
  condition number ``sqrt(w_max / w_min)`` and the thresholded, damped
  pseudo-inverse solution ``tau = -lambda sum_j (v_j^T b) / (w_j + d2) v_j`` of
  :func:`controllers.laws.solve_normal`; the inverse Jacobian ``J_inv``
  (``docs/math.md`` section 3) and ``q_dot = J_inv tau``; and the finiteness checks
  of :meth:`controllers.laws.VisionLaw.step` (error norm, sum of ``N``, a
  ``q_dot`` check that is 0 exactly when every entry is finite).

The other cases (hidden features, DESIRED / MEAN interaction) keep the numpy
path of :mod:`controllers.laws`; both paths are tested equal
(``tests/controllers/test_law_kernel.py``).

Input: the feature block (see :data:`DIRECTION_INPUTS`, :data:`EDGE_INPUTS`),
then the law parameters :data:`LAW_INPUTS`. Output: the feature error, then
:data:`LAW_OUTPUTS`, then the leg directions (18).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import lru_cache

import casadi as ca
import numpy as np

from controllers.law_tools import gain_formula
from controllers.tasks.joint_length import inverse_jacobian_row
from controllers.tasks.leg_direction import direction_block
from controllers.tasks.leg_edge import edge_block, leg_direction_of_edges, normal_of_line
from hexapod.compiled import CompiledFunction

#: Cyclic Jacobi sweeps of the 6 x 6 eigen-decomposition (quadratic convergence:
#: 5 to 6 reach double precision on the matrices of the laws; 8 leave a margin).
JACOBI_SWEEPS = 8
#: Sweeps of the laws' eigenvalues (rank and condition only; see :func:`law_tail`).
LAW_SWEEPS = 6

#: Law parameters after the feature block: gain ``(lambda0, lambda_inf, lambda0')``,
#: squared threshold, squared damping (or the QP regularization).
LAW_INPUTS = (("gain", 3), ("threshold2", 1), ("damping2", 1))
#: Direction-law feature block: measured ``u`` (6 x 3), desired ``u*``, ``A`` (6 x 3), ``q``.
DIRECTION_INPUTS = (("features", 18), ("desired", 18), ("base_points", 18), ("lengths", 6))
#: Edge-law feature block: features (12 x 3 lines or normals), desired, ``K``, ``K^-1``
#: (row-major; identities for normals), ``A`` (6 x 3), ``q``.
EDGE_INPUTS = (("features", 36), ("desired", 36), ("K", 9), ("K_inv", 9), ("base_points", 18),
               ("lengths", 6))
#: After the error: ``|e|``, sum of ``N``, rank, condition, gain, ``tau`` (6), ``q_dot`` (6),
#: finiteness check of ``q_dot``, ``N`` (36, row-major), ``b`` (6), ``J_inv`` (36).
LAW_OUTPUTS = (("error_norm", 1), ("n_sum", 1), ("rank", 1), ("condition", 1), ("gain", 1),
               ("tau", 6), ("qdot", 6), ("qdot_check", 1), ("N", 36), ("b", 6), ("J", 36))


def _offsets(fields: Sequence[tuple[str, int]], start: int = 0) -> dict[str, slice]:
    return dict(_offsets_cached(tuple(fields), start))


@lru_cache(maxsize=32)
def _offsets_cached(fields: tuple[tuple[str, int], ...], start: int) -> dict[str, slice]:
    out: dict[str, slice] = {}
    k = start
    for name, size in fields:
        out[name] = slice(k, k + size)
        k += size
    return out


# --------------------------------------------------------------------------- expressions
def cholesky_solve(M: list[list[ca.SX]], rhs: list[ca.SX]) -> list[ca.SX]:
    """``M^-1 rhs`` for a symmetric positive definite 6 x 6 ``M`` (unrolled Cholesky;
    NaN when ``M`` is not positive definite)."""
    n = len(rhs)
    L: list[list[ca.SX]] = [[ca.SX(0.0)] * n for _ in range(n)]
    for j in range(n):
        d = M[j][j]
        for k in range(j):
            d = d - L[j][k] * L[j][k]
        L[j][j] = ca.sqrt(d)
        for i in range(j + 1, n):
            v = M[i][j]
            for k in range(j):
                v = v - L[i][k] * L[j][k]
            L[i][j] = v / L[j][j]
    z: list[ca.SX] = []
    for i in range(n):
        v = rhs[i]
        for k in range(i):
            v = v - L[i][k] * z[k]
        z.append(v / L[i][i])
    sol: list[ca.SX] = [ca.SX(0.0)] * n
    for i in reversed(range(n)):
        v = z[i]
        for k in range(i + 1, n):
            v = v - L[k][i] * sol[k]
        sol[i] = v / L[i][i]
    return sol


def jacobi_eigen(N: ca.SX, sweeps: int = JACOBI_SWEEPS, vectors: bool = True
                 ) -> tuple[list[ca.SX], list[list[ca.SX]]]:
    """Eigenvalues and eigenvectors of a symmetric 6 x 6 SX matrix (cyclic Jacobi, unrolled).

    Each rotation zeroes ``a_pq`` (Golub and Van Loan, ``sym.schur2``); a rotation
    whose ``a_pq`` is already zero is skipped without dividing by it.

    Args:
        N: The matrix.
        sweeps: Cyclic sweeps (unrolled).
        vectors: Accumulate the eigenvectors (False: the identity is returned for
            ``V``, and the expression is about a third smaller).

    Returns:
        The eigenvalues ``w`` (6, unsorted) and ``V`` as rows ``V[k][j]`` (column
        ``j`` is the eigenvector of ``w[j]``).
    """
    n = N.shape[0]
    a = [[N[i, j] for j in range(n)] for i in range(n)]
    V: list[list[ca.SX]] = [[ca.SX(1.0 if i == j else 0.0) for j in range(n)] for i in range(n)]
    for _ in range(sweeps):
        for p in range(n - 1):
            for q in range(p + 1, n):
                apq = a[p][q]
                zero = apq == 0
                theta = (a[q][q] - a[p][p]) / (2.0 * ca.if_else(zero, 1.0, apq))
                t = ca.if_else(theta >= 0, 1.0, -1.0) / (ca.fabs(theta)
                                                         + ca.sqrt(1.0 + theta * theta))
                t = ca.if_else(zero, 0.0, t)
                c = 1.0 / ca.sqrt(1.0 + t * t)
                s = t * c
                app = a[p][p] - t * apq
                aqq = a[q][q] + t * apq
                for k in range(n):
                    if k in (p, q):
                        continue
                    akp, akq = a[k][p], a[k][q]
                    a[k][p] = a[p][k] = c * akp - s * akq
                    a[k][q] = a[q][k] = s * akp + c * akq
                a[p][p], a[q][q] = app, aqq
                a[p][q] = a[q][p] = ca.SX(0.0)
                if not vectors:
                    continue
                for k in range(n):
                    vkp, vkq = V[k][p], V[k][q]
                    V[k][p] = c * vkp - s * vkq
                    V[k][q] = s * vkp + c * vkq
    return [a[i][i] for i in range(n)], V


def full_rank_certificate(N: ca.SX, thr2: ca.SX) -> ca.SX:
    """1 when ``N`` is certainly of full rank for the eigenvalue threshold, else 0.

    The certificate of the lean cores (:func:`law_tail` with ``lean``): the Cholesky
    pivots of ``N - c I`` with ``c = (2 thr2 + 1e-10) |N|_F`` are all positive. As
    ``|N|_F >= w_max``, this proves ``w_min > c >= thr2 w_max`` with a margin of a
    factor two (and of ``1e-10 |N|_F`` against rounding), i.e. the rank the exact
    eigenvalues give is 6. A 0 says nothing: the caller computes the exact rank.
    """
    fro = ca.sqrt(ca.sum1(ca.reshape(N * N, 36, 1)))
    c = (2.0 * thr2 + 1e-10) * fro
    L: list[list[ca.SX]] = [[ca.SX(0.0)] * 6 for _ in range(6)]
    ok = fro > 0
    for j in range(6):
        d = N[j, j] - c
        for k in range(j):
            d = d - L[j][k] * L[j][k]
        ok = ca.logic_and(ok, d > 0)
        L[j][j] = ca.sqrt(ca.if_else(d > 0, d, 1.0))
        for i in range(j + 1, 6):
            v = N[i, j]
            for k in range(j):
                v = v - L[i][k] * L[j][k]
            L[i][j] = v / L[j][j]
    return ca.if_else(ok, 1.0, 0.0)


def law_tail(e: ca.SX, N: ca.SX, b: ca.SX, directions: list[ca.SX], base_points: list[ca.SX],
             params: ca.SX, lean: bool = False) -> list[ca.SX]:
    """The law part shared by every feature kind (see the module docstring).

    Args:
        e: Stacked error (m, 1).
        N: ``L^T L`` (6, 6).
        b: ``L^T e`` (6, 1).
        directions: Six (3, 1) leg directions for ``J_inv``.
        base_points: Six (3, 1) ``A_i`` [m].
        params: The :data:`LAW_INPUTS` (5, 1).
        lean: The core of the batched laws: no eigenvalues; the rank output is 6 when
            :func:`full_rank_certificate` proves full rank (then every output equals
            the full core's to the last bit) and 0 otherwise (the caller steps that
            row with the full core); the condition output is NaN.

    Returns:
        The :data:`LAW_OUTPUTS`, in order.
    """
    l0, linf, slope, thr2, d2 = (params[k] for k in range(5))
    # Gain (controllers.law_tools.gain_formula) at x = |e|_inf.
    x = ca.mmax(ca.fabs(e))
    lam = gain_formula(x, l0, linf, slope, ca.exp, ca.if_else)
    if lean:
        full = full_rank_certificate(N, thr2) == 1.0
        rank = ca.if_else(full, 6.0, 0.0)
        cond = ca.SX(float("nan"))
    else:
        # Rank and condition from the eigenvalues (solve_normal's threshold). The
        # command is needed only at full rank (the laws refuse below it), where the
        # thresholded, damped pseudo-inverse sum_j (v_j^T b) / (w_j + d2) v_j is
        # (N + d2 I)^-1 b: a Cholesky solve, without the eigenvectors.
        w, _ = jacobi_eigen(N, LAW_SWEEPS, vectors=False)
        w_max = w[0]
        w_min = w[0]
        for j in range(1, 6):
            w_max = ca.fmax(w_max, w[j])
            w_min = ca.fmin(w_min, w[j])
        positive = w_max > 0
        keep = [ca.logic_and(positive, w[j] > thr2 * w_max) for j in range(6)]
        rank = ca.SX(0.0)
        for kept in keep:
            rank = rank + ca.if_else(kept, 1.0, 0.0)
        cond = ca.if_else(ca.logic_and(positive, w_min > 0),
                          ca.sqrt(w_max / ca.if_else(w_min > 0, w_min, 1.0)), ca.inf)
        full = rank == 6.0
    M = [[ca.if_else(full, N[i, j] + (d2 if i == j else 0.0), 1.0 if i == j else 0.0)
          for j in range(6)] for i in range(6)]
    sol = cholesky_solve(M, [b[i] for i in range(6)])
    tau = ca.vertcat(*[ca.if_else(full, x, 0.0) for x in sol]) * (-lam)
    # Inverse Jacobian rows [u_i^T, (A_i x u_i)^T] and q_dot = J_inv tau.
    J = ca.vertcat(*[inverse_jacobian_row(u, A)
                     for u, A in zip(directions, base_points, strict=True)])
    qdot = J @ tau
    return [ca.sqrt(ca.dot(e, e)), ca.sum1(ca.reshape(N, 36, 1)), rank, cond, lam, tau, qdot,
            ca.sum1(qdot - qdot), ca.reshape(N.T, 36, 1), b, ca.reshape(J.T, 36, 1)]


def _upper_zeros() -> list[list[ca.SX]]:
    """The upper triangle of a 6 x 6 accumulator (``N = L^T L`` is symmetric: each sum is
    built once)."""
    return [[ca.SX(0.0) for _ in range(6)] for _ in range(6)]


def _symmetric(upper: list[list[ca.SX]]) -> ca.SX:
    """The symmetric 6 x 6 matrix of an upper triangle."""
    return ca.vertcat(*[ca.horzcat(*[upper[min(i, j)][max(i, j)] for j in range(6)])
                        for i in range(6)])


def _direction_function(lean: bool = False) -> ca.Function:
    """Leg-direction law: ``e_i = u_i x u_i*``, ``L_i = -[u_i*]_x M_i`` (docs/math.md §3, §6)."""
    n_feat = sum(s for _, s in DIRECTION_INPUTS)
    x = ca.SX.sym("x", n_feat + sum(s for _, s in LAW_INPUTS))
    sl = _offsets(DIRECTION_INPUTS)
    u = [x[sl["features"]][3 * i:3 * i + 3] for i in range(6)]
    us = [x[sl["desired"]][3 * i:3 * i + 3] for i in range(6)]
    A = [x[sl["base_points"]][3 * i:3 * i + 3] for i in range(6)]
    q = [x[sl["lengths"]][i] for i in range(6)]
    errors = []
    Nu = _upper_zeros()
    b = ca.SX.zeros(6, 1)
    for i in range(6):
        ei, L = direction_block(u[i], us[i], A[i], q[i])
        for row in range(6):
            for col in range(row, 6):
                Nu[row][col] = Nu[row][col] + ca.dot(L[:, row], L[:, col])
        b += L.T @ ei
        errors.append(ei)
    N = _symmetric(Nu)
    e = ca.vertcat(*errors)
    tail = law_tail(e, N, b, u, A, x[n_feat:], lean)
    name = "hexapod_direction_law" + ("_lean" if lean else "")
    return ca.Function(name, [x], [ca.vertcat(e, *tail, *u)])


def _edge_function(use_lines: bool, lean: bool = False) -> ca.Function:
    """Leg-edge law on pixel lines or normals (rank-one blocks, ``controllers.interaction``)."""
    n_feat = sum(s for _, s in EDGE_INPUTS)
    x = ca.SX.sym("x", n_feat + sum(s for _, s in LAW_INPUTS))
    sl = _offsets(EDGE_INPUTS)
    feat = [x[sl["features"]][3 * k:3 * k + 3] for k in range(12)]
    star = [x[sl["desired"]][3 * k:3 * k + 3] for k in range(12)]
    Kt = ca.reshape(x[sl["K"]], 3, 3)  # column-major read of a row-major K: K^T
    Kinv_t = ca.reshape(x[sl["K_inv"]], 3, 3)  # (K^-1)^T
    A = [x[sl["base_points"]][3 * i:3 * i + 3] for i in range(6)]
    q = [x[sl["lengths"]][i] for i in range(6)]
    n = [normal_of_line(f, Kt) if use_lines else f for f in feat]
    u = [leg_direction_of_edges(n[2 * i], n[2 * i + 1]) for i in range(6)]
    errors = []
    Nu = _upper_zeros()
    b = ca.SX.zeros(6, 1)
    inv_q = [1.0 / qi for qi in q]  # one division per leg
    for k in range(12):
        i = k // 2
        ek, a, g = edge_block(feat[k], star[k], n[k], u[i], A[i], q[i], inv_q[i],
                              Kt if use_lines else None, Kinv_t if use_lines else None)
        errors.append(ek)
        weight = ca.dot(a, a)
        for row in range(6):
            for col in range(row, 6):
                Nu[row][col] = Nu[row][col] + weight * (g[row] * g[col])
        b += ca.dot(a, ek) * g
    N = _symmetric(Nu)
    e = ca.vertcat(*errors)
    tail = law_tail(e, N, b, u, A, x[n_feat:], lean)
    name = "hexapod_edge_law_lines_v2" if use_lines else "hexapod_edge_law_normals_v2"
    name += "_lean" if lean else ""
    return ca.Function(name, [x], [ca.vertcat(e, *tail, *u)])


# --------------------------------------------------------------------------- runtime
@dataclass
class LawResult:
    """One evaluation of a law kernel (fresh arrays, safe to keep in a command).

    Attributes:
        error: (m,) stacked error.
        error_norm: ``|e|``.
        n_sum: Sum of the entries of ``N`` (finiteness check).
        rank: Rank of ``L`` (eigenvalues of ``N`` above ``threshold^2 w_max``).
        condition: ``sqrt(w_max / w_min)`` (inf when singular).
        gain: ``lambda`` [1/s].
        tau: (6,) classical twist ``-lambda L^+ e``.
        qdot: (6,) ``J_inv tau`` [m/s].
        qdot_finite: Every entry of ``qdot`` is finite.
        N: (6, 6) ``L^T L``.
        b: (6,) ``L^T e``.
        J: (6, 6) inverse Jacobian.
        directions: (6, 3) leg directions used by ``J``.
    """

    error: np.ndarray
    error_norm: float
    n_sum: float
    rank: int
    condition: float
    gain: float
    tau: np.ndarray
    qdot: np.ndarray
    qdot_finite: bool
    N: np.ndarray
    b: np.ndarray
    J: np.ndarray
    directions: np.ndarray


class LawKernel:
    """A compiled law core with a preallocated input vector.

    Constant inputs (desired features, base points, gain, ...) are written once
    with :meth:`set`; each step writes the measured features and lengths into
    the views of :attr:`inputs` and calls :meth:`evaluate`.

    Args:
        function: The compiled core.
        feature_inputs: The feature block layout.
        n_error: Size of the stacked error.
        lean: Builds the lean core of the same law (same inputs and outputs; see
            :func:`law_tail`), compiled on first use by :attr:`lean_function`.
    """

    def __init__(self, function: CompiledFunction, feature_inputs: Sequence[tuple[str, int]],
                 n_error: int, lean: Callable[[], CompiledFunction] | None = None) -> None:
        self.function = function
        self._lean = lean
        n_feat = sum(s for _, s in feature_inputs)
        #: The input vector (constants set once, features and lengths each step).
        self.input_vector = np.zeros(function.n_in)
        #: Where each named input lies in :attr:`input_vector`.
        self.slices = {**_offsets(feature_inputs), **_offsets(LAW_INPUTS, n_feat)}
        #: Views of the input vector by name (write into them).
        self.inputs = {k: self.input_vector[s] for k, s in self.slices.items()}
        #: Where each named output lies in the output vector.
        self.outputs = _offsets((("error", n_error), *LAW_OUTPUTS, ("directions", 18)))

    @property
    def lean_function(self) -> CompiledFunction:
        """The lean core (the batched laws' one; :attr:`function` without a lean one)."""
        return self.function if self._lean is None else self._lean()

    @property
    def compiled(self) -> bool:
        """True when the C code is used (False: CasADi virtual machine)."""
        return self.function.compiled

    def set(self, name: str, value: np.ndarray | float | Sequence[float]) -> None:
        """Write an input (any shape with the right number of values)."""
        self.inputs[name][:] = np.asarray(value, dtype=float).reshape(-1)

    def evaluate(self) -> LawResult:
        """One call of the core on the current inputs."""
        y = self.function.single(self.input_vector)
        o = self.outputs
        return LawResult(
            error=y[o["error"]], error_norm=float(y[o["error_norm"].start]),
            n_sum=float(y[o["n_sum"].start]), rank=int(y[o["rank"].start]),
            condition=float(y[o["condition"].start]), gain=float(y[o["gain"].start]),
            tau=y[o["tau"]], qdot=y[o["qdot"]], qdot_finite=y[o["qdot_check"].start] == 0.0,
            N=y[o["N"]].reshape(6, 6), b=y[o["b"]], J=y[o["J"]].reshape(6, 6),
            directions=y[o["directions"]].reshape(6, 3))


@lru_cache(maxsize=2)
def _direction_compiled(lean: bool = False) -> CompiledFunction:
    return CompiledFunction(_direction_function(lean))


@lru_cache(maxsize=4)
def _edge_compiled(use_lines: bool, lean: bool = False) -> CompiledFunction:
    return CompiledFunction(_edge_function(use_lines, lean))


def direction_kernel() -> LawKernel:
    """A kernel of the leg-direction law (its own input buffer; shared compiled code)."""
    return LawKernel(_direction_compiled(), DIRECTION_INPUTS, 18,
                     lambda: _direction_compiled(True))


def edge_law_kernel(use_lines: bool) -> LawKernel:
    """A kernel of the leg-edge law on pixel lines (True) or normals (False)."""
    return LawKernel(_edge_compiled(use_lines), EDGE_INPUTS, 36,
                     lambda: _edge_compiled(use_lines, True))
