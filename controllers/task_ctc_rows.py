"""The one step of the task computed-torque laws (``cartesian-ctc``, ``vision-ctc``,
``leg-edge-ctc``, ``leg-direction-ctc``, a plugin feature's ``<name>-ctc``) over a batch
of trials (a batch of one is the per-trial step).

:class:`TaskRows` (built at the first step after a reset) owns its trials' state: the
input matrix ``X`` (n, n_in) with each row's constants and pose guess, the guess flags,
command counts, reference clocks, force limits and integrals (each instance's state is
views of these arrays), and the addresses of each law's reference on its control grid
(S, w) and of the grid steps whose task rows are all known (the law's own arrays, read
in place).

One step (:meth:`TaskRows.step`) is C (:mod:`controllers.task_ctc_c`, compiled once and
cached as the kernels are) around the compiled step of
:mod:`controllers.solvers.compiled_task_ctc`:

- ``prepare``: each row's time, lengths and leg velocities (a value not finite: a
  refusal), the law's measurement where all of it is seen and finite (its
  ``batch_measurement``), its clock (a fixed goal's first step, a grid to build:
  Python), the reference on its grid, and the integral term;
- ``evaluate``: the compiled step of each row, called again from the pose reached while
  the pose has not converged (from :data:`~hexapod.compiled.LANE_ROWS` rows, in lanes
  between the two C passes: the same numbers);
- ``finish``: the rows with status 0 whose rank screen clears them: the next pose guess,
  the command count, the forces and the anti-windup integral over the task rows used.

Python takes the rare rows: a fixed goal's first step (the line from the pose found),
a reference's new grid, a feature hidden or a reference off its grid (the law's own
``compiled_inputs``, written into the trial's row), a rank the screen does not settle
(LAPACK), forces over a limit (the law's saturation) and the refusals' reasons.
"""

from __future__ import annotations

import contextlib
import ctypes
import math
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy.linalg.lapack import dsyevd as _eigenvalues

from controllers.base import Command
from controllers.control_grid import chunks, model_world
from controllers.ctc_rows import FK_MAX_CALLS, evaluate_rows, norms, rank_condition
from controllers.data import CommandBatch, ObservationBatch
from controllers.plausible import reading_bounds, stroke_of
from controllers.task_ctc_c import (
    ACCEPT,
    ACCEPTED,
    CODES,
    FIRST,
    OFF_GRID,
    OVER,
    READY,
    REFUSED,
    STALE,
    UNKNOWN,
    UNSEEN,
    UNSURE,
    Call,
    Context,
    library,
)
from controllers.task_ctc_inputs import line_to
from controllers.task_ctc_refusals import parallel_singular, row_reason, step_refusal, unusable
from hexapod.actuation import Actuation
from hexapod.c_step import KernelCall, RowArrays
from hexapod.compiled import LANE_ROWS, CompilationError

if TYPE_CHECKING:
    from controllers.task_ctc import TaskComputedTorque
    from controllers.task_ctc_compiled import CompiledTaskStep

#: The columns of a trial's reference clock (3,): started (1.0 or 0.0), the observation
#: time at which the reference's clock is 0 [s], and the reference's version (counts
#: its changes: a grid built for an older version is built again).
STARTED, START, VERSION = 0, 1, 2
#: Six zeros (the velocities of a force command), copied.
_ZEROS = np.zeros(6)
#: The codes left to :meth:`TaskRows._rare` after the first C call.
_PENDING = frozenset((OFF_GRID, UNSURE, READY, FIRST, STALE, UNKNOWN, UNSEEN))
#: Whether a code (its index) is pending.
_IS_PENDING = np.isin(np.arange(len(CODES)), sorted(_PENDING))

class TaskRows:
    """The arrays of a batch of task computed-torque trials and its one step (see the
    module docstring); each instance's state becomes views of them.

    Args:
        laws: The trials' instances (reset), in trial order; those without a compiled
            step are refused.
    """

    def __init__(self, laws: list[TaskComputedTorque]) -> None:
        self.laws = laws
        n = len(laws)
        self.usable = np.array([law.compiled is not None and law.model is not None
                                for law in laws], dtype=np.uint8)
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
        self.plain = np.array([not law.integral_gain for law in laws], dtype=np.uint8)
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
        #: Each trial's reference on its control grid (S, w) and the grid steps with
        #: every task row known (S,) (the laws' own arrays, read in place by the C
        #: through their addresses), each grid's length (0: none) and the version built.
        self.held: list[tuple[np.ndarray, np.ndarray] | None] = [None] * n
        self.grids = np.zeros(n, dtype=np.uintp)
        self.known = np.zeros(n, dtype=np.uintp)
        self.grid_len = np.zeros(n, dtype=np.int64)
        self.built = np.full(n, -1.0)
        law0 = laws[0] if laws else None
        self.kp_ki = (law0.gains.kp * law0.integral_gain
                      if law0 is not None and law0.integral_gain else 0.0)
        #: The rank test's relative singular-value threshold (the laws' solver's; its
        #: screen's scale set in C).
        self.threshold = law0.solver.threshold if law0 is not None else math.nan
        self._last: RowArrays | None = None
        self.context: ctypes.Structure | None = None
        if self.step_of is not None:
            self._bind(self.step_of)

    def _bind(self, step: CompiledTaskStep) -> None:
        """The C context of the arrays and of the compiled step (its work arrays)."""
        function = step.function
        self._kernel = KernelCall.of(function)
        ins, outs = step.inputs, step.outputs
        self.function_name = function.name
        #: The output blocks the step reads (the error, the pose, ``L^T L``, the residual).
        self._error, self._pose, self._factor = outs["error"], outs["pose"], outs["factor"]
        self._residual = outs.index("fk_residual")
        ref = ins["reference_features"] if "reference_features" in ins else ins["reference"]
        mask = ins["mask"] if "mask" in ins else slice(0, 0)
        self.context = Context(
            0, function.n_in, ins["q"].start, ins["q_dot"].start, ref.start,
            ref.stop - ref.start, mask.start, mask.stop - mask.start, ins["integral"].start,
            self.integral.shape[1], ins["pose"].start, 0, 0, 0, 0, 0, 0, 0, 0, self.kp_ki,
            0, 0, 0, 0, self._kernel, function.n_out, outs["pose"].start, outs.index("fk_residual"),
            outs.index("status"), outs["screen"].start, outs["forces"].start,
            outs["error"].start, step.tolerance, FK_MAX_CALLS, 4.0 * self.threshold**2)
        self.context.q_lo, self.context.q_hi = reading_bounds(  # type: ignore[attr-defined]
            stroke_of(law.context) for law in self.laws)
        law0 = self.laws[0]
        measurement = law0.batch_measurement
        #: The observation's measured field and its visibility (None: nothing measured).
        self.measured: tuple[str, str] | None = None
        c = self.context
        if measurement:
            field, visibility, into, ones = measurement
            self.measured = (field, visibility)
            c.measured, c.feat_at = 1, ins[into].start
            c.feat_w = ins[into].stop - ins[into].start
            c.vis_w = c.feat_w // 3  # one flag per unit vector (leg or edge)
            if ones is not None:
                c.ones_at, c.ones_w = ins[ones].start, ins[ones].stop - ins[ones].start
        #: Whether the rows' measurement is the law's own (every row by its inputs).
        self.own_inputs = measurement is None
        self._addresses()

    def _addresses(self) -> None:
        """The arrays' addresses in the C context."""
        c = self.context
        assert c is not None
        for name in ("X", "usable", "plain", "clock", "built", "dt", "grid_len", "grids",
                     "known", "integral", "guessed", "steps", "limit"):
            setattr(c, name, getattr(self, name).ctypes.data)
        self._ctx = ctypes.addressof(c)

    def _buffers(self, n: int) -> RowArrays:
        """The step's arrays for ``n`` rows (the last step's when it had as many) and
        their C ``TaskCall``: a measurement of ``feat_w`` values and ``vis_w`` flags."""
        b = self._last
        if b is None or b.n != n:
            assert self.step_of is not None and self.context is not None
            c = self.context
            b = self._last = RowArrays(n, {
                "X": ((self.X.shape[1],), float), "trials": ((), np.int64),
                "t": ((), float), "q": ((6,), float), "qd": ((6,), float),
                "code": ((), np.int64), "tr": ((), float), "gstep": ((), np.int64),
                "feat": ((c.feat_w,), float), "vis": ((c.vis_w,), np.uint8),
                "seen": ((), np.uint8), "Y": ((self.step_of.function.n_out,), float),
                "forces": ((6,), float)}, Call, n)
        return b

    # ---------------------------------------------------------------- grids
    def _build_stale(self, trials: np.ndarray) -> None:
        """Build the grids of ``trials`` whose reference changed, a chunk of trials of one
        model world together (:func:`controllers.control_grid.chunks`)."""
        new = np.unique(trials[self.built[trials] != self.clock[trials, VERSION]]).tolist()
        worlds = [None if (c := self.laws[k].context) is None else model_world(c) for k in new]
        for members in chunks(worlds):
            chunk = [new[m] for m in members]
            with contextlib.suppress(Exception):  # each trial's _build meets it again
                self.laws[chunk[0]].build_grids([self.laws[k] for k in chunk])
            for k in chunk:
                self._build(k)

    def _build(self, k: int) -> None:
        """Hold trial ``k``'s reference grid (the law's ``batch_grid``: none when it
        raises; its own inputs then meet the failure)."""
        law = self.laws[k]
        self.built[k] = law.clock[VERSION]
        try:
            grid = law.batch_grid()
        except Exception:  # the trial's own compiled_inputs meets it again
            grid = None
        if grid is None:
            self.grid_len[k] = 0
            self.held[k] = None
            return
        rows, known = grid
        assert self.context is not None
        if rows.ndim != 2 or rows.shape[1] != self.context.ref_w:
            raise ValueError(f"{law.name}: a reference grid of shape {rows.shape}, expected "
                             f"(steps, {self.context.ref_w})")
        rows = np.ascontiguousarray(rows, dtype=float)
        known = (np.ones(len(rows), dtype=np.uint8) if known is None
                 else np.ascontiguousarray(known, dtype=np.uint8))
        self.held[k] = (rows, known)  # (alive while the C reads them)
        self.grids[k], self.known[k] = rows.ctypes.data, known.ctypes.data
        self.grid_len[k] = len(rows)

    # ---------------------------------------------------------------- the step
    def step(self, observations: ObservationBatch, out: CommandBatch) -> None:
        """Every row's command into ``out`` (a refusal with its reason where there is
        none); a batch of one gets the full :class:`Command` (the diagnostics of a
        per-trial step: error, rank, condition number and notes).

        Args:
            observations: The batch (row ``k`` of trial ``observations.trials[k]``).
            out: The commands, written in place.

        Raises:
            CompilationError: The compiled step failed.
        """
        n = len(observations)
        c = self.context
        if c is None or observations.q_dot is None:
            for j in range(n):
                self._refuse(out, j, unusable(observations, j))
            return
        lib = library()
        threshold = self.threshold
        b = self._buffers(n)
        observations.write_rows(b)
        if self.measured is not None:
            field, visibility = self.measured
            values = getattr(observations, field)
            if values is None:  # not measured: every row by its law (which says so)
                b.vis[:] = 0
            else:
                b.feat.reshape(values.shape)[...] = values
                visible = getattr(observations, visibility)
                b.vis.reshape(visible.shape)[...] = visible
        code = b.code
        if n < LANE_ROWS:  # a few rows: one C call
            if lib.tc_step_call(self._ctx, b.at):
                raise CompilationError(f"{self.function_name}: the compiled function failed")
        else:
            lib.tc_prepare_call(self._ctx, b.at)
        if n == 1:
            if int(code[0]) in _PENDING:
                used: dict[int, np.ndarray] = {}
                notes: dict[int, str] = {}
                reasons = self._rare(observations, b, used, notes, threshold)
                self._one(observations, out, b, used.get(0), notes.get(0), reasons.get(0))
            else:  # the common case
                self._one(observations, out, b, None, None, None)
            return
        pending = bool(_IS_PENDING[code].any())
        used = {}
        notes = {}
        reasons = self._rare(observations, b, used, notes, threshold) if pending else {}
        forces = out.forces
        assert forces is not None
        forces[...] = b.forces
        E = b.Y[:, self._error]
        if not used and (code == ACCEPTED).all():  # the common case
            out.error_norm[:] = np.sqrt(norms(E))
            return
        over = np.flatnonzero(code == OVER)
        if len(over):  # (forces over a limit: at a parallel singularity, no command)
            singular = parallel_singular(self.laws, b, over, self._pose, threshold)
            for j, why in singular.items():
                code[j], reasons[j] = REFUSED, why
        accepted = (code == ACCEPTED) | (code == OVER)
        out.error_norm[accepted] = np.sqrt(norms(E[accepted]))
        for j, u in used.items():  # the norms of the rows used
            if accepted[j]:
                e = E[j][u]
                out.error_norm[j] = math.sqrt(e.dot(e))
        for j in np.flatnonzero(code == OVER).tolist():  # over a limit: the law's strategy
            forces[j] = self._limited(b, j, forces[j], used.get(j))
        for j in np.flatnonzero(~accepted).tolist():  # refused: zeros and the reason
            self._refuse(out, j, reasons.get(j)
                         or row_reason(self.laws, observations, b, j, threshold))

    def _one(self, observations: ObservationBatch, out: CommandBatch, b: RowArrays,
             used: np.ndarray | None, note: str | None, reason: str | None) -> None:
        """A batch of one's row as the per-trial step's :class:`Command`."""
        code = b.code[0]
        if code == OVER and (singular := parallel_singular(
                self.laws, b, np.zeros(1, dtype=int), self._pose, self.threshold)):
            code, reason = REFUSED, singular[0]
        if code != ACCEPTED and code != OVER:
            self._refuse(out, 0, reason
                         or row_reason(self.laws, observations, b, 0, self.threshold))
            return
        y = b.Y[0]
        forces = b.forces[0].copy()
        if code == OVER:
            forces = self._limited(b, 0, forces, used)
        e = y[self._error]
        e = e.copy() if used is None else e[used]
        w = _eigenvalues(y[self._factor].reshape(6, 6), 0)[0]  # (compute_v=0)
        cmd = Command(_ZEROS.copy(), error=e, error_norm=math.sqrt(e.dot(e)), rank=6,
                      condition=math.sqrt(float(w[5]) / float(w[0])), features_used=len(e),
                      active_constraints=[], notes=[] if note is None else [note],
                      actuation=Actuation.FORCE, forces=forces)
        out.forces[0] = forces  # type: ignore[index]
        out.error_norm[0] = cmd.error_norm
        out.commands = [cmd]

    def _limited(self, b: RowArrays, j: int, forces: np.ndarray, used: np.ndarray | None
                 ) -> np.ndarray:
        """Row ``j``'s forces [N] over a limit under its law's strategy."""
        law = self.laws[int(b.trials[j])]
        return law.limited(forces, b.Y[j, self._pose], b.qd[j], b.Y[j, self._error], used,
                           True)

    def _rare(self, observations: ObservationBatch, b: RowArrays, used: dict[int, np.ndarray],
              notes: dict[int, str], threshold: float) -> dict[int, str]:
        """Prepare the rows the C did not (module docstring), then evaluate and finish
        every prepared row; the reasons of the rows refused on the way."""
        lib = library()
        code, X = b.code, b.X
        n = len(code)
        step0 = self.step_of
        assert step0 is not None
        reasons: dict[int, str] = {}
        first = np.flatnonzero(code == FIRST)
        for j in first.tolist():  # a fixed goal's first step: its line from the pose
            problem = self._start(observations, b, j)
            if problem is not None:
                reasons[j] = problem
        again = (code == STALE) | (code == FIRST)
        if again.any():  # new references: their grids, then those rows again
            self._build_stale(b.trials[again])
            lib.tc_prepare_call(self._ctx, b.at)  # (the trials' rows again: a pose found)
            for j in reasons:
                code[j] = REFUSED
        seen = b.seen.astype(bool)
        law0: Any = self.laws[int(b.trials[0])]
        candidates = ((code == UNSEEN) | (code == UNKNOWN)) & ~seen
        if candidates.any() and not self.own_inputs:  # partly seen, as arrays if it can
            for j, (u, note) in law0.batch_partly_seen(self, step0, X, observations,
                                                       candidates).items():
                seen[j] = True
                code[j] = READY if code[j] == UNSEEN else UNKNOWN
                if u is not None:
                    X[j, step0.inputs["mask"]] = u
                    used[j] = u
                if note is not None:
                    notes[j] = note
        for j in np.flatnonzero((code == UNKNOWN) & seen).tolist():  # reference rows
            law: Any = self.laws[int(b.trials[j])]  # not known: left out (feature laws)
            known = law.reference_grid()[2][b.gstep[j]]
            used[j] = used[j] & known if j in used else known.copy()
            X[j, step0.inputs["mask"]] = used[j]
            code[j] = READY
        own = (code == UNSEEN) | (code == UNKNOWN) | (code == OFF_GRID)
        if self.own_inputs:
            own |= code == READY
        for j in np.flatnonzero(own).tolist():
            problem = self._own_inputs(observations, b, j, used, notes)
            if problem is not None:
                reasons[j] = problem
                code[j] = REFUSED
            else:
                code[j] = READY
        ready = np.flatnonzero(code == READY)
        if len(ready) >= LANE_ROWS:  # the compiled step in lanes
            rows = slice(None) if len(ready) == n else ready
            b.Y[rows] = evaluate_rows(step0.function, X[rows], step0.inputs["pose"],
                                      self._pose, self._residual, step0.tolerance,
                                      FK_MAX_CALLS)[0]
        elif len(ready) and lib.tc_evaluate_call(self._ctx, b.at):
            raise CompilationError(f"{self.function_name}: the compiled function failed")
        lib.tc_finish_call(self._ctx, b.at)
        unsure = np.flatnonzero(code == UNSURE)
        if len(unsure):  # the exact rank test (LAPACK) where the screen does not settle it
            for j in unsure.tolist():
                full = rank_condition(b.Y[j, self._factor], threshold) is not None
                code[j] = ACCEPT if full else REFUSED
            lib.tc_finish_call(self._ctx, b.at)
        return reasons

    def _start(self, observations: ObservationBatch, b: RowArrays, j: int) -> str | None:
        """A fixed goal's first step for row ``j`` (the law's ``start``: with a smooth
        goal, the line from the pose of a compiled step towards the goal at rest); None,
        or why there is no pose."""
        i = int(b.trials[j])
        law = self.laws[i]
        step = law.compiled
        assert step is not None
        try:
            if law.smooth_goal:
                prepared = self._inputs(law, observations, b, j, 0.0)
                if isinstance(prepared, str):
                    return prepared
                x = step.row.copy()
                y = evaluate_rows(step.function, x[None], step.inputs["pose"],
                                  step.outputs["pose"], step.outputs.index("fk_residual"),
                                  step.tolerance, FK_MAX_CALLS)[0][0]
                found = None
                if y[step.outputs.index("status")] == 0.0:
                    found = rank_condition(y[step.outputs["factor"]], law.solver.threshold)
                if found is None:
                    return step_refusal(step, y, step.inputs.views(x), law.solver.threshold)
                step.row[step.inputs["pose"]] = y[step.outputs["pose"]]
                step.guessed[0] = 1.0
                assert law.context is not None and law.guess is not None
                law.reference = line_to(law.context, *law.guess, *law.goal_pose())
            law.clock[STARTED], law.clock[START] = 1.0, float(b.t[j])
        except Exception as exc:  # the nominal model failed here: refuse with its reason
            return f"nominal model failed: {exc}"
        return None

    def _inputs(self, law: TaskComputedTorque, observations: ObservationBatch, b: RowArrays,
                j: int, tr: float) -> tuple[np.ndarray | None, str | None] | str:
        """The law's own inputs of row ``j`` at ``tr`` [s] written into its trial's row
        (its readings there first): the rows used and a note, or why there are none."""
        step = law.compiled
        assert step is not None
        step.views["q"][:] = b.q[j]
        step.views["q_dot"][:] = b.qd[j]
        return step.prepare(law, observations.item(j), tr)  # type: ignore[no-any-return]

    def _own_inputs(self, observations: ObservationBatch, b: RowArrays, j: int,
                    used: dict[int, np.ndarray], notes: dict[int, str]) -> str | None:
        """Row ``j`` prepared by its law (a feature hidden, a reference off its grid) and
        copied into the step's rows; None, or why it has no inputs."""
        law = self.laws[int(b.trials[j])]
        try:
            prepared = self._inputs(law, observations, b, j, float(b.tr[j]))
        except Exception as exc:  # the nominal model failed here
            return f"nominal model failed: {exc}"
        if isinstance(prepared, str):
            return prepared
        assert law.compiled is not None
        b.X[j] = law.compiled.row
        if prepared[0] is not None:
            used[j] = prepared[0]
        if prepared[1] is not None:
            notes[j] = prepared[1]
        return None

    def _refuse(self, out: CommandBatch, j: int, reason: str) -> None:
        name = self.laws[0].name if self.laws else "controller"
        out.put(j, Command.refuse(f"{name}: {reason}", actuation=Actuation.FORCE))


__all__ = ["START", "STARTED", "VERSION", "TaskRows"]
