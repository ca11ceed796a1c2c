"""What the computed-torque laws' one steps share around their compiled kernels.

:data:`NEWTON_CALLS_C` calls a kernel on a row from C, again from the pose reached while
it has not converged, and screens the rank of its result (``rank_screen``);
:func:`evaluate_rows` does the same for many rows in lanes (the
same bits as row by row); :func:`rank_condition` is the exact rank test (LAPACK) where
the kernel's screen does not settle it; :func:`refusal` words why a row is not a
command; :func:`norms` the error norms as a vector's own dot product.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg.lapack import dsyevd as _eigenvalues

from controllers.ctc_status import Status, status_reason
from hexapod.c_step import KERNEL_CALL_C
from hexapod.compiled import CompiledFunction

#: Calls of a compiled step (its Newton iterations each) before the step is refused (as
#: the 50 iterations of :func:`hexapod.fk.forward_kinematics`).
FK_MAX_CALLS = 16


#: C: ``newton_calls(k, x, y, pose_in, pose_out, residual, tol, max_calls)``: ``y = f(x)``
#: by the :class:`~hexapod.c_step.KernelCall` ``k``, called again from the pose reached
#: (``y``'s 12 pose values into ``x``'s) while the residual ``y[residual]`` is not below
#: ``tol`` (finite, at most ``max_calls`` calls in all): :func:`evaluate_rows` row by row.
NEWTON_CALLS_C = KERNEL_CALL_C + r"""
static int newton_calls(const KernelCall *k, double *x, double *y, int64_t pose_in,
                        int64_t pose_out, int64_t residual, double tol, int64_t max_calls) {
    if (kernel_call(k, x, y)) return 1;
    for (int64_t calls = 1; !(y[residual] < tol); calls++) {
        if (calls >= max_calls || !isfinite(y[residual])) break;
        memcpy(x + pose_in, y + pose_out, 12 * sizeof(double));
        if (kernel_call(k, x, y)) return 1;
    }
    return 0;
}

/* the rank screen of a step's output row y: 0 a nonzero status (refused), 1 the screen
   cannot prove full rank (unsure: the exact test decides), 2 full rank */
static int rank_screen(const double *y, int64_t status_at, int64_t screen_at,
                       double scale) {
    if (y[status_at] != 0.0) return 0;
    double det = y[screen_at], tr = y[screen_at + 1];
    return tr > 0.0 && det > scale * pow(tr, 6.0) ? 2 : 1;
}
"""


def evaluate_rows(function: CompiledFunction, X: np.ndarray, pose_in: slice, pose_out: slice,
                  residual: int, tolerance: float, max_calls: int) -> tuple[np.ndarray,
                                                                            np.ndarray]:
    """The compiled step of every row of ``X`` (n, n_in), called again from the pose
    reached on the rows whose pose residual is not below ``tolerance`` (as the per-trial
    steps do), at most ``max_calls`` calls in all.

    Args:
        function: The compiled step.
        X: (n, n_in) input rows; their ``pose_in`` block is overwritten on the rows
            called again.
        pose_in: The pose guess's block in an input row.
        pose_out: The pose's block in an output row.
        residual: The index of the pose residual in an output row.
        tolerance: Residual below which the pose has converged.
        max_calls: Calls of the step per row at most.

    Returns:
        (n, n_out) the output rows and (n,) the mask of the rows whose pose converged.
    """
    Y = function.batch(X, lanes=True)
    calls = 1
    with np.errstate(invalid="ignore"):
        pending = np.flatnonzero(~(Y[:, residual] < tolerance))
        while len(pending) and calls < max_calls:
            pending = pending[np.isfinite(Y[pending, residual])]
            if not len(pending):
                break
            X[pending, pose_in] = Y[pending, pose_out]
            Y[pending] = function.batch(X[pending], lanes=True)
            calls += 1
            pending = pending[~(Y[pending, residual] < tolerance)]
        converged = Y[:, residual] < tolerance
    return Y, converged  # type: ignore[return-value]


def rank_condition(factor: np.ndarray, threshold: float) -> float | None:
    """The condition number of a Jacobian from ``L^T L`` (36,), or None when it is
    rank-deficient (its smallest squared singular value, an eigenvalue of ``L^T L`` by
    LAPACK ``syevd``, not above ``threshold^2`` times the largest)."""
    w, _, info = _eigenvalues(factor.reshape(6, 6), 0)  # compute_v=0 (by position)
    w_min, w_max = float(w[0]), float(w[-1])
    if info != 0 or not (w_max > 0 and w_min > threshold**2 * w_max):
        return None
    return math.sqrt(w_max) / math.sqrt(w_min)


def norms(e: np.ndarray) -> np.ndarray:
    """(m,) the squared norms of the rows of ``e`` (m, k): each row's own ``e @ e`` (the
    dot product of a vector, as the per-trial steps compute it: the same numbers)."""
    return np.matmul(e[:, None, :], e[:, :, None])[:, 0, 0]  # type: ignore[no-any-return]


def refusal(y: np.ndarray, status: int, residual: int, factor: slice, threshold: float,
            pose_name: str = "forward kinematics of the lengths",
            inputs: dict[str, np.ndarray] | None = None) -> str | None:
    """Why a compiled step's output row ``y`` is not a command (None: it is): its
    ``status`` output (:class:`~controllers.ctc_status.Status`), then the rank test of
    the Jacobian (``RANK_DEFICIENT``), worded by :func:`~controllers.ctc_status.
    status_reason`.

    Args:
        y: The output row.
        status: The index of the ``status`` code in the row.
        residual: The index of the pose residual in the row.
        factor: The block of ``L^T L`` (36) in the row.
        threshold: Relative singular-value threshold of the rank test.
        pose_name: What found the pose (named by the refusal).
        inputs: The input row's views by block (``mask``, ``seen``: the rows and legs a
            refusal for too few of them counts), or None.
    """
    code = int(y[status])
    if code == Status.OK:
        if rank_condition(y[factor], threshold) is not None:
            return None
        w = np.linalg.eigvalsh(y[factor].reshape(6, 6))
        cond = math.sqrt(w[-1] / w[0]) if w[0] > 0 else math.inf
        return status_reason(Status.RANK_DEFICIENT, condition=cond)
    views = {} if inputs is None else inputs
    mask, seen = views.get("mask"), views.get("seen")
    return status_reason(
        code, residual=float(y[residual]), pose_name=pose_name,
        non_finite="leg forces" if np.isfinite(y[factor]).all() else "Jacobian",
        rows=0 if mask is None else int(np.sum(mask == 1.0)),
        legs=None if seen is None else np.flatnonzero(seen == 1.0).tolist())


__all__ = ["FK_MAX_CALLS", "NEWTON_CALLS_C", "evaluate_rows", "norms",
           "rank_condition", "refusal"]
