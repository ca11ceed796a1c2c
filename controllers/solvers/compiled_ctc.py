"""The joint-space computed-torque step as one compiled CasADi function (C, ctypes).

The SAME symbolic expressions as :func:`hexapod.fk.newton_function` and
:func:`hexapod.dynamics.compiled.expressions`, composed into one function generated to C
by :class:`hexapod.compiled.CompiledFunction`:

- forward kinematics of the encoder lengths: ``FK_CALLS`` calls of the Newton steps from
  the previous pose, the length residual out (the caller calls again from the pose
  reached until it is below :data:`FK_TOLERANCE`);
- ``K`` there, the twist ``tau = K^-1 q_dot`` and the bias ``K_dot tau``;
- ``a* = q_ddot* + Kd (q_dot* - K tau) + Kp (q* - q)``, ``tau_dot = K^-1 (a* - K_dot
  tau)``, the leg acceleration ``a = K tau_dot + K_dot tau``;
- the forces ``K^-T (M tau_dot + h)`` (``solved`` 1.0 when that solve's residual is below
  the tolerance) plus the drives' reflected inertia, viscous and Coulomb terms.

Input row :data:`INPUTS`: ``pose`` (``R`` column-major, ``t``), ``q``, ``q_dot``,
``desired`` (``q*``, ``q_dot*``, ``q_ddot*``), ``points`` (``A``, ``E``), the 19 inertial
``params``, the drives' ``rotor``, ``viscous``, ``coulomb`` and the ``gains`` ``Kp``,
``Kd``. Output row :data:`OUTPUTS`: ``pose``, ``factor`` ``K^T K`` (for the rank test),
``forces`` [N], ``fk_residual`` [m], ``solved`` and ``status`` (:func:`sx_status`: 0 or
the :class:`controllers.ctc_status.Status` the caller's refusal words). The numpy step
this replaced is the tests' oracle (``tests/controllers/ctc_oracles.py``).
"""

from __future__ import annotations

from functools import lru_cache, partial

import casadi as ca

from controllers.ctc_status import Status
from controllers.law_algebra import rank_screen
from hexapod.compiled import CompiledFunction, Layout, code_key
from hexapod.dynamics import compiled as dyn
from hexapod.dynamics.drive_model import COULOMB_SMOOTHING
from hexapod.dynamics.model import INVERSE_TOLERANCE
from hexapod.fk import NEWTON_OUTPUTS, newton_function

#: Calls of the compiled Newton steps unrolled in the function.
FK_CALLS = 1
#: The model blocks of every compiled computed-torque step (the task-space ones too:
#: :mod:`controllers.solvers.compiled_task_ctc`) after the pose, ``q`` and ``q_dot``.
MODEL_BLOCKS = (("points", (2, 6, 3)), ("params", 19), ("rotor", 6), ("viscous", 6),
                ("coulomb", 6))
#: The input row of the joint-space step (module docstring).
INPUTS = Layout([("pose", 12), ("q", 6), ("q_dot", 6), ("desired", (3, 6)), *MODEL_BLOCKS,
                 ("gains", 2)], "joint-space computed-torque input")
#: Its output row.
OUTPUTS = Layout([("pose", 12), ("factor", (6, 6)), ("forces", 6), ("fk_residual", 1),
                  ("solved", 1), ("status", 1), ("screen", 2)],
                 "joint-space computed-torque output")
#: Forward-kinematics tolerance on the length residual [m] (as :func:`forward_kinematics`):
#: the step's status is ``NOT_CONVERGED`` above it.
FK_TOLERANCE = 1e-12
#: Largest finite double: a sum of squares not above it is finite (NaN compares false).
_DBL_MAX = 1.7976931348623157e308


def sx_encoder_pose(pose: ca.SX, q: ca.SX, points: ca.SX, calls: int
                    ) -> tuple[ca.SX, ca.SX]:
    """The pose ``R`` (9, column-major) and ``t`` (3) of the encoder lengths ``q`` after
    ``calls`` calls of the compiled Newton steps from ``pose``, and the (6,) length
    residual."""
    newton = newton_function()
    y = NEWTON_OUTPUTS.split(newton(ca.vertcat(pose, q, points)))
    for _ in range(calls - 1):
        y = NEWTON_OUTPUTS.split(newton(ca.vertcat(y["R"], y["t"], q, points)))
    return ca.vertcat(y["R"], y["t"]), y["residual"]


def sx_model_state(R_t: ca.SX, qd: ca.SX, points: ca.SX, params: ca.SX
                   ) -> tuple[ca.SX, ca.SX, ca.SX, ca.SX, ca.SX]:
    """At the pose ``R_t``: ``K``, the twist ``K^-1 q_dot``, and with it ``M``, ``h`` and
    the legs' bias ``K_dot tau`` of the nominal model."""
    row, e = dyn.expressions()
    terms = ca.Function("terms", [row], [e["M"], e["h"], e["K"], e["leg_bias"]])
    zeros = ca.SX.zeros(6)
    K = terms(ca.vertcat(R_t, zeros, zeros, points, params))[2]
    twist = ca.solve(K, qd)
    M, h, K, bias = terms(ca.vertcat(R_t, twist, zeros, points, params))
    return K, twist, M, h, bias


def sx_mechanism_forces(K: ca.SX, M: ca.SX, h: ca.SX, bias: ca.SX, acc: ca.SX,
                        inverse_tolerance: float) -> tuple[ca.SX, ca.SX, ca.SX]:
    """The leg acceleration ``a = K tau_dot + K_dot tau``, the mechanism's forces
    ``K^-T (M tau_dot + h)`` and 1.0 when that solve's residual is below
    ``inverse_tolerance`` relative to its right-hand side (else 0.0; NaN compares
    false)."""
    a = K @ acc + bias
    rhs = M @ acc + h
    f = ca.solve(K.T, rhs)
    inverse_residual = ca.norm_2(K.T @ f - rhs)
    solved = ca.if_else(inverse_residual <= inverse_tolerance * ca.norm_2(rhs) + 1e-12,
                        1.0, 0.0)
    return a, f, solved


def sx_status(fk_residual: ca.SX, tolerance: float, solved: ca.SX, values: ca.SX,
              problem: ca.SX | None = None) -> ca.SX:
    """The step's status code (:class:`controllers.ctc_status.Status`, as a double): the
    input's own ``problem`` code when not 0 (too few rows or legs seen), else
    ``NOT_CONVERGED`` when the pose's residual is not below ``tolerance``, ``NON_FINITE``
    when a value of ``values`` is not finite (their sum of squares, as
    :func:`controllers.ctc_rows.refusal` checked it), ``SINGULAR_INVERSE`` when the
    inverse dynamics' solve is not ``solved``, else 0 (the rank test of the Jacobian is
    the caller's, by LAPACK: :func:`controllers.ctc_rows.rank_condition`)."""
    status = ca.if_else(solved == 1.0, 0.0, float(Status.SINGULAR_INVERSE))
    status = ca.if_else(ca.dot(values, values) <= _DBL_MAX, status, float(Status.NON_FINITE))
    status = ca.if_else(fk_residual < tolerance, status, float(Status.NOT_CONVERGED))
    if problem is not None:
        status = ca.if_else(problem == 0.0, status, problem)
    return status


#: The modules that write the computed-torque steps' expressions (their
#: :func:`~hexapod.compiled.code_key`; a task step's adds its own).
KEY_MODULES = ("controllers.ctc_status", "controllers.law_algebra", "controllers.law_tools",
               "controllers.solvers.compiled_ctc", "controllers.tasks.joint_length",
               "hexapod.layout", "hexapod.dynamics.compiled", "hexapod.dynamics.drive_model",
               "hexapod.fk")


def _build(inverse_tolerance: float) -> ca.Function:
    x = ca.SX.sym("x", INPUTS.size)
    v = INPUTS.split(x)
    pose, q, qd, desired, points = v["pose"], v["q"], v["q_dot"], v["desired"], v["points"]
    q_s, qd_s, qdd_s = desired[0:6], desired[6:12], desired[12:18]
    kp, kd = v["gains"][0], v["gains"][1]
    R_t, residual = sx_encoder_pose(pose, q, points, FK_CALLS)
    K, twist, M, h, bias = sx_model_state(R_t, qd, points, v["params"])
    a_star = qdd_s + kd * (qd_s - K @ twist) + kp * (q_s - q)
    acc = ca.solve(K, a_star - bias)
    a, f, inverse_solved = sx_mechanism_forces(K, M, h, bias, acc, inverse_tolerance)
    f = f + v["rotor"] * a + v["viscous"] * qd + v["coulomb"] * ca.tanh(
        qd_s / COULOMB_SMOOTHING)
    fk_residual = ca.mmax(ca.fabs(residual))
    KtK = K.T @ K
    out = ca.vertcat(R_t, ca.reshape(KtK, 36, 1), f, fk_residual, inverse_solved)
    out = ca.vertcat(out, sx_status(fk_residual, FK_TOLERANCE, inverse_solved, out),
                     rank_screen(KtK))
    return ca.Function("hexapod_ctc_joint_step", [x], [ca.cse(out)])


@lru_cache(maxsize=4)
def joint_step(inverse_tolerance: float = INVERSE_TOLERANCE) -> CompiledFunction:
    """The compiled step (built and compiled on first use; cached on disk).

    Args:
        inverse_tolerance: Relative residual of the inverse solve above which ``K`` is
            taken as singular (as :meth:`hexapod.dynamics.DynamicModel.inverse_batch`).
    """
    tolerance = float(inverse_tolerance)
    return CompiledFunction(partial(_build, tolerance), inputs=INPUTS, outputs=OUTPUTS,
                            key=("hexapod_ctc_joint_step", code_key(KEY_MODULES, tolerance)))


__all__ = ["FK_CALLS", "FK_TOLERANCE", "INPUTS", "MODEL_BLOCKS", "OUTPUTS", "joint_step",
           "sx_encoder_pose", "sx_mechanism_forces", "sx_model_state", "sx_status"]
