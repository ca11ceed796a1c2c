"""The C of the task computed-torque laws' one step (:mod:`controllers.task_ctc_rows`):
``tc_prepare`` (each row's readings, the law's measurement where all of it is seen and
finite, the reference on its grid, the integral term; a row's code says what is left to
Python), ``tc_evaluate`` (the compiled step, again from the pose reached until it
converges) and ``tc_finish`` (the rank screen and the accepted rows' state), each also
as ``*_call`` taking a step's arrays in one struct, and ``tc_step_call`` (the three, for a
few rows). Compiled with ``-fno-builtin -ffp-contract=off``: every IEEE operation as
written (``pow`` the C library's).
"""

from __future__ import annotations

import ctypes
from functools import lru_cache

from controllers.control_grid import GRID_TOLERANCE
from controllers.ctc_rows import NEWTON_CALLS_C
from hexapod.c_step import c_library, c_struct

#: A row's code in a step, in order (the C ``enum`` is made of these names): a command
#: (over a limit or not), or why not yet or not.
CODES = ("ACCEPTED", "OVER", "NOT_FINITE", "OFF_GRID", "REFUSED", "UNSURE", "READY", "ACCEPT",
         "FIRST", "STALE", "UNUSABLE", "UNKNOWN", "UNSEEN")
(ACCEPTED, OVER, NOT_FINITE, OFF_GRID, REFUSED, UNSURE, READY, ACCEPT, FIRST, STALE, UNUSABLE,
 UNKNOWN, UNSEEN) = range(len(CODES))

#: The C of a step (module docstring); ``TaskCtc`` is :class:`Context`, ``TaskCall``
#: :class:`Call`.
SOURCE = NEWTON_CALLS_C + r"""
typedef struct {
    double *X; int64_t n_in, q_at, qd_at, ref_at, ref_w, mask_at, mask_w, int_at, int_w;
    int64_t pose_in; const uint8_t *usable, *plain; const double *clock, *built, *dt;
    const int64_t *grid_len; const double *const *grids; const uint8_t *const *known;
    double kp_ki; double *integral, *guessed; int64_t *steps; const double *limit;
    KernelCall kernel;
    int64_t n_out, pose_out, residual_at, status_at, screen_at, forces_at, error_at;
    double tol; int64_t max_calls; double screen_scale;
    int64_t measured, feat_at, feat_w, vis_w, ones_at, ones_w;
    double q_lo, q_hi;  /* the plausible readings [m] (controllers.plausible) */
} TaskCtc;
enum { @CODES@ };

/* the measurement of row j written where all of it is seen and finite (1), else 0 */
static int measure(const TaskCtc *c, int64_t j, double *x, const double *feat,
                   const uint8_t *vis) {
    if (!c->measured) return 1;  /* nothing measured: the pose from the encoders */
    const double *f = feat + c->feat_w * j;
    const uint8_t *v = vis + c->vis_w * j;
    double sum = 0.0;
    for (int64_t l = 0; l < c->vis_w; l++) if (!v[l]) return 0;
    for (int64_t l = 0; l < c->feat_w; l++) sum += f[l];
    if (!isfinite(sum)) return 0;  /* a NaN or inf makes the sum so */
    memcpy(x + c->feat_at, f, c->feat_w * sizeof(double));
    for (int64_t l = 0; l < c->ones_w; l++) x[c->ones_at + l] = 1.0;
    return 1;
}

void tc_prepare(const TaskCtc *c, int64_t m, double *Xl, const int64_t *trials,
                const double *t, const double *q, const double *qd, int64_t *code,
                double *tr, int64_t *gstep, const double *feat, const uint8_t *vis,
                uint8_t *seen) {
    for (int64_t j = 0; j < m; j++) {
        int64_t i = trials[j];
        double *x = Xl + c->n_in * j;
        const double *qj = q + 6 * j, *qdj = qd + 6 * j, *clock = c->clock + 3 * i;
        if (!c->usable[i]) { code[j] = UNUSABLE; continue; }
        memcpy(x, c->X + c->n_in * i, c->n_in * sizeof(double));  /* the trial's row */
        int finite = isfinite(t[j]);
        for (int l = 0; l < 6; l++)
            finite &= qj[l] > c->q_lo && qj[l] < c->q_hi && isfinite(qdj[l]);
        if (!finite) { code[j] = NOT_FINITE; continue; }
        memcpy(x + c->q_at, qj, 6 * sizeof(double));
        memcpy(x + c->qd_at, qdj, 6 * sizeof(double));
        seen[j] = (uint8_t)measure(c, j, x, feat, vis);
        if (clock[0] == 0.0) { code[j] = FIRST; continue; }
        if (c->built[i] != clock[2]) { code[j] = STALE; continue; }
        double r = t[j] - clock[1], dt = c->dt[i], k = nearbyint(r / dt);
        int64_t len = c->grid_len[i];
        tr[j] = r;
        if (!(fabs(r - k * dt) <= @GRID_TOLERANCE@ && k >= 0) || len <= 0) {
            code[j] = OFF_GRID; continue;
        }
        gstep[j] = (int64_t)k < len - 1 ? (int64_t)k : len - 1;
        memcpy(x + c->ref_at, c->grids[i] + c->ref_w * gstep[j], c->ref_w * sizeof(double));
        for (int64_t r2 = 0; r2 < c->mask_w; r2++) x[c->mask_at + r2] = 1.0;
        if (!c->plain[i])
            for (int64_t r2 = 0; r2 < c->int_w; r2++)
                x[c->int_at + r2] = c->kp_ki * c->integral[c->int_w * i + r2];
        /* UNKNOWN: some task rows not known; UNSEEN: a feature hidden or not finite */
        code[j] = !c->known[i][gstep[j]] ? UNKNOWN : seen[j] ? READY : UNSEEN;
    }
}

int tc_evaluate(const TaskCtc *c, int64_t m, double *Xl, const int64_t *code, double *Y) {
    for (int64_t j = 0; j < m; j++) {
        if (code[j] != READY) continue;
        if (newton_calls(&c->kernel, Xl + c->n_in * j, Y + c->n_out * j, c->pose_in,
                         c->pose_out, c->residual_at, c->tol, c->max_calls)) return 1;
    }
    return 0;
}

void tc_finish(const TaskCtc *c, int64_t m, const double *Xl, const int64_t *trials,
               int64_t *code, const double *Y, double *forces) {
    for (int64_t j = 0; j < m; j++) {
        const double *y = Y + c->n_out * j, *x = Xl + c->n_in * j;
        if (code[j] == READY) {
            int screen = rank_screen(y, c->status_at, c->screen_at, c->screen_scale);
            if (screen < 2) { code[j] = screen ? UNSURE : REFUSED; continue; }
        } else if (code[j] != ACCEPT) continue;
        int64_t i = trials[j];
        memcpy(c->X + c->n_in * i + c->pose_in, y + c->pose_out, 12 * sizeof(double));
        c->guessed[i] = 1.0;
        c->steps[i] += 1;
        int over = 0;
        for (int l = 0; l < 6; l++) {
            double f = y[c->forces_at + l];
            forces[6 * j + l] = f;
            if (fabs(f) > c->limit[6 * i + l]) over = 1;
        }
        if (!c->plain[i] && !over)  /* anti-windup: held while over a limit */
            for (int64_t r = 0; r < c->int_w; r++) {
                if (c->mask_w && x[c->mask_at + r] != 1.0) continue;  /* a row not used */
                double e = y[c->error_at + r];
                c->integral[c->int_w * i + r] += (isfinite(e) ? e : 0.0) * c->dt[i];
            }
        code[j] = over ? OVER : ACCEPTED;
    }
}

/* the calls with a step's arrays in one struct (two arguments from Python) */
typedef struct {
    double *X; const int64_t *trials; const double *t, *q, *qd; int64_t *code; double *tr;
    int64_t *gstep; const double *feat; const uint8_t *vis; uint8_t *seen; double *Y, *forces;
    int64_t m;
} TaskCall;
void tc_prepare_call(const TaskCtc *c, const TaskCall *a) {
    tc_prepare(c, a->m, a->X, a->trials, a->t, a->q, a->qd, a->code, a->tr, a->gstep, a->feat,
               a->vis, a->seen);
}
int tc_evaluate_call(const TaskCtc *c, const TaskCall *a) {
    return tc_evaluate(c, a->m, a->X, a->code, a->Y);
}
void tc_finish_call(const TaskCtc *c, const TaskCall *a) {
    tc_finish(c, a->m, a->X, a->trials, a->code, a->Y, a->forces);
}
int tc_step_call(const TaskCtc *c, const TaskCall *a) {
    tc_prepare_call(c, a);
    for (int64_t j = 0; j < a->m; j++)
        if (a->code[j] != READY && a->code[j] != NOT_FINITE && a->code[j] != UNUSABLE)
            return 0;
    if (tc_evaluate_call(c, a)) return 1;
    tc_finish_call(c, a);
    return 0;
}
""".replace("@CODES@", ", ".join(CODES)).replace("@GRID_TOLERANCE@", repr(GRID_TOLERANCE))

#: The C ``TaskCtc`` (:func:`~hexapod.c_step.c_struct`: its fields read from the C).
Context = c_struct(SOURCE, "TaskCtc")


#: The C ``TaskCall`` (:func:`~hexapod.c_step.c_struct`: its fields read from the C).
Call = c_struct(SOURCE, "TaskCall")


@lru_cache(maxsize=1)
def library() -> ctypes.CDLL:
    """The compiled :data:`SOURCE` (``-fno-builtin -ffp-contract=off``: IEEE operations
    as written)."""
    return c_library("task_ctc_rows", SOURCE)


__all__ = ["ACCEPT", "ACCEPTED", "CODES", "FIRST", "NOT_FINITE", "OFF_GRID", "OVER", "READY",
           "REFUSED", "SOURCE", "STALE", "UNKNOWN", "UNSEEN", "UNSURE", "UNUSABLE", "Call",
           "Context", "library"]
