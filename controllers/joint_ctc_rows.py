"""The one step of the joint-space computed torque (``computed-torque``) over a batch of
trials (a batch of one is the per-trial ``step``).

:class:`JointRows` (built by the controller's reset) owns its trials' state: the input
matrix ``X`` (n, n_in) with each row's constants and pose guess, the leg integrals, the
fixed goals' quintics, the command counts, the force limits and the reference's legs on
the control grid (one grid when they are equal). Each instance's state is views of these
arrays.

One step (:meth:`JointRows.step`) is C (:data:`SOURCE`, compiled once and cached as the
kernels are) around the compiled step of :mod:`controllers.solvers.compiled_ctc`:

- ``prepare``: each row's time, lengths and leg velocities (a row with a value not
  finite is refused), the desired legs (the reference on its grid, at rest after its
  end, or the fixed goal's leg-space quintic, started from the lengths of the first
  step) plus the integral term, written into the trial's input row;
- ``evaluate``: the compiled step of each row, called again from the pose reached while
  the pose has not converged (a batch of :data:`~hexapod.compiled.LANE_ROWS` rows or
  more is evaluated in lanes instead, :func:`~controllers.ctc_rows.evaluate_rows`: the
  same numbers);
- ``finish``: the rows with status 0 whose rank screen (``det`` and ``trace`` of ``L^T
  L``) clears them: the next pose guess, the command count, the forces, the leg error
  and the anti-windup integral (held while a leg's force is over its limit).

Python takes the rare rows: an instant off the control grid (the reference evaluated on
demand), a rank the screen does not settle (LAPACK, :func:`~controllers.ctc_rows.
rank_condition`), forces over a limit (the saturation strategy) and the refusals'
reasons (the kernel's status, :func:`~controllers.ctc_rows.refusal`). The quintic's
arithmetic is Python's (``pow`` of the C library, no fused multiply-add), so its numbers
are those of the Python expressions it replaced, to the last bit.
"""

from __future__ import annotations

import ctypes
import math
from functools import lru_cache
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from controllers.base import Command
from controllers.control_grid import GRID_TOLERANCE
from controllers.ctc_rows import (
    FK_MAX_CALLS,
    NEWTON_CALLS_C,
    evaluate_rows,
    norms,
    rank_condition,
    refusal,
)
from controllers.data import CommandBatch, ObservationBatch
from controllers.plausible import reading_bounds, stroke_of
from controllers.solvers import compiled_ctc
from controllers.task_ctc_inputs import QUINTIC_PEAK_SPEED, encoder_readings
from hexapod.actuation import Actuation
from hexapod.c_step import KernelCall, RowArrays, c_library, c_struct
from hexapod.compiled import LANE_ROWS, CompilationError

if TYPE_CHECKING:
    from controllers.computed_torque import ComputedTorqueController
    from hexapod.compiled import CompiledFunction

#: Where the compiled step's blocks lie in its rows (:data:`compiled_ctc.INPUTS`,
#: :data:`compiled_ctc.OUTPUTS`), looked up once.
DESIRED, POSE_IN = compiled_ctc.INPUTS["desired"], compiled_ctc.INPUTS["pose"]
POSE_OUT, FACTOR, FORCES = (compiled_ctc.OUTPUTS[k] for k in ("pose", "factor", "forces"))
RESIDUAL, STATUS = (compiled_ctc.OUTPUTS.index(k) for k in ("fk_residual", "status"))
#: The columns of a quintic's row (21,): started (1.0 or 0.0), ``t0`` [s], duration
#: ``T`` [s], ``q0`` (6) [m], ``q* - q0`` (6) [m], ``q*`` (6) [m].
QUINTIC_SIZE = 21
#: A row's code after a step, in order (the C ``enum`` is made of these names): a command
#: (over a limit or not), or why not yet or not.
CODES = ("ACCEPTED", "OVER", "NOT_FINITE", "OFF_GRID", "REFUSED", "UNSURE", "READY", "ACCEPT")
ACCEPTED, OVER, NOT_FINITE, OFF_GRID, REFUSED, UNSURE, READY, ACCEPT = range(len(CODES))

#: The C of a step (see the module docstring); ``JointCtc`` is :class:`_Context`.
SOURCE = NEWTON_CALLS_C + r"""
typedef struct {
    double *X; int64_t n_in, q_at, qd_at, desired_at, pose_in;
    const uint8_t *tracking; const double *dt, *t_end; const int64_t *grid_len;
    const double *grids; int64_t grid_stride;
    double *quintic; const double *quintic_speed; double peak, kp_ki;
    double *integral; double grid_tol; int64_t *steps; const double *limit;
    KernelCall kernel;
    int64_t n_out, pose_out, residual_at, status_at, screen_at, forces_at;
    double fk_tol; int64_t max_calls; double screen_scale; double *scratch;
    double q_lo, q_hi;  /* the plausible readings [m] (controllers.plausible) */
} JointCtc;
enum { @CODES@ };

/* the quintic's (q*, q_dot*, q_ddot*) at t (the Python floats' operations) */
static void quintic_at(double t, const double *r, double *d) {
    double T = r[2];
    if (T <= 0.0) {
        for (int l = 0; l < 6; l++) { d[l] = r[15 + l]; d[6 + l] = 0.0; d[12 + l] = 0.0; }
        return;
    }
    double v = (t - r[1]) / T;
    double x = (0.0 > v) ? 0.0 : v;
    x = (1.0 < x) ? 1.0 : x;
    double s = pow(x, 3.0) * ((10.0 - 15.0 * x) + 6.0 * pow(x, 2.0));
    double sd = 0.0, sdd = 0.0;
    if (0.0 < x && x < 1.0) {
        sd = 30.0 * pow(x, 2.0) * pow(1.0 - x, 2.0) / T;
        sdd = 60.0 * x * (1.0 - x) * (1.0 - 2.0 * x) / pow(T, 2.0);
    }
    for (int l = 0; l < 6; l++) {
        d[l] = r[3 + l] + s * r[9 + l]; d[6 + l] = sd * r[9 + l]; d[12 + l] = sdd * r[9 + l];
    }
}

/* trial i's desired legs at t into d (18); 1: off the control grid (d not written) */
int jc_desired(const JointCtc *c, int64_t i, double t, double *d) {
    if (!c->tracking[i]) { quintic_at(t, c->quintic + 21 * i, d); return 0; }
    int64_t len = c->grid_len[i];
    double dt = c->dt[i], k = nearbyint(t / dt);
    const double *g = c->grids + 18 * (c->grid_stride * i);
    if (len > 0 && t > c->t_end[i]) g += 18 * (len - 1);
    else if (k >= 0 && k < len && fabs(t - k * dt) <= c->grid_tol) g += 18 * (int64_t)k;
    else return 1;
    memcpy(d, g, 18 * sizeof(double));
    return 0;
}

void jc_prepare(JointCtc *c, int64_t m, const int64_t *trials, const double *t,
                const double *q, const double *qd, int64_t *code) {
    for (int64_t j = 0; j < m; j++) {
        int64_t i = trials[j];
        const double *qj = q + 6 * j, *qdj = qd + 6 * j;
        int finite = isfinite(t[j]);
        for (int l = 0; l < 6; l++)
            finite &= qj[l] > c->q_lo && qj[l] < c->q_hi && isfinite(qdj[l]);
        if (!finite) { code[j] = NOT_FINITE; continue; }
        double *x = c->X + c->n_in * i, *r = c->quintic + 21 * i;
        memcpy(x + c->q_at, qj, 6 * sizeof(double));
        memcpy(x + c->qd_at, qdj, 6 * sizeof(double));
        if (!c->tracking[i] && r[0] == 0.0) {  /* a fixed goal's first step */
            double mx = 0.0, speed = c->quintic_speed[i];
            for (int l = 0; l < 6; l++) { double a = fabs(r[15 + l] - qj[l]); if (a > mx) mx = a; }
            r[0] = 1.0; r[1] = t[j]; r[2] = isnan(speed) ? 0.0 : c->peak * mx / speed;
            for (int l = 0; l < 6; l++) { r[3 + l] = qj[l]; r[9 + l] = r[15 + l] - qj[l]; }
        }
        double *d = x + c->desired_at;
        if (jc_desired(c, i, t[j], d)) { code[j] = OFF_GRID; continue; }
        if (c->kp_ki != 0.0)
            for (int l = 0; l < 6; l++) d[12 + l] += c->kp_ki * c->integral[6 * i + l];
        code[j] = READY;
    }
}

int jc_evaluate(JointCtc *c, int64_t m, const int64_t *trials, const int64_t *code,
                double *Y) {
    double *x = c->scratch;
    for (int64_t j = 0; j < m; j++) {
        if (code[j] != READY) continue;
        memcpy(x, c->X + c->n_in * trials[j], c->n_in * sizeof(double));
        if (newton_calls(&c->kernel, x, Y + c->n_out * j, c->pose_in, c->pose_out,
                         c->residual_at, c->fk_tol, c->max_calls)) return 1;
    }
    return 0;
}

void jc_finish(JointCtc *c, int64_t m, const int64_t *trials, int64_t *code,
               const double *Y, double *forces, double *errors) {
    for (int64_t j = 0; j < m; j++) {
        const double *y = Y + c->n_out * j;
        if (code[j] == READY) {
            int screen = rank_screen(y, c->status_at, c->screen_at, c->screen_scale);
            if (screen < 2) { code[j] = screen ? UNSURE : REFUSED; continue; }
        } else if (code[j] != ACCEPT) continue;
        int64_t i = trials[j];
        double *x = c->X + c->n_in * i, *e = errors + 6 * j;
        memcpy(x + c->pose_in, y + c->pose_out, 12 * sizeof(double));
        c->steps[i] += 1;
        int over = 0;
        for (int l = 0; l < 6; l++) {
            double f = y[c->forces_at + l];
            e[l] = x[c->desired_at + l] - x[c->q_at + l];
            forces[6 * j + l] = f;
            if (fabs(f) > c->limit[6 * i + l]) over = 1;
        }
        if (c->kp_ki != 0.0 && !over)  /* anti-windup: held while over a limit */
            for (int l = 0; l < 6; l++) c->integral[6 * i + l] += e[l] * c->dt[i];
        code[j] = over ? OVER : ACCEPTED;
    }
}

int jc_step(JointCtc *c, int64_t m, const int64_t *trials, const double *t, const double *q,
            const double *qd, int64_t *code, double *Y, double *forces, double *errors) {
    jc_prepare(c, m, trials, t, q, qd, code);
    if (jc_evaluate(c, m, trials, code, Y)) return 1;
    jc_finish(c, m, trials, code, Y, forces, errors);
    return 0;
}
""".replace("@CODES@", ", ".join(CODES))

#: The C ``JointCtc`` (:func:`~hexapod.c_step.c_struct`: its fields read from the C).
_Context = c_struct(SOURCE, "JointCtc")


@lru_cache(maxsize=1)
def _library() -> ctypes.CDLL:
    """The compiled :data:`SOURCE` (``-fno-builtin``: ``pow`` is the C library's, as
    Python's; ``-ffp-contract=off``: no fused multiply-add)."""
    return c_library("joint_ctc_rows", SOURCE)


class JointState(NamedTuple):
    """One trial's state as its batch takes it (its own arrays, copied into the batch's).

    Attributes:
        row: (n_in,) the compiled step's input row.
        integral: (6,) ``int (q* - q) dt`` [m s].
        quintic: (21,) the fixed goal's quintic (:data:`QUINTIC_SIZE`).
        steps: (1,) the commands of the compiled step.
        limit: (6,) the nominal force limits [N].
        dt: The control period [s].
        t_end: The time after which the reference is at rest [s] (inf: none).
        grid: (N, 18) the reference's legs on the control grid, None for a fixed goal.
        quintic_speed: The speed limit timing a fixed goal's quintic [m/s] (NaN: a step).
        function: The compiled step.
    """

    row: np.ndarray
    integral: np.ndarray
    quintic: np.ndarray
    steps: np.ndarray
    limit: np.ndarray
    dt: float
    t_end: float
    grid: np.ndarray | None
    quintic_speed: float
    function: CompiledFunction


class JointRows:
    """The arrays of a batch of computed-torque trials and its one step (see the module
    docstring); each instance's state becomes views of them.

    Args:
        laws: The trials' instances (reset), in trial order.
    """

    def __init__(self, laws: list[ComputedTorqueController]) -> None:
        self.laws = laws
        law0 = laws[0]
        states = [law.batch_state() for law in laws]
        self.function = function = states[0].function
        n = len(laws)
        self.X = np.stack([st.row for st in states])
        self.integral = np.stack([st.integral for st in states])
        self.quintic = np.stack([st.quintic for st in states])
        self.steps = np.concatenate([st.steps for st in states])
        self.limit = np.stack([st.limit for st in states])
        for k, law in enumerate(laws):
            law.adopt(self, k)
        self.dt = np.array([st.dt for st in states])
        self.t_end = np.array([st.t_end for st in states])
        self.quintic_speed = np.array([st.quintic_speed for st in states])
        self.tracking = np.array([st.grid is not None for st in states], dtype=np.uint8)
        grids = [st.grid for st in states if st.grid is not None]
        self.grid_len = np.array([0 if st.grid is None else len(st.grid) for st in states],
                                 dtype=np.int64)
        #: (1 or n, S, 18) the grids, one shared when they are equal (index 0).
        shared = bool(grids) and all(g is grids[0] or np.array_equal(g, grids[0])
                                     for g in grids)
        if shared:
            self.grids = np.ascontiguousarray(grids[0][None])
        else:
            size = max((len(g) for g in grids), default=1)
            self.grids = np.zeros((n, max(size, 1), 18))
            for k, st in enumerate(states):
                g = st.grid
                if g is not None and len(g):
                    self.grids[k, :len(g)] = g
                    self.grids[k, len(g):] = g[-1]
        self.shared = shared
        self.name = law0.name
        self.threshold = law0.solver.threshold
        self.kp_ki = law0.kp * law0.integral_gain if law0.integral_gain else 0.0
        self._last: RowArrays | None = None
        self._bind(function)

    def _bind(self, function: CompiledFunction) -> None:
        """The C context of the arrays and of the compiled step (its work arrays)."""
        self._kernel = KernelCall.of(function)
        self._scratch = np.zeros(function.n_in)
        ins, outs = compiled_ctc.INPUTS, compiled_ctc.OUTPUTS
        self.context = _Context(
            self.X.ctypes.data, function.n_in, ins["q"].start, ins["q_dot"].start,
            DESIRED.start, POSE_IN.start, self.tracking.ctypes.data, self.dt.ctypes.data,
            self.t_end.ctypes.data, self.grid_len.ctypes.data, self.grids.ctypes.data,
            0 if self.shared else self.grids.shape[1], self.quintic.ctypes.data,
            self.quintic_speed.ctypes.data, QUINTIC_PEAK_SPEED, self.kp_ki,
            self.integral.ctypes.data, GRID_TOLERANCE, self.steps.ctypes.data,
            self.limit.ctypes.data, self._kernel, function.n_out, POSE_OUT.start, RESIDUAL, STATUS,
            outs["screen"].start, FORCES.start, compiled_ctc.FK_TOLERANCE, FK_MAX_CALLS,
            4.0 * self.threshold**2, self._scratch.ctypes.data,
            *reading_bounds(stroke_of(law.context) for law in self.laws))
        self._ctx = ctypes.addressof(self.context)

    def desired(self, trial: int, t: float) -> np.ndarray:
        """``(q*, q_dot*, q_ddot*)`` (18,) of ``trial`` at ``t`` [s] as a step reads them
        (a fixed goal's quintic as it is: ``q*`` before its first step), off the control
        grid the reference itself.

        Raises:
            DynamicsError: The nominal model cannot evaluate the reference there.
        """
        out = np.empty(18)
        if _library().jc_desired(self._ctx, trial, t, out.ctypes.data):
            out[:] = self.laws[trial].reference_legs(np.array([t]))[0].ravel()
        return out

    def _buffers(self, n: int) -> RowArrays:
        """The step's arrays for ``n`` rows in the C calls' order (those of the last step
        when it had as many: their addresses taken once)."""
        b = self._last
        if b is None or b.n != n:
            b = self._last = RowArrays(n, {
                "trials": ((), np.int64), "t": ((), float), "q": ((6,), float),
                "qd": ((6,), float), "code": ((), np.int64),
                "Y": ((self.function.n_out,), float), "forces": ((6,), float),
                "errors": ((6,), float)})
        return b

    def step(self, observations: ObservationBatch, out: CommandBatch) -> None:
        """Every row's command into ``out`` (a refusal with its reason where there is
        none); a batch of one gets the full :class:`Command` (the diagnostics of a
        per-trial step: error, rank and condition number).

        Raises:
            CompilationError: The compiled step failed.
            ValueError: The observations' arrays are not of the batch's shapes.
        """
        n = len(observations)
        if observations.q_dot is None:
            for j in range(n):
                self._refuse(out, j, "needs the measured leg velocities (Observation.q_dot), "
                             "which only the dynamic world gives")
            return
        lib = _library()
        b = self._buffers(n)
        observations.write_rows(b)
        code = b.code
        if n < LANE_ROWS:
            if lib.jc_step(self._ctx, n, *b.addresses):
                raise CompilationError(f"{self.function.name}: the compiled function failed")
        else:  # the compiled step in lanes between the two C passes
            lib.jc_prepare(self._ctx, n, *b.addresses[:5])
            ready = np.flatnonzero(code == READY)
            if len(ready):
                b.Y[ready] = evaluate_rows(
                    self.function, self.X[b.trials[ready]], POSE_IN, POSE_OUT, RESIDUAL,
                    compiled_ctc.FK_TOLERANCE, FK_MAX_CALLS)[0]
            lib.jc_finish(self._ctx, n, b.addresses[0], *b.addresses[4:])
        simple = code[0] == ACCEPTED if n == 1 else bool((code == ACCEPTED).all())
        reasons = {} if simple else self._resolve(observations, b)
        forces = out.forces
        assert forces is not None
        forces[...] = b.forces
        if not simple:
            for j in np.flatnonzero(code == OVER).tolist():  # over a limit: the strategy
                i = int(b.trials[j])
                forces[j] = self.laws[i].saturated_forces(forces[j], b.Y[j, POSE_OUT], b.qd[j],
                                                          self.X[i, DESIRED][6:12])
            for j, reason in reasons.items():
                self._refuse(out, j, reason)
        if n == 1:
            if code[0] in (ACCEPTED, OVER):  # a per-trial step's Command
                e = b.errors[0].copy()
                condition = rank_condition(b.Y[0, FACTOR], self.threshold)
                assert condition is not None  # (an accepted row is of full rank)
                out.put(0, Command(np.zeros(6), error=e, error_norm=math.sqrt(e.dot(e)),
                                   rank=6, condition=condition, features_used=6,
                                   active_constraints=[], notes=[],
                                   actuation=Actuation.FORCE, forces=forces[0].copy()))
        elif simple:
            out.error_norm[:] = np.sqrt(norms(b.errors))
        else:
            accepted = (code == ACCEPTED) | (code == OVER)
            out.error_norm[accepted] = np.sqrt(norms(b.errors[accepted]))

    def _resolve(self, observations: ObservationBatch, b: RowArrays) -> dict[int, str]:
        """Finish the rows off the control grid and those whose rank the screen does not
        settle (module docstring); the reasons of the rows refused."""
        lib = _library()
        code, Y, trials = b.code, b.Y, b.trials
        reasons: dict[int, str] = {}
        again = False
        for j in np.flatnonzero(code == OFF_GRID).tolist():  # the reference on demand
            i = int(trials[j])
            try:
                d = self.laws[i].reference_legs(b.t[j:j + 1])[0].ravel()
            except Exception as exc:  # the nominal model failed here
                reasons[j] = f"nominal model failed: {exc}"
                code[j] = REFUSED
                continue
            if self.kp_ki:
                d[12:18] += self.kp_ki * self.integral[i]
            self.X[i, DESIRED] = d
            code[j] = READY
            again = True
        n = len(code)
        if again:
            if lib.jc_evaluate(self._ctx, n, b.addresses[0], *b.addresses[4:6]):
                raise CompilationError(f"{self.function.name}: the compiled function failed")
            lib.jc_finish(self._ctx, n, b.addresses[0], *b.addresses[4:])
        unsure = np.flatnonzero(code == UNSURE)
        if len(unsure):  # the exact rank test (LAPACK) where the screen does not settle it
            for j in unsure.tolist():
                full = rank_condition(Y[j, FACTOR], self.threshold) is not None
                code[j] = ACCEPT if full else REFUSED
            lib.jc_finish(self._ctx, n, b.addresses[0], *b.addresses[4:])
        for j in np.flatnonzero(code == NOT_FINITE).tolist():
            readings = encoder_readings(observations.item(j),
                                        stroke_of(self.laws[int(b.trials[j])].context))
            reasons[j] = readings if isinstance(readings, str) else "readings not finite"
        for j in np.flatnonzero(code == REFUSED).tolist():
            if j not in reasons:
                reasons[j] = refusal(Y[j], STATUS, RESIDUAL, FACTOR, self.threshold) or ""
        return reasons

    def _refuse(self, out: CommandBatch, j: int, reason: str) -> None:
        out.put(j, Command.refuse(f"{self.name}: {reason}", actuation=Actuation.FORCE))


__all__ = ["ACCEPTED", "QUINTIC_SIZE", "SOURCE", "JointRows", "JointState"]
