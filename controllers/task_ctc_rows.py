"""The batch of the task computed-torque laws (``cartesian-ctc``, ``vision-ctc``,
``leg-edge-ctc``, ``leg-direction-ctc``, a plugin feature's ``<name>-ctc``) as arrays.

:class:`TaskRows` (built at the first batched step after a reset) owns its trials' state:
the input matrix ``X`` (n, n_in) with each row's constants and pose guess, the guess
flags, command counts, reference clocks, force limits, integrals and the references on
the control grid (n, S, w) with the steps whose task rows are all known. Each instance's
state is views of these arrays, so its per-trial step (which refuses with the reason)
and the batch share it.

One batched step (:meth:`TaskRows.step`): readings, features (the law's
``batch_inputs``) and references written by fancy indexing, one C call
(:func:`~controllers.ctc_rows.evaluate_rows`), the rows screened at once
(:func:`~controllers.ctc_rows.accepted_rows`), the results written as slices; Python per
row only for rare rows (a feature hidden, an instant off the grid, a grid built, forces
over a limit).
"""

from __future__ import annotations

import contextlib
import math
from typing import TYPE_CHECKING, Any

import numpy as np

from controllers.ctc_rows import FK_MAX_CALLS, accepted_rows, evaluate_rows, norms, over_limits
from controllers.data import CommandBatch, ObservationBatch

if TYPE_CHECKING:
    from controllers.task_ctc import TaskComputedTorque
    from controllers.task_ctc_compiled import CompiledTaskStep

#: Trials whose new reference grids are built together (their arrays stay in the
#: caches).
GRID_CHUNK = 8
#: The columns of a trial's reference clock (3,): started (1.0 or 0.0), the observation
#: time at which the reference's clock is 0 [s], and the reference's version (counts
#: its changes: a grid built for an older version is built again).
STARTED, START, VERSION = 0, 1, 2


def grid_steps(tr: np.ndarray, dt: np.ndarray) -> np.ndarray:
    """The steps ``k`` (m,) int of the control grid at ``tr`` (m,) [s] (``tr = k dt``
    within 1 ns, ``dt`` (m,) [s]), or -1 off the grid (the per-trial test of
    :func:`controllers.task_ctc.grid_step`, element by element: the same numbers)."""
    k = np.round(tr / dt)
    on = (np.abs(tr - k * dt) < 1e-9) & (k >= 0)
    return np.where(on, k, -1).astype(int)  # type: ignore[no-any-return]


class TaskRows:
    """The arrays of a batch of task computed-torque trials (see the module docstring);
    each instance's state becomes views of them.

    Args:
        laws: The trials' instances (reset), in trial order; those without a compiled
            step are left to their own steps.
    """

    def __init__(self, laws: list[TaskComputedTorque]) -> None:
        self.laws = laws
        n = len(laws)
        self.usable = np.array([law.compiled is not None and law.model is not None
                                for law in laws], dtype=bool)
        steps: list[CompiledTaskStep] = [law.compiled for law in laws if law.compiled]
        self.step_of = steps[0] if steps else None
        width = 0 if self.step_of is None else self.step_of.function.n_in
        self.X = np.zeros((n, width))
        self.guessed = np.zeros(n)
        self.steps = np.zeros(n, dtype=np.int64)
        self.clock = np.stack([law.clock for law in laws])
        self.limit = np.stack([law.force_limit for law in laws])
        self.dt = np.array([float(law.context.dt) if law.context is not None else 1.0
                            for law in laws])
        #: Rows without integral action, and each trial's ``int e dt`` of its task rows.
        self.plain = np.array([not law.integral_gain for law in laws], dtype=bool)
        size = 0 if self.step_of is None else len(range(width)[
            self.step_of.inputs["integral"]])
        self.integral = np.zeros((n, size))
        for k, law in enumerate(laws):
            law.clock = self.clock[k]
            step = law.compiled
            if step is None or not self.usable[k]:
                continue
            self.X[k] = step.row
            self.guessed[k] = step.guessed[0]
            self.steps[k] = step.steps[0]
            step.adopt(self.X[k], self.guessed[k:k + 1], self.steps[k:k + 1])
            if law.integral.shape == (size,):
                self.integral[k] = law.integral
            law.integral = self.integral[k]
        #: The references on the control grid (n, S, w), the grid steps with every task
        #: row known (n, S), each trial's grid length (0: none) and the version built.
        self.grids = np.zeros((n, 1, 0))
        self.known = np.zeros((n, 1), dtype=bool)
        self.grid_len = np.zeros(n, dtype=int)
        self.built = np.full(n, -1.0)

    def references(self, trials: np.ndarray, tr: np.ndarray) -> tuple[np.ndarray,
                                                                       np.ndarray,
                                                                       np.ndarray]:
        """The reference rows (m, w) of the trials ``trials`` (m,) at ``tr`` (m,) [s]
        on their clocks read from their grids (built for a new reference), the (m,)
        mask of the rows read (on the grid, every task row known) and their (m,) steps
        on their grids (-1: off the grid; the rows there are read, known or not)."""
        stale = self.built[trials] != self.clock[trials, VERSION]
        if stale.any():  # once per reference, GRID_CHUNK trials together
            new = np.unique(trials[stale]).tolist()
            for start in range(0, len(new), GRID_CHUNK):
                chunk = new[start:start + GRID_CHUNK]
                with contextlib.suppress(Exception):  # each trial's _build meets it again
                    self.laws[chunk[0]].build_grids([self.laws[k] for k in chunk])
                for k in chunk:
                    self._build(k)
        k = grid_steps(tr, self.dt[trials])
        length = self.grid_len[trials]
        ok = (k >= 0) & (length > 0)
        steps = np.where(ok, np.minimum(k, length - 1), -1)
        at = np.maximum(steps, 0) + self.grids.shape[1] * trials  # the grids one by one
        ok &= self.known.reshape(-1).take(at)
        n, size, width = self.grids.shape
        return self.grids.reshape(n * size, width).take(at, axis=0), ok, steps

    def _build(self, k: int) -> None:
        """Stack trial ``k``'s reference grid (the law's ``batch_grid``: none when it
        raises; its own step then meets the failure)."""
        law = self.laws[k]
        self.built[k] = law.clock[VERSION]
        try:
            grid = law.batch_grid()
        except Exception:  # the trial's own compiled_inputs meets it again
            grid = None
        if grid is None:
            self.grid_len[k] = 0
            return
        rows, known = grid
        size, width = rows.shape
        if size > self.grids.shape[1] or width != self.grids.shape[2]:
            grown = np.zeros((len(self.laws), max(size, self.grids.shape[1]), width))
            grown_known = np.zeros(grown.shape[:2], dtype=bool)
            if width == self.grids.shape[2]:
                grown[:, :self.grids.shape[1]] = self.grids
                grown_known[:, :self.known.shape[1]] = self.known
                for j in np.flatnonzero(self.grid_len).tolist():  # views of the new array
                    self.laws[j].share_grid(grown[j, :self.grid_len[j]])
            self.grids, self.known = grown, grown_known
        self.grids[k, :size] = rows
        self.known[k, :size] = True if known is None else known
        self.grid_len[k] = size
        law.share_grid(self.grids[k, :size])

    def step(self, observations: ObservationBatch, out: CommandBatch, threshold: float
             ) -> np.ndarray:
        """Step every row of a started trial with finite readings into ``out``; returns
        the rows left to the trials' own steps.

        Args:
            observations: The batch (row ``k`` of trial ``observations.trials[k]``).
            out: The commands, written in place.
            threshold: The rank test's relative singular-value threshold.
        """
        n = len(observations)
        first = self.step_of
        if observations.q_dot is None or first is None:
            return np.arange(n)
        t = np.asarray(observations.t, dtype=float)
        q_all = np.asarray(observations.lengths, dtype=float)
        qd_all = np.asarray(observations.q_dot, dtype=float)
        trials_all = np.asarray(observations.trials, dtype=int)
        finite = self.usable[trials_all] & (self.clock[trials_all, STARTED] != 0.0)
        if not (np.isfinite(t).all() and np.isfinite(q_all).all()
                and np.isfinite(qd_all).all()):  # off the common case: row by row
            finite &= (np.isfinite(t) & np.isfinite(q_all).all(axis=1)
                       & np.isfinite(qd_all).all(axis=1))
        rows = np.flatnonzero(finite)
        if not len(rows):
            return np.arange(n)
        trials = trials_all[rows]
        inputs, outputs = first.inputs, first.outputs
        X = self.X[trials]
        X[:, inputs["q"]] = q_all[rows]
        X[:, inputs["q_dot"]] = qd_all[rows]
        tr = t[rows] - self.clock[trials, START]
        law0: Any = self.laws[int(trials[0])]
        #: The task rows used of a batch row (its index in ``rows``), where not all.
        self.used: dict[int, np.ndarray] = {}
        fast = law0.batch_inputs(self, X, observations, rows, trials, tr)
        keep = np.ones(len(rows), dtype=bool)
        used = self.used
        for j in np.flatnonzero(~fast).tolist():  # each by its law, off the common case
            k = int(rows[j])
            law = self.laws[int(trials[j])]
            step = law.compiled
            assert step is not None
            views = step.views or step.bind()
            views["q"][:] = q_all[k]
            views["q_dot"][:] = qd_all[k]
            try:
                prepared = step.prepare(law, observations.item(k), float(tr[j]))
            except Exception:  # the trial's own step refuses with the reason
                prepared = "failed"
            if isinstance(prepared, str):
                keep[j] = False
                continue
            X[j] = step.row
            if prepared[0] is not None:
                used[j] = prepared[0]
        gain = fast & ~self.plain[trials]  # the integral action of the rows written here
        if gain.any():
            kp_ki = law0.gains.kp * law0.integral_gain
            X[gain, inputs["integral"]] = kp_ki * self.integral[trials[gain]]
        if not keep.all():
            if used:
                index = np.cumsum(keep) - 1
                used = {int(index[j]): u for j, u in used.items()}
            rows, trials, X = rows[keep], trials[keep], X[keep]
        if not len(rows):
            return np.arange(n)
        Y, _ = evaluate_rows(first.function, X, inputs["pose"], outputs["pose"],
                             outputs.index("fk_residual"), first.tolerance, FK_MAX_CALLS)
        a = np.flatnonzero(accepted_rows(Y, outputs.index("status"), outputs["screen"],
                                         outputs["factor"], threshold))
        if not len(a):
            return np.arange(n)
        if len(a) == len(rows):  # the common case: every row accepted (no copies)
            ka, ta, Ya = rows, trials, Y
        else:
            ka, ta, Ya = rows[a], trials[a], Y[a]
        F, P, E = Ya[:, outputs["forces"]], Ya[:, outputs["pose"]], Ya[:, outputs["error"]]
        self.X[ta, inputs["pose"]] = P  # the next steps' guesses
        self.guessed[ta] = 1.0
        self.steps[ta] += 1
        assert out.forces is not None
        out.forces[ka] = F
        out.error_norm[ka] = np.sqrt(norms(E))
        over = over_limits(F, self.limit[ta])
        used_a: dict[int, np.ndarray] = {}
        if used:  # the accepted row of a row (``a`` is sorted)
            at = np.searchsorted(a, np.fromiter(used, dtype=int, count=len(used))).tolist()
            used_a = {i: u for i, (j, u) in zip(at, used.items(), strict=True)
                      if i < len(a) and a[i] == j}
        self._integrate(ta, E, over, used_a)
        for i in np.flatnonzero(over).tolist():  # over a limit: the law's strategy
            out.forces[ka[i]] = self.laws[int(ta[i])].limited(
                F[i], P[i], qd_all[ka[i]], E[i], used.get(int(a[i])), True)
        for i, u in used_a.items():  # the norms of the rows used
            e = E[i][u]
            out.error_norm[ka[i]] = math.sqrt(e.dot(e))
        if len(ka) == n:
            return np.zeros(0, dtype=np.int64)
        slow = np.ones(n, dtype=bool)
        slow[ka] = False
        return np.flatnonzero(slow)

    def _integrate(self, ta: np.ndarray, E: np.ndarray, over: np.ndarray,
                   used: dict[int, np.ndarray]) -> None:
        """Advance ``int e dt`` of the trials ``ta`` with integral action by their task
        errors ``E`` (m, k) over the rows ``used``, held where a force is ``over`` its
        limit (as the law's ``limited``: the same numbers)."""
        go = np.flatnonzero(~self.plain[ta] & ~over)
        if not len(go):
            return
        step = np.where(np.isfinite(E[go]), E[go], 0.0) * self.dt[ta[go]][:, None]
        for r, i in enumerate(go.tolist()):
            u = used.get(i)
            if u is not None:
                step[r] = np.where(u, step[r], 0.0)
        self.integral[ta[go]] += step


__all__ = ["GRID_CHUNK", "START", "STARTED", "VERSION", "TaskRows", "grid_steps"]
