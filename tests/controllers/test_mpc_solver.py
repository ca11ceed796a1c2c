"""The predictive controllers' SQP and QP plumbing (``controllers/mpc/solver.py``) on
problems made by hand: the line search's bookkeeping, and DAQP's solutions held to their
rows (checked here with the rows themselves, ``C x``, not the solver's status)."""

from __future__ import annotations

import numpy as np
import pytest

from controllers.mpc.solver import (
    LINE_SEARCH_TRIALS,
    ROW_TOLERANCE,
    daqp,
    outside_rows,
    run_sqp,
)

#: The slices of the hand-made kernel output: its cost, then one row's two bound slacks.
ROWS = {"cost": slice(0, 1), "lba": slice(1, 2), "uba": slice(2, 3)}


def test_a_failed_line_search_builds_the_next_qp_at_the_point_it_keeps() -> None:
    """When no step of the line search decreases the merit, the SQP goes on from the last
    point it evaluated, and its next QP is built from that point's output: the ``U``
    handed to ``qp_data`` is always the argument of the last ``evaluate`` (it was a
    point twice as far along the step as the one kept)."""
    evaluated: list[np.ndarray] = []
    built_at: list[tuple[np.ndarray, np.ndarray]] = []

    def evaluate(U: np.ndarray) -> np.ndarray:
        evaluated.append(U.copy())
        # a cost that rises along every step the QP proposes (its model is wrong): no
        # step decreases the merit; the row's slacks keep it inside (lba <= 0 <= uba)
        return np.array([1.0 + 100.0 * float(U @ U), -1.0, -1.0, *U])

    def qp_data(out: np.ndarray, U: np.ndarray):  # type: ignore[no-untyped-def]
        built_at.append((out[3:].copy(), U.copy()))
        n = len(U)
        return (np.eye(n), -np.ones(n), np.eye(1, n), np.array([-10.0]), np.array([10.0]))

    U, converged, status, _, iterations = run_sqp(
        evaluate, qp_data, np.zeros(6), max_iter=3, tolerance=1e-12, compiled=False,
        merit_rows=ROWS)
    assert not converged and iterations == 3 and U is not None
    assert len(built_at) == 3
    assert len(evaluated) == 1 + 2 * LINE_SEARCH_TRIALS  # the start, two line searches
    for point_of_output, U_given in built_at:
        np.testing.assert_array_equal(point_of_output, U_given)
    # the first line search kept the smallest step tried: 1/32 of the QP's step of ones
    np.testing.assert_array_equal(built_at[1][1], np.full(6, 0.5 ** (LINE_SEARCH_TRIALS - 1)))
    assert "not converged in 3" in status


def _badly_scaled_qp(seed: int) -> tuple[np.ndarray, ...]:
    """A strictly convex QP with a Hessian's eigenvalues from 1e-10 to 1e-6 (as the
    predictive controllers' are: leg forces' or velocities' effects on a sub-millimetre
    error) under box and general rows, several active."""
    rng = np.random.default_rng(seed)
    n = 30
    Q, _ = np.linalg.qr(rng.normal(size=(n, n)))
    H = Q @ np.diag(np.logspace(-10, -6, n)) @ Q.T
    H = 0.5 * (H + H.T)
    g = 1e-6 * rng.normal(size=n)
    C = np.vstack([np.eye(n), rng.normal(size=(20, n))])
    bound = np.full(len(C), 0.05)
    return H, g, C, -bound, bound


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "casadi.conic"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_daqp_solutions_keep_their_rows_on_badly_scaled_problems(compiled: bool,
                                                                  seed: int) -> None:
    """DAQP at its default feasibility tolerance returned "optimal" solutions 0.15 outside
    their rows on these problems (seed 0); the solve must give a solution, and ``C x``
    must lie within the rows (to 1e-9 relative), both through the compiled solver and
    ``casadi.conic``."""
    H, g, C, lba, uba = _badly_scaled_qp(seed)
    res = daqp(H, g, C, lba, uba, compiled)
    assert res.step is not None, res.status
    v = C @ res.step
    size = 1 + np.abs(C) @ np.abs(res.step)
    assert np.all(v >= lba - ROW_TOLERANCE * size)
    assert np.all(v <= uba + ROW_TOLERANCE * size)
    assert np.abs(v).max() > 0.049  # some rows are active (the test's point)


@pytest.mark.parametrize("scale", [1e-3, 1e3])
def test_daqp_judges_a_problem_the_same_in_other_units(scale: float) -> None:
    """The rows and bounds of the badly scaled QPs multiplied by ``scale`` (the same
    problem in other units, the same solution): none of 40 is refused. Measured relative
    to ``1 + |C x|``, 8 of 40 were refused at 1e3 (on their bounds to 1e-9 to 8.5e-9 of
    it: DAQP's accuracy), and 1 of 40 at scale 1."""
    refused = []
    for seed in range(40):
        H, g, C, lba, uba = _badly_scaled_qp(seed)
        res = daqp(H, g, scale * C, scale * lba, scale * uba, True)
        if res.step is None:
            refused.append((seed, res.status))
    assert not refused, refused


def test_outside_rows_measures_the_relative_excess() -> None:
    C = np.eye(2)  # |C| |x| = |C x|: the excess relative to 1 + |C x|
    lo, hi = np.array([-1.0, -1.0]), np.array([1.0, 1.0])
    assert outside_rows(C, np.array([0.5, -1.0]), lo, hi) == 0.0
    assert outside_rows(C, np.array([1.0 + 1e-12, 0.0]), lo, hi) == 0.0  # within
    excess = outside_rows(C, np.array([1.0 + 2e-6, 0.0]), lo, hi)
    assert excess == pytest.approx(2e-6 / (2.0 + 2e-6) - ROW_TOLERANCE, rel=1e-9)
    assert outside_rows(C, np.array([0.0, -1.5]), lo, hi) == pytest.approx(
        0.5 / 2.5 - ROW_TOLERANCE, rel=1e-12)
    # a row whose terms cancel: relative to the terms' size 1 + 100 + 101.5, not 1 + 1.5
    row = np.array([[1.0, -1.0]])
    assert outside_rows(row, np.array([100.0, 101.5]), lo[:1], hi[:1]) == pytest.approx(
        0.5 / 202.5 - ROW_TOLERANCE, rel=1e-12)


def test_outside_rows_refuses_a_nan_row_or_solution() -> None:
    """A NaN bound or solution lies outside (infinitely): the filter of the rows over the
    tolerance (``raw > tol``) had dropped NaN rows and passed them as inside."""
    C, lo, hi = np.eye(2), np.array([-1.0, -1.0]), np.array([1.0, 1.0])
    assert outside_rows(C, np.array([0.0, 0.0]), np.array([np.nan, -1.0]), hi) == np.inf
    assert outside_rows(C, np.array([np.nan, 0.0]), lo, hi) == np.inf
    assert outside_rows(C, np.array([0.0, 0.0]), lo, np.array([1.0, np.nan])) == np.inf
