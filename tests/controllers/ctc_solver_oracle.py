"""The numpy second-order solve and the central differences of a moving reference: the
test oracles of the computed-torque laws' compiled steps and of the tasks' analytic
reference terms.

The laws solve ``tau_dot = L^+ (-2 zeta omega_n e_dot - omega_n^2 e - L_dot tau - e_tt)``
inside their compiled functions (:mod:`controllers.solvers.compiled_ctc`,
:mod:`controllers.solvers.compiled_task_ctc`); :func:`acceleration` is that solve by an
SVD in numpy, the one they replaced. :func:`reference_terms` differentiates a task along
its reference numerically, the check of :meth:`controllers.tasks.Task.reference_terms`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from controllers.solvers.computed_torque import ComputedTorqueSolver
from controllers.tasks.base import Task, TaskState

#: Time step of the central differences of a task along its reference [s].
REFERENCE_STEP = 1e-3


@dataclass
class Acceleration:
    """The solver's platform acceleration and its diagnostics.

    Attributes:
        acc: (6,) ``tau_dot`` (model coordinates) [m/s^2, rad/s^2], zeros when refused.
        error_rate: (m,) ``e_dot``.
        rank: Rank of ``L``.
        condition: Its condition number (inf when rank-deficient).
        reason: Why it is refused (None when valid).
    """

    acc: np.ndarray
    error_rate: np.ndarray
    rank: int
    condition: float
    reason: str | None = None


def acceleration(solver: ComputedTorqueSolver, error: np.ndarray, jacobian: np.ndarray,
                 ldot_tau: np.ndarray, twist: np.ndarray, error_t: np.ndarray | None = None,
                 error_tt: np.ndarray | None = None, damping: float = 0.0) -> Acceleration:
    """``tau_dot`` giving the designed ``e_ddot`` (least squares over the rows given;
    refused when ``L`` loses rank, or damped, ``(L^T L + mu^2 I)^-1 L^T``, when a damping
    ``mu`` is set).

    Args:
        solver: The law's solver (its gains and rank threshold).
        error: (m,) ``e``.
        jacobian: (m, 6) ``L`` (model coordinates).
        ldot_tau: (m,) ``L_dot tau``.
        twist: (6,) ``tau`` (model coordinates).
        error_t: (m,) ``e_t`` of the reference's motion (None: a fixed reference).
        error_tt: (m,) ``e_tt`` (None: zeros).
        damping: ``mu`` of a damped least squares (0: refuse a rank-deficient ``L``).
    """
    e = np.asarray(error, dtype=float)
    L = np.asarray(jacobian, dtype=float)
    e_dot = L @ twist + (0.0 if error_t is None else error_t)
    rhs = -solver.gains.kd * e_dot - solver.gains.kp * e - ldot_tau
    if error_tt is not None:
        rhs = rhs - error_tt
    if L.shape[0] == 0:
        return Acceleration(np.zeros(6), e_dot, 0, math.inf, "no task rows")
    U, s, Vt = np.linalg.svd(L, full_matrices=False)
    rank = int(np.sum(s > solver.threshold * s[0])) if s[0] > 0 else 0
    cond = float(s[0] / s[-1]) if s[-1] > 0 else math.inf
    if rank < 6 and damping == 0.0:
        return Acceleration(np.zeros(6), e_dot, rank, cond,
                            f"task Jacobian of rank {rank} < 6 "
                            f"({L.shape[0]} rows, condition {cond:.3g})")
    inv = s / (s * s + damping**2)
    acc = Vt.T @ (inv * (U.T @ rhs))
    return Acceleration(acc, e_dot, rank, cond)


def reference_terms(task_at: Callable[[int], Task], state: TaskState, twist: np.ndarray,
                    step: float = REFERENCE_STEP) -> tuple[np.ndarray, np.ndarray]:
    """``e_t`` and ``e_tt`` of a task whose desired value moves, by central differences.

    With ``e(s, t)`` the task error at the state ``s`` and the reference at ``t``:
    ``e_t = de/dt`` and ``e_tt = d2e/dt2 + 2 d(L tau)/dt``, the state held
    (``e_ddot = L tau_dot + L_dot tau + e_tt``).

    Args:
        task_at: ``task_at(k)`` the task with the reference at ``t + k step`` for
            ``k`` in (-1, 0, 1).
        state: One state row.
        twist: (6,) the task's twist ``tau`` (of its own frame).
        step: ``step`` [s].
    """
    tasks = {k: task_at(k) for k in (-1, 0, 1)}
    e = {k: tasks[k].error(state)[0] for k in (-1, 0, 1)}
    Lp = tasks[1].jacobian(state)[0]
    Lm = tasks[-1].jacobian(state)[0]
    e_t = (e[1] - e[-1]) / (2 * step)
    e_tt = (e[1] - 2 * e[0] + e[-1]) / step**2 + (Lp - Lm) @ twist / step
    return e_t, e_tt
