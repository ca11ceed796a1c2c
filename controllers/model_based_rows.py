"""The one step of ``model-based`` over a batch of trials (a batch of one is the
per-trial ``step``).

:class:`PoseServoRows` (built by the controller's reset) owns its trials' state: the
forward kinematics' input rows ``F`` (n, 54) (each trial's nominal base and platform
points), the pose servo's input rows ``X`` (n, n_in) (gain, goal, camera) and the pose
estimates (the warm starts); each instance's ``servo_input`` and ``estimate`` are views
of their rows.

One step is C (:data:`SOURCE`, compiled once and cached as the kernels are): for each
row, the readings (a time or a length not finite: refused), the forward kinematics of
:func:`hexapod.fk.forward_kinematics` (``method="newton"``): the compiled Newton steps
(:func:`hexapod.fk.newton_kernel`, ``ITERATIONS_PER_CALL`` a call) from the estimate
until the largest absolute length residual (NaN if one is) is below the tolerance, not
finite, or the iteration budget spent; then the estimate and the servo's pose, and the
compiled pose servo (:func:`controllers.model_based.pose_servo_kernel`), whose status
refuses a row. Python takes the rare rows: the refusals' reasons, a failed forward
kinematics (its message, the estimate reset to the home pose) and the servo of a
controller built with ``compiled=False`` (the CasADi virtual machine).
"""

from __future__ import annotations

import ctypes
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np

from controllers.data import Command, CommandBatch, ObservationBatch, observation_problem
from controllers.estimators import PoseEstimate
from controllers.plausible import reading_bounds, stroke_of
from hexapod.c_step import KERNEL_CALL_C, KernelCall, RowArrays, c_library, c_struct
from hexapod.compiled import CompilationError
from hexapod.exceptions import ForwardKinematicsError
from hexapod.fk import ITERATIONS_PER_CALL, NEWTON_INPUTS, NEWTON_OUTPUTS, newton_kernel, pack_rows
from hexapod.workspace import home_pose

if TYPE_CHECKING:
    from controllers.model_based import ModelBasedController
    from hexapod.compiled import CompiledFunction

#: A row's code after the C step: a command, refused by the servo's status, a reading not
#: finite, a failed forward kinematics, the servo left to Python.
COMMAND, REFUSED, NOT_FINITE, FK_FAILED, READY = range(5)

#: The C of a step (see the module docstring); ``ModelBased`` is :class:`_Context`.
SOURCE = KERNEL_CALL_C + r"""
typedef struct {
    double *F, *X, *R, *p, *y;
    int64_t fk_in, R_in, t_in, q_in, R_out, t_out, residual_out;
    int64_t n_in, n_out, R_at, t_at, status_at, max_iterations, per_call;
    double tol;
    KernelCall newton, servo;
    double q_lo, q_hi;  /* the plausible readings [m] (controllers.plausible) */
} ModelBased;
enum { COMMAND, REFUSED, NOT_FINITE, FK_FAILED, READY };

/* fk (m, 2): each row's iterations and last residual [m] */
int mb_step(ModelBased *c, int64_t m, const int64_t *trials, const double *t,
            const double *q, int64_t *code, double *Y, double *fk) {
    for (int64_t j = 0; j < m; j++) {
        const double *qj = q + 6 * j;
        int finite = isfinite(t[j]);
        for (int l = 0; l < 6; l++) finite &= qj[l] > c->q_lo && qj[l] < c->q_hi;
        if (!finite) { code[j] = NOT_FINITE; continue; }
        int64_t i = trials[j], it = 0;
        double *x = c->F + c->fk_in * i, *R = c->R + 9 * i, *p = c->p + 3 * i, *y = c->y;
        double res = INFINITY;
        for (int r = 0; r < 3; r++)  /* the Newton rows' R is column-major */
            for (int k = 0; k < 3; k++) x[c->R_in + r + 3 * k] = R[3 * r + k];
        memcpy(x + c->t_in, p, 3 * sizeof(double));
        memcpy(x + c->q_in, qj, 6 * sizeof(double));
        while (it < c->max_iterations) {
            if (kernel_call(&c->newton, x, y)) return 1;
            it += c->per_call;
            res = fabs(y[c->residual_out]);  /* the largest, NaN if one is */
            for (int l = 1; l < 6; l++) {
                double a = fabs(y[c->residual_out + l]);
                if (a > res || isnan(a)) res = a;
            }
            if (!isfinite(res) || res < c->tol) break;
            memcpy(x + c->R_in, y + c->R_out, 9 * sizeof(double));
            memcpy(x + c->t_in, y + c->t_out, 3 * sizeof(double));
        }
        fk[2 * j] = (double)it; fk[2 * j + 1] = res;
        if (!(res < c->tol)) { code[j] = FK_FAILED; continue; }
        double *xs = c->X + c->n_in * i;
        for (int r = 0; r < 3; r++)
            for (int k = 0; k < 3; k++) R[3 * r + k] = y[c->R_out + r + 3 * k];
        memcpy(p, y + c->t_out, 3 * sizeof(double));
        memcpy(xs + c->R_at, R, 9 * sizeof(double));
        memcpy(xs + c->t_at, p, 3 * sizeof(double));
        if (!c->servo.f) { code[j] = READY; continue; }
        double *yj = Y + c->n_out * j;
        if (kernel_call(&c->servo, xs, yj)) return 1;
        code[j] = yj[c->status_at] != 0.0 ? REFUSED : COMMAND;
    }
    return 0;
}
"""

#: The C ``ModelBased`` (:func:`~hexapod.c_step.c_struct`: its fields read from the C).
_Context = c_struct(SOURCE, "ModelBased")


@lru_cache(maxsize=1)
def _library() -> ctypes.CDLL:
    """The compiled :data:`SOURCE` (no arithmetic but comparisons: the flags of
    :mod:`controllers.joint_ctc_rows`)."""
    return c_library("model_based_rows", SOURCE)


class PoseServoRows:
    """The arrays of a batch of model-based trials and its one step (see the module
    docstring); each instance's servo input and estimate become views of them.

    Args:
        laws: The trials' instances (reset), in trial order.

    Raises:
        CompilationError: No compiled C (the Newton steps or this step).
    """

    def __init__(self, laws: list[ModelBasedController]) -> None:
        self.laws = laws
        kernel = laws[0].kernel
        assert kernel is not None
        self.kernel = kernel
        self.X = np.stack([law.servo_input for law in laws])
        self.estimate = PoseEstimate(np.stack([law.estimate.rotation for law in laws]),
                                     np.stack([law.estimate.translation for law in laws]))
        self.F = pack_rows(self.estimate.rotation, self.estimate.translation,
                           np.zeros((len(laws), 6)), np.stack([law.base_points for law in laws]),
                           np.stack([law.platform_points for law in laws]))
        for k, law in enumerate(laws):
            law.servo_input, law.estimate = self.X[k], self.estimate.row(k)
        #: Whether each trial's command carries the twist in its camera frame.
        self.twist = [law.camera_from_base is not None for law in laws]
        self.name = laws[0].name
        self._last: RowArrays | None = None
        newton, out, ins = newton_kernel(), kernel.outputs, NEWTON_INPUTS
        if newton.entry is None:
            raise CompilationError(f"{newton.name}: the model-based step needs its compiled "
                                   "C (no C compiler?)")
        self._y = np.zeros(newton.n_out)
        #: The kernels' calls (their work arrays live as long as these).
        self._calls = (self._call(newton), self._call(kernel))
        self.context = _Context(
            self.F.ctypes.data, self.X.ctypes.data, self.estimate.rotation.ctypes.data,
            self.estimate.translation.ctypes.data, self._y.ctypes.data, newton.n_in,
            ins["R"].start, ins["t"].start, ins["q"].start, NEWTON_OUTPUTS["R"].start,
            NEWTON_OUTPUTS["t"].start, NEWTON_OUTPUTS["residual"].start, kernel.n_in,
            kernel.n_out, kernel.inputs["R"].start, kernel.inputs["t"].start,
            out.index("status"), laws[0].fk_max_iterations, ITERATIONS_PER_CALL,
            laws[0].fk_tolerance, *self._calls,
            *reading_bounds(stroke_of(law.context) for law in laws))
        self._ctx = ctypes.addressof(self.context)
        #: The pose servo in the CasADi virtual machine (``compiled=False``): by Python.
        self._python_servo = kernel.entry is None
        self._at = {name: out[name] for name in ("e", "qdot", "twist")}
        self._norm, self._cond, self._status = (out.index(k) for k in ("norm", "cond", "status"))

    @staticmethod
    def _call(function: CompiledFunction) -> KernelCall:
        """The C call of ``function`` (its own work arrays), empty without its compiled C
        (the CasADi virtual machine: evaluated by :meth:`_servo`)."""
        return KernelCall() if function.entry is None else KernelCall.of(function)

    def step(self, observations: ObservationBatch, out: CommandBatch) -> None:
        """Every row's command into ``out`` (a refusal with its reason where there is
        none); a batch of one gets the full :class:`Command` (the diagnostics of a
        per-trial step: error, twist, rank, condition number, the iterations).

        Raises:
            CompilationError: A compiled function failed.
            ValueError: The observations' arrays are not of the batch's shapes.
        """
        n = len(observations)
        b = self._last
        if b is None or b.n != n:  # (in the C call's order)
            b = self._last = RowArrays(n, {
                "trials": ((), np.int64), "t": ((), float), "q": ((6,), float),
                "code": ((), np.int64), "Y": ((self.kernel.n_out,), float),
                "fk": ((2,), float)})
        observations.write_rows(b, rates=False)
        if _library().mb_step(self._ctx, n, *b.addresses):
            raise CompilationError(f"{self.kernel.name}: the compiled function failed")
        code, Y, at = b.code, b.Y, self._at
        if self._python_servo:
            self._servo(b)
        if n == 1 and code[0] == COMMAND:  # a per-trial step's Command
            y = Y[0].copy()
            out.put(0, Command(y[at["qdot"]], twist=y[at["twist"]] if self.twist[b.trials[0]]
                               else None, error=y[at["e"]], error_norm=float(y[self._norm]),
                               rank=6, condition=float(y[self._cond]), features_used=6,
                               notes=[f"forward kinematics: {int(b.fk[0, 0])} iterations"]))
            return
        if n > 1 and (code == COMMAND).all():
            out.velocities[:] = Y[:, at["qdot"]]
            out.error_norm[:] = Y[:, self._norm]
            return
        ok = np.flatnonzero(code == COMMAND)
        out.velocities[ok] = Y[ok, at["qdot"]]
        out.error_norm[ok] = Y[ok, self._norm]
        for j in np.flatnonzero(code != COMMAND).tolist():
            out.put(j, self._refusal(observations, b, j))

    def _servo(self, b: RowArrays) -> None:
        """The pose servo of the rows the C left to Python (the CasADi virtual machine)."""
        ready = np.flatnonzero(b.code == READY)
        if len(ready):
            b.Y[ready] = self.kernel.batch(self.X[b.trials[ready]])
            b.code[ready] = np.where(b.Y[ready, self._status] != 0.0, REFUSED, COMMAND)

    def _refusal(self, observations: ObservationBatch, b: RowArrays, j: int) -> Command:
        """The refusal of row ``j`` with its reason; a failed forward kinematics resets its
        trial's estimate to the home pose (the next step starts again from there)."""
        code, i = int(b.code[j]), int(b.trials[j])
        if code == REFUSED:
            from controllers.model_based import STATUS_REASONS

            return Command.refuse(STATUS_REASONS[int(b.Y[j, self._status])], b.Y[j, self._at["e"]])
        if code == NOT_FINITE:
            obs = observations.item(j)
            law = self.laws[i]
            return Command.refuse(observation_problem(obs, law.features,
                                                      stroke_of(law.context))
                                  or "readings not finite")
        context = self.laws[i].context
        assert context is not None
        self.estimate.set(*home_pose(context.geometry), np.array([i]))
        res = float(b.fk[j, 1])
        exc = ForwardKinematicsError("newton", res, int(b.fk[j, 0]), (
            "no convergence within the iteration budget" if np.isfinite(res)
            else "singular Jacobian on the way"))
        return Command.refuse(f"forward kinematics failed: {exc}")


__all__ = ["COMMAND", "FK_FAILED", "NOT_FINITE", "READY", "REFUSED", "SOURCE",
           "PoseServoRows"]
