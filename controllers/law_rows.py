"""The compiled core of a vision law over the rows of a batch (:meth:`controllers.laws.
VisionLaw.step_batch`): each trial's core inputs as one row of an array, and the lean
core (:mod:`controllers.law_kernel`) that evaluates any rows of it in one C loop and
fills the commands of the rows whose result is the command as it is.
"""

from __future__ import annotations

import numpy as np

from controllers.base import CommandBatch
from controllers.estimators import LegDirectionEstimate
from controllers.law_kernel import LawKernel
from controllers.solvers.base import Solver
from hexapod.compiled import CompiledFunction, Layout


class KernelRows:
    """The inputs of the compiled cores of a batch's trials, one row per trial, and the
    lean core that evaluates any rows of them in one C loop (the vision laws' step over
    a batch, :meth:`controllers.laws.VisionLaw.step_batch`).

    Args:
        n: Trials of the batch.
    """

    def __init__(self, n: int) -> None:
        #: The lean core (None until a trial has a compiled core).
        self.function: CompiledFunction | None = None
        #: Where each named input lies in a row, and each named output in a result (the
        #: lean core's layouts; empty until a trial has a compiled core).
        self.slices: Layout = Layout((), "law core input")
        self.outputs: Layout = Layout((), "law core output")
        self.n = n
        self.X = np.zeros((0, 0))
        #: (n,) the trials whose row holds its core's inputs (the lean core may step them).
        self.ready = np.zeros(n, dtype=bool)
        #: (n,) the rows holding a core's constants (a retarget may write its desired
        #: features alone).
        self.filled = np.zeros(n, dtype=bool)

    def take(self, trial: int, kernel: LawKernel | None) -> None:
        """Copy a trial's core inputs into its row (None: the trial has no lean core)."""
        self.ready[trial] = kernel is not None
        if kernel is None:
            return
        if self.function is None:
            self.function = kernel.lean_function
            self.slices = kernel.slices
            self.outputs = kernel.outputs
            self.X = np.zeros((self.n, kernel.function.n_in))
        self.X[trial] = kernel.input_vector
        self.filled[trial] = True

    def write_desired(self, trials: np.ndarray, desired: np.ndarray, quick: np.ndarray
                      ) -> np.ndarray:
        """Write the desired features ``desired`` (m, D) of the goals ``quick`` (m,) into
        the rows of ``trials`` (m,) that hold their constants; returns the mask of the
        goals written."""
        if self.function is None:
            return np.zeros(len(trials), dtype=bool)
        quick = quick & self.filled[trials]
        rows = np.flatnonzero(quick)
        if len(rows):
            self.X[trials[rows], self.slices["desired"]] = desired[rows]
            self.ready[trials[rows]] = True
        return quick  # type: ignore[no-any-return]

    def accepted(self, Y: np.ndarray) -> np.ndarray:
        """(m,) the results that are a command as they are: a finite error and
        interaction matrix, rank 6, a finite command (the refusals and the non-finite
        cases are left to the trial's own step, which says why)."""
        o = self.outputs
        with np.errstate(invalid="ignore"):
            return (np.isfinite(Y[:, o["error_norm"].start])  # type: ignore[no-any-return]
                    & np.isfinite(Y[:, o["n_sum"].start])
                    & (Y[:, o["rank"].start] >= 6) & (Y[:, o["qdot_check"].start] == 0.0))

    def step(self, rows: np.ndarray, trials: np.ndarray, features: np.ndarray,
             lengths: np.ndarray, solver: Solver, estimate: LegDirectionEstimate,
             out: CommandBatch) -> np.ndarray:
        """The lean core over the batch rows ``rows`` of ``trials`` with their measured
        ``features`` and ``lengths`` [m]; the rows whose result is the command
        (:meth:`accepted`, and ``solver.batch_accept``) update the batch's ``estimate``
        as a commanded step and fill ``out``.

        Returns:
            (m,) the rows filled.
        """
        X = self.X[trials]
        X[:, self.slices["features"]] = features
        X[:, self.slices["lengths"]] = lengths
        assert self.function is not None
        Y = self.function.batch(X)
        o = self.outputs
        ok = self.accepted(Y) & solver.batch_accept(trials, lengths, Y[:, o["qdot"]])
        if ok.all():  # the common case: no row copies
            Ya, tr, qa, ra = Y, trials, lengths, rows
        else:
            acc = np.flatnonzero(ok)
            Ya, tr, qa, ra = Y[acc], trials[acc], lengths[acc], rows[acc]
        estimate.measured_all(Ya[:, o["directions"]].reshape(-1, 6, 3), tr)
        estimate.commanded(Ya[:, o["tau"]], qa, tr)
        out.velocities[ra] = Ya[:, o["qdot"]]
        out.error_norm[ra] = Ya[:, o["error_norm"].start]
        return ok  # type: ignore[no-any-return]
