"""The algebra shared by the compiled law cores (:mod:`controllers.law_kernel`), as CasADi
SX expressions: an unrolled Cholesky solve, the cyclic Jacobi eigen-decomposition of a
symmetric 6 x 6 matrix, the full-rank certificate of the lean cores, the rank screen of
the computed-torque steps (:func:`rank_screen`), and the law part every feature kind
shares (:func:`law_tail`: gain, rank, condition, damped solve, inverse Jacobian,
``q_dot``)."""

from __future__ import annotations

from collections.abc import Callable

import casadi as ca

from controllers.law_tools import gain_formula
from controllers.tasks.joint_length import inverse_jacobian_row

#: Cyclic Jacobi sweeps of the 6 x 6 eigen-decomposition (quadratic convergence:
#: 5 to 6 reach double precision on the matrices of the laws; 8 leave a margin).
JACOBI_SWEEPS = 8
#: Sweeps of the laws' eigenvalues (rank and condition only; see :func:`law_tail`).
LAW_SWEEPS = 6


def _cholesky(M: list[list[ca.SX]], pivot: Callable[[ca.SX], ca.SX]) -> list[list[ca.SX]]:
    """The lower Cholesky factor of a symmetric ``M`` (unrolled), each diagonal entry
    ``pivot(d)`` of the remaining pivot ``d``."""
    n = len(M)
    L: list[list[ca.SX]] = [[ca.SX(0.0)] * n for _ in range(n)]
    for j in range(n):
        d = M[j][j]
        for k in range(j):
            d = d - L[j][k] * L[j][k]
        L[j][j] = pivot(d)
        for i in range(j + 1, n):
            v = M[i][j]
            for k in range(j):
                v = v - L[i][k] * L[j][k]
            L[i][j] = v / L[j][j]
    return L


def cholesky_solve(M: list[list[ca.SX]], rhs: list[ca.SX]) -> list[ca.SX]:
    """``M^-1 rhs`` for a symmetric positive definite 6 x 6 ``M`` (unrolled Cholesky;
    NaN when ``M`` is not positive definite)."""
    n = len(rhs)
    L = _cholesky(M, ca.sqrt)
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
    """The eigenvalues ``w`` (6, unsorted) of a symmetric 6 x 6 SX matrix and ``V`` as rows
    ``V[k][j]`` (column ``j`` the eigenvector of ``w[j]``; the identity unless
    ``vectors``, an expression a third smaller): ``sweeps`` unrolled cyclic Jacobi sweeps,
    each rotation zeroing ``a_pq`` (Golub and Van Loan, ``sym.schur2``; skipped where
    ``a_pq`` is already zero)."""
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
                # the other rows at once: the same scalar operations as one by one
                others = [k for k in range(n) if k not in (p, q)]
                akp = ca.vertcat(*(a[k][p] for k in others))
                akq = ca.vertcat(*(a[k][q] for k in others))
                new_p, new_q = c * akp - s * akq, s * akp + c * akq
                for j, k in enumerate(others):
                    a[k][p] = a[p][k] = new_p[j]
                    a[k][q] = a[q][k] = new_q[j]
                a[p][p], a[q][q] = app, aqq
                a[p][q] = a[q][p] = ca.SX(0.0)
                if not vectors:
                    continue
                vkp = ca.vertcat(*(V[k][p] for k in range(n)))
                vkq = ca.vertcat(*(V[k][q] for k in range(n)))
                new_p, new_q = c * vkp - s * vkq, s * vkp + c * vkq
                for k in range(n):
                    V[k][p], V[k][q] = new_p[k], new_q[k]
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
    ok = [fro > 0]

    def pivot(d: ca.SX) -> ca.SX:
        ok[0] = ca.logic_and(ok[0], d > 0)
        return ca.sqrt(ca.if_else(d > 0, d, 1.0))

    _cholesky([[N[i, j] - c if i == j else N[i, j] for j in range(6)] for i in range(6)], pivot)
    return ca.if_else(ok[0], 1.0, 0.0)


def rank_screen(N: ca.SX) -> ca.SX:
    """(2,) the rank screen of the computed-torque steps' ``N = L^T L`` (symmetric 6 x 6):
    ``det N`` when every pivot of its Cholesky factorisation is positive (their product;
    else 0), and ``trace N``. As ``w_min >= det / trace^5``,
    the computed-torque steps' C (:mod:`controllers.joint_ctc_rows`,
    :mod:`controllers.task_ctc_rows`) clears a row with ``det > 4 thr^2 trace^6``: far
    above the threshold, where rounding cannot matter (the other rows get the exact
    test, :func:`controllers.ctc_rows.rank_condition`)."""
    ok, det = [ca.SX(1.0)], [ca.SX(1.0)]

    def pivot(d: ca.SX) -> ca.SX:
        ok[0], det[0] = ca.logic_and(ok[0], d > 0), det[0] * d
        return ca.sqrt(ca.if_else(d > 0, d, 1.0))

    _cholesky([[N[i, j] for j in range(6)] for i in range(6)], pivot)
    return ca.vertcat(ca.if_else(ok[0], det[0], 0.0), ca.trace(N))


def law_tail(e: ca.SX, N: ca.SX, b: ca.SX, directions: list[ca.SX], base_points: list[ca.SX],
             params: ca.SX, lean: bool = False) -> list[ca.SX]:
    """The law part shared by every feature kind (:mod:`controllers.law_kernel`): gain,
    rank, condition, damped solve at full rank, ``J_inv`` and ``q_dot``.

    Args:
        e: Stacked error (m, 1), zeros for the unused features.
        N: ``L^T W L`` (6, 6).
        b: ``L^T W e`` (6, 1).
        directions: Six (3, 1) leg directions for ``J_inv``.
        base_points: Six (3, 1) ``A_i`` [m].
        params: The :data:`LAW_INPUTS` (5, 1).
        lean: The batched laws' core: no eigenvalues, the rank 6 when
            :func:`full_rank_certificate` proves it (every output then the full core's to
            the last bit) else 0 (the caller steps the row with the full core), the
            condition NaN.

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


class WeightedNormal:
    """``N = sum_k w_k L_k^T L_k`` and ``b = sum_k w_k L_k^T e_k`` over weighted blocks.

    A block of weight zero is left out exactly: its terms are replaced by zeros (a
    ``NaN`` or ``inf`` in an unused block does not reach ``N`` or ``b``), and its error
    counts neither in :attr:`used_errors` (the error norm and the gain of the law) nor
    in the rank of ``N``. With weight one the sums are, to the last bit, the unweighted
    ones (``1 x`` is ``x``).
    """

    def __init__(self) -> None:
        #: The upper triangle of ``N`` (symmetric: each sum is built once).
        self.upper = [[ca.SX(0.0) for _ in range(6)] for _ in range(6)]
        self.b = ca.SX.zeros(6, 1)
        #: The blocks' errors with the unused ones replaced by zeros.
        self.used_errors: list[ca.SX] = []

    def add_dense(self, e: ca.SX, L: ca.SX, weight: ca.SX) -> None:
        """A block ``e`` (r, 1), ``L`` (r, 6) of weight ``weight`` (>= 0)."""
        used = weight != 0
        Lm = ca.if_else(used, L, 0.0)
        em = ca.if_else(used, e, 0.0)
        for row in range(6):
            for col in range(row, 6):
                self.upper[row][col] = self.upper[row][col] + weight * ca.dot(Lm[:, row],
                                                                              Lm[:, col])
        self.b += weight * (Lm.T @ em)
        self.used_errors.append(em)

    def add_rank_one(self, e: ca.SX, a: ca.SX, g: ca.SX, weight: ca.SX) -> None:
        """A rank-one block ``L = a g^T`` (``a`` (r, 1), ``g`` (6, 1)): ``L^T L =
        |a|^2 g g^T``, ``L^T e = (a^T e) g``."""
        used = weight != 0
        gm = ca.if_else(used, g, 0.0)
        w = ca.if_else(used, weight * ca.dot(a, a), 0.0)
        c = ca.if_else(used, weight * ca.dot(a, e), 0.0)
        for row in range(6):
            for col in range(row, 6):
                self.upper[row][col] = self.upper[row][col] + w * (gm[row] * gm[col])
        self.b += c * gm
        self.used_errors.append(ca.if_else(used, e, 0.0))

    @property
    def N(self) -> ca.SX:
        """``N`` (6, 6)."""
        return ca.vertcat(*[ca.horzcat(*[self.upper[min(i, j)][max(i, j)] for j in range(6)])
                            for i in range(6)])
