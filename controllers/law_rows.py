"""The one step of the image-based laws over a batch of trials (a batch of one is the
per-trial ``step``): C around the law's compiled core (:mod:`controllers.law_kernel`).

:class:`LawRows` (built by the law's batch reset) holds each trial's core inputs as a
row of ``X`` (constants written at the reset and by the goals), and points at the
batch's estimate (:class:`~controllers.estimators.LegDirectionEstimate`), the limit QP's
bounds and the leg-rate feed-forward's gains and offsets. One step
(:meth:`LawRows.step`) is C (:data:`SOURCE`, compiled once and cached as the kernels
are):

- ``prepare``: a row is COMMON when its trial's row holds the core's inputs (its goal
  sees every feature and its trial has the batch's core), every feature is visible, and
  its features, lengths and time are finite with every length > 0; its features and
  lengths (and, when the goal gives no lengths, the ``desired_lengths`` of the DESIRED /
  MEAN interaction) are packed into its input row. Every other row is RARE;
- ``evaluate``: the core over the COMMON rows: the lean core (``law_tail(lean=True)``)
  for a batch of several, the full core for a batch of one (the per-trial command's
  rank and condition number); both give the same error, ``tau``, ``q_dot`` and
  directions to the last bit where the lean one certifies full rank;
- ``finish``: a row is accepted when its norms are finite, its rank is 6, its ``q_dot``
  is finite and, for the limit QP, the unconstrained optimum clears every bound by twice
  the tolerance (:func:`~controllers.solvers.limit_qp.velocity_bounds`' arithmetic);
  every evaluated row's estimate has every direction measured; an accepted row writes
  the twist and the lengths commanded, its leg velocities and error norm, and the
  leg-rate feed-forward (:func:`~controllers.leg_rate.feed_forward`'s arithmetic). The
  other rows are REJECTED (their twist zero until Python commands one).

Python takes the RARE rows (a hidden feature, an unusable observation: the law's own
per-row step) and the REJECTED ones (from the full core's result: the degenerate
core's reasons, OSQP where the optimum touches a bound). The C is compiled without
fused multiply-adds, so its numbers are those of the numpy expressions it replaced.
"""

from __future__ import annotations

import ctypes
from functools import lru_cache
from typing import TYPE_CHECKING, Any

import numpy as np

from controllers.data import ObservationBatch
from controllers.estimators import LegDirectionEstimate
from controllers.law_kernel import LawKernel, LawResult
from controllers.plausible import reading_bounds, stroke_of
from hexapod.c_step import KERNEL_CALL_C, KernelCall, RowArrays, c_library, c_struct
from hexapod.compiled import CompilationError

if TYPE_CHECKING:
    from controllers.laws import VisionLaw
    from hexapod.compiled import CompiledFunction

#: A row's code after a step (the C ``enum`` is made of these names): a command, why
#: Python steps the row (RARE: not the common case; REJECTED: the core's result is not
#: the command), or READY (packed, not evaluated yet).
CODES = ("ACCEPTED", "RARE", "REJECTED", "READY")
ACCEPTED, RARE, REJECTED, READY = range(len(CODES))

#: What the C takes of the core's solution (:attr:`~controllers.solvers.base.Solver.
#: core_acceptance`, in the C ``enum``'s order).
ACCEPTANCE = ("core", "bounds", "none")

#: The C of a step (see the module docstring); ``VisionRows`` is :class:`_Context`.
SOURCE = KERNEL_CALL_C + r"""
typedef struct {
    double *X; int64_t n_in; const uint8_t *ready, *desired_q;
    int64_t feat_at, n_feat, units, len_at, dlen_at;
    KernelCall lean, full;
    int64_t n_out, norm_at, n_sum_at, rank_at, check_at, tau_at, qdot_at, dir_at;
    int64_t accept; const double *lower, *upper, *inv_dt, *vmax; const uint8_t *shortcut;
    double *directions, *in_use, *twist, *lengths; uint8_t *observed;
    const double *kappa; double *offset;
    double q_lo, q_hi;  /* the plausible readings [m] (controllers.plausible) */
} VisionRows;
typedef struct {
    const int64_t *trials; const double *t, *q, *feats; const uint8_t *vis; const double *qd;
    int64_t *code; double *Y, *vel, *norm;
} StepRows;
enum { @CODES@ };
enum { @ACCEPTANCE@ };

void vl_prepare(const VisionRows *c, int64_t m, const int64_t *trials, const double *t,
                const double *q, const double *feats, const uint8_t *vis, int64_t *code) {
    for (int64_t j = 0; j < m; j++) {
        int64_t i = trials[j];
        const double *qj = q + 6 * j, *fj = feats + c->n_feat * j;
        const uint8_t *vj = vis + c->units * j;
        int ok = c->ready[i] && isfinite(t[j]);
        for (int64_t k = 0; ok && k < c->units; k++) ok = vj[k] != 0;
        for (int64_t k = 0; ok && k < c->n_feat; k++) ok = isfinite(fj[k]);
        for (int l = 0; ok && l < 6; l++) ok = qj[l] > c->q_lo && qj[l] < c->q_hi;
        if (!ok) { code[j] = RARE; continue; }
        double *x = c->X + c->n_in * i;
        memcpy(x + c->feat_at, fj, c->n_feat * sizeof(double));
        memcpy(x + c->len_at, qj, 6 * sizeof(double));
        if (c->desired_q[i]) memcpy(x + c->dlen_at, qj, 6 * sizeof(double));
        code[j] = READY;
    }
}

int vl_evaluate(const VisionRows *c, int64_t m, const int64_t *trials, const int64_t *code,
                double *Y, int64_t full) {
    const KernelCall *k = full ? &c->full : &c->lean;
    for (int64_t j = 0; j < m; j++)
        if (code[j] == READY && kernel_call(k, c->X + c->n_in * trials[j], Y + c->n_out * j))
            return 1;
    return 0;
}

void vl_finish(const VisionRows *c, int64_t m, const int64_t *trials, const double *q,
               const double *qd, int64_t *code, const double *Y, double *vel, double *norm) {
    for (int64_t j = 0; j < m; j++) {
        double *v = vel + 6 * j;
        if (code[j] != READY) {  /* (rows Python steps: their command is put there) */
            memset(v, 0, 6 * sizeof(double)); norm[j] = 0.0; continue;
        }
        int64_t i = trials[j];
        const double *y = Y + c->n_out * j, *qj = q + 6 * j, *qdot = y + c->qdot_at;
        int ok = isfinite(y[c->norm_at]) && isfinite(y[c->n_sum_at]) && y[c->rank_at] >= 6.0
                 && y[c->check_at] == 0.0;
        if (c->accept == NONE) ok = 0;
        if (ok && c->accept == BOUNDS) {  /* limit_qp.velocity_bounds, the shortcut's test */
            double vmax = c->vmax[i], tol2 = 2.0 * (1e-6 * vmax);
            ok = c->shortcut[i];
            for (int l = 0; ok && l < 6; l++) {
                double slo = (c->lower[i] - qj[l]) * c->inv_dt[i];
                double shi = (c->upper[i] - qj[l]) * c->inv_dt[i];
                double lo = fmin(fmax(slo, -vmax), vmax), hi = fmin(fmax(shi, -vmax), vmax);
                ok = (qdot[l] - lo) > tol2 && (hi - qdot[l]) > tol2;
            }
        }
        memcpy(c->directions + 18 * i, y + c->dir_at, 18 * sizeof(double));
        memcpy(c->in_use + 18 * i, y + c->dir_at, 18 * sizeof(double));
        memset(c->observed + 6 * i, 1, 6);
        if (!ok) {  /* every direction measured, nothing commanded (yet: Python's) */
            memset(c->twist + 6 * i, 0, 6 * sizeof(double));
            code[j] = REJECTED; memset(v, 0, 6 * sizeof(double)); norm[j] = 0.0; continue;
        }
        memcpy(c->twist + 6 * i, y + c->tau_at, 6 * sizeof(double));
        memcpy(c->lengths + 6 * i, qj, 6 * sizeof(double));
        memcpy(v, qdot, 6 * sizeof(double));
        norm[j] = y[c->norm_at];
        if (c->kappa) {  /* feed_forward: u = q_dot + kappa (q_dot - (v - offset)) */
            double *off = c->offset + 6 * i;
            const double *kap = c->kappa + 6 * i;
            if (qd) {
                const double *vj = qd + 6 * j;
                int known = 1;
                for (int l = 0; l < 6; l++) known &= isfinite(vj[l]);
                if (known)
                    for (int l = 0; l < 6; l++) v[l] = v[l] + kap[l] * (v[l] - (vj[l] - off[l]));
            }
            for (int l = 0; l < 6; l++) off[l] = 0.0;
        }
        code[j] = ACCEPTED;
    }
}

int vl_step(const VisionRows *c, const StepRows *r, int64_t m, int64_t full, int64_t has_qd) {
    vl_prepare(c, m, r->trials, r->t, r->q, r->feats, r->vis, r->code);
    if (vl_evaluate(c, m, r->trials, r->code, r->Y, full)) return 1;
    vl_finish(c, m, r->trials, r->q, has_qd ? r->qd : NULL, r->code, r->Y, r->vel, r->norm);
    return 0;
}
""".replace("@CODES@", ", ".join(CODES)).replace(
    "@ACCEPTANCE@", ", ".join(a.upper() for a in ACCEPTANCE))

#: The C ``VisionRows`` (:func:`~hexapod.c_step.c_struct`: its fields read from the C).
_Context = c_struct(SOURCE, "VisionRows")


@lru_cache(maxsize=1)
def _library() -> ctypes.CDLL:
    """The compiled :data:`SOURCE` (``-fno-builtin``, ``-ffp-contract=off``: no fused
    multiply-add, the numpy expressions' bits)."""
    return c_library("vision_law_rows", SOURCE)


#: The C ``StepRows`` (:func:`~hexapod.c_step.c_struct`: its fields read from the C).
_StepRows = c_struct(SOURCE, "StepRows")


def core_key(law: VisionLaw) -> tuple[object, object]:
    """What the trials stepped by one :class:`LawRows` share: the observed feature and
    the compiled core's input layout (the core's feature and interaction)."""
    kernel = law.kernel
    return law.observed_feature, None if kernel is None else kernel.slices


def positive(bounds: tuple[float, float]) -> tuple[float, float]:
    """Reading bounds [m] that also refuse a length of zero or less."""
    return max(bounds[0], 0.0), bounds[1]


class LawRows:
    """The core inputs of a batch's trials, one row per trial, and the batch's one step
    (module docstring).

    Args:
        laws: The trials' instances (reset), in trial order.
        estimate: The batch's estimate (the instances' estimates are its rows).
        feedforward: ``(kappa, offset)`` (n, 6) of the leg-rate feed-forward, or None
            (off).
        core: The instance whose compiled core and feature the rows take (default the
            first trial's): the trials of another core are not this object's (their
            rows RARE), nor those whose goal hides a feature.

    Raises:
        CompilationError: No C compiler (the step is C).
    """

    def __init__(self, laws: list[VisionLaw], estimate: LegDirectionEstimate,
                 feedforward: tuple[np.ndarray, np.ndarray] | None,
                 core: VisionLaw | None = None) -> None:
        _library()  # (without a C compiler, the reset says so)
        law0 = laws[0] if core is None else core
        kernel = law0.kernel
        assert kernel is not None, "reset() sets the compiled core"
        n = len(laws)
        #: The batch's core (its layouts are every ready row's).
        self.kernel: LawKernel = kernel
        self.feature = law0.observed_feature
        #: What identifies the trials of this core (:func:`core_key`).
        self.key = core_key(law0)
        self.slices = kernel.slices
        self.outputs = kernel.outputs
        self.X = np.zeros((n, kernel.input_vector.size))
        #: (n,) the trials whose row holds its core's inputs (they may be COMMON).
        self.ready = np.zeros(n, dtype=np.uint8)
        #: (n,) the trials whose ``desired_lengths`` are the measured ones (no goal lengths).
        self.desired_q = np.zeros(n, dtype=np.uint8)
        #: (n,) the rows holding a core's constants (a retarget may write its desired
        #: features alone).
        self.filled = np.zeros(n, dtype=bool)
        for k, law in enumerate(laws):
            self.take(k, law)
        self.laws = laws
        self._estimate = estimate
        solver = law0.solver
        accept = ACCEPTANCE.index(solver.core_acceptance)
        qp = solver.core_acceptance == "bounds"
        solvers: list[Any] = [law.solver for law in laws]
        windows = [s.window for s in solvers] if qp else []
        self._bounds = [np.array([getattr(w, name) for w in windows] or [0.0])
                        for name in ("lower", "upper", "max_speed")]
        self._bounds.append(np.array([1.0 / w.dt for w in windows] or [0.0]))
        self._shortcut = np.array([s.shortcut for s in solvers] if qp else [0],
                                  dtype=np.uint8)
        self._feedforward = feedforward
        o, ins = self.outputs, self.slices
        lo, hi, vmax, inv_dt = self._bounds
        est = estimate
        self.context = _Context(
            self.X.ctypes.data, self.X.shape[1], self.ready.ctypes.data,
            self.desired_q.ctypes.data, ins["features"].start,
            ins["features"].stop - ins["features"].start, self.feature.units,
            ins["lengths"].start,
            ins["desired_lengths"].start if "desired_lengths" in ins else -1,
            KernelCall(), KernelCall(), o.size, o.index("error_norm"), o.index("n_sum"),
            o.index("rank"), o.index("qdot_check"), o["tau"].start, o["qdot"].start,
            o["directions"].start, accept, lo.ctypes.data, hi.ctypes.data,
            inv_dt.ctypes.data, vmax.ctypes.data, self._shortcut.ctypes.data,
            est.directions.ctypes.data, est.in_use.ctypes.data, est.twist.ctypes.data,
            est.lengths.ctypes.data, est.observed.ctypes.data,
            None if feedforward is None else feedforward[0].ctypes.data,
            None if feedforward is None else feedforward[1].ctypes.data,
            *positive(reading_bounds(stroke_of(law.context) for law in laws)))
        self._ctx = ctypes.addressof(self.context)
        #: The lean and full cores, once bound to the C (built on first use: a batch
        #: stepped only one row at a time never builds the lean core).
        self.functions: dict[bool, CompiledFunction] = {}
        self._calls: dict[bool, KernelCall] = {}
        #: The slices and indices of a command's outputs: error, tau, |e|, rank, condition.
        self.command_outputs = (o["error"], o["tau"], o.index("error_norm"), o.index("rank"),
                                o.index("condition"))
        self._c = True  # the core has its C (else the cores are called from Python)
        self._last: RowArrays | None = None

    def take(self, trial: int, law: VisionLaw) -> None:
        """Copy a trial's core inputs into its row (after its reset or a new goal)."""
        kernel = law.kernel
        same = kernel is not None and core_key(law) == self.key
        self.ready[trial] = same and law.goal_all_visible
        self.desired_q[trial] = same and law.desired_lengths_measured
        if kernel is None or not same:
            self.filled[trial] = False
            return
        self.X[trial] = kernel.input_vector
        for name in ("weights", "measured"):  # the common case: every feature, measured
            self.X[trial, self.slices[name]] = 1.0
        self.filled[trial] = True

    def write_desired(self, trials: np.ndarray, desired: np.ndarray, quick: np.ndarray
                      ) -> np.ndarray:
        """Write the desired features ``desired`` (m, D) of the goals ``quick`` (m,) into
        the rows of ``trials`` (m,) that hold their constants; returns the mask of the
        goals written."""
        quick = quick & self.filled[trials]
        rows = np.flatnonzero(quick)
        if len(rows):
            self.X[trials[rows], self.slices["desired"]] = desired[rows]
            self.ready[trials[rows]] = 1
        return quick  # type: ignore[no-any-return]

    def _bind(self, full: bool) -> CompiledFunction:
        """The lean or full core, bound to the C context on its first use."""
        function = self.kernel.function if full else self.kernel.lean_function
        self.functions[full] = function
        try:
            call = KernelCall.of(function)
        except CompilationError:  # no C: the CasADi virtual machine between the C passes
            self._c = False
            return function
        self._calls[full] = call  # (its work arrays live as long as the rows)
        setattr(self.context, "full" if full else "lean", call)
        return function

    def step(self, observations: ObservationBatch) -> tuple[np.ndarray, RowArrays]:
        """Every COMMON row's command, where the core's result is one (module docstring);
        returns the rows' codes (n,) and the step's arrays (``vel`` and ``norm``: the
        accepted rows' velocities [m/s] and error norms, zeros elsewhere; ``Y``: the
        core's outputs, the full core's for a batch of one).

        Raises:
            CompilationError: The compiled core failed.
            ValueError: The observations' arrays are not of the batch's shapes.
        """
        obs = observations
        n = len(obs)
        b = self._last
        if b is None or b.n != n:  # in: trials, times, lengths, features, visibility,
            shape = self.feature.shape  # leg rates; out: codes, outputs, velocities, norms
            b = self._last = RowArrays(n, {
                "trials": ((), np.int64), "t": ((), float), "q": ((6,), float),
                "feats": (shape, float), "vis": (shape[:-1], bool), "qd": ((6,), float),
                "code": ((), np.int64), "Y": ((self.outputs.size,), float),
                "vel": ((6,), float), "norm": ((), float)}, _StepRows)
        b.trials[...] = obs.trials
        feats = getattr(obs, self.feature.field)
        if feats is None:  # not measured: every row's own step says so
            b.code[:] = RARE
            b.vel[:] = 0.0
            b.norm[:] = 0.0
            return b.code, b
        full = n == 1
        function = self.functions.get(full) or self._bind(full)
        b.t[...] = obs.t
        b.q[...] = obs.lengths
        b.feats[...] = feats
        b.vis[...] = getattr(obs, self.feature.visibility)
        qd = obs.q_dot if self._feedforward is not None else None
        if qd is not None:
            b.qd[...] = qd
        lib = _library()
        if self._c:
            if lib.vl_step(self._ctx, b.at, n, full, qd is not None):
                raise CompilationError(f"{function.name}: the compiled function failed")
        else:
            r: Any = b.call
            lib.vl_prepare(self._ctx, n, r.trials, r.t, r.q, r.feats, r.vis, r.code)
            ready = np.flatnonzero(b.code == READY)
            if len(ready):
                b.Y[ready] = function.batch(self.X[b.trials[ready]])
            lib.vl_finish(self._ctx, n, r.trials, r.q, None if qd is None else r.qd, r.code,
                          r.Y, r.vel, r.norm)
        return b.code, b

    def full_result(self, trial: int, y: np.ndarray, full: bool) -> LawResult:
        """The full core's result of a REJECTED row of ``trial`` (its outputs ``y`` when
        they are the full core's, else evaluated on its packed input row)."""
        if not full:
            y = self.kernel.function.single(self.X[trial])
        return self.kernel.result(y.copy())


__all__ = ["ACCEPTED", "CODES", "RARE", "READY", "REJECTED", "SOURCE", "LawRows", "core_key"]
