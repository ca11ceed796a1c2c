"""The compiled path of the task-space computed-torque laws.

:class:`CompiledTaskStep` fills the input row of the law's compiled step
(:func:`controllers.solvers.compiled_task_ctc.task_step`: the pose, the dynamics, the
task, the reference's terms, the solve and the leg forces in one C call), calls it and
reads the command. It answers None off the happy path (the law's measurement has no
answer, forward kinematics not converged from the last pose, a rank-deficient task
Jacobian, a singular inverse solve, a non-finite value, fewer than six rows): the
law's numpy path (:meth:`controllers.task_ctc.TaskComputedTorque._command`, the
reference, tested equal) then decides, with its reasons.

A law gives the compiled path its kind and pose source (``compiled_kind``,
``compiled_fk``), its constants (``compiled_constants(step)``) and, each period, its
measurement and reference (``compiled_inputs(step, observation, tr, q)``, returning the
rows to use or None, and a note).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from scipy.linalg.lapack import dsyevd as _eigenvalues

from controllers.base import Command, Observation
from controllers.solvers.compiled_task_ctc import layout, task_step
from hexapod.dynamics.model import INVERSE_TOLERANCE
from hexapod.workspace import home_pose

if TYPE_CHECKING:
    from controllers.task_ctc import TaskComputedTorque

#: Forward-kinematics tolerance on the length residual [m] (as :func:`forward_kinematics`).
FK_TOLERANCE = 1e-12
#: Calls of the compiled step (3 Newton iterations each) before the numpy path takes over.
FK_MAX_CALLS = 16
#: Size of the rigid fit's last Newton step [rad] below which it has converged (the
#: next would be of its square: the fit is exact to rounding).
FIT_TOLERANCE = 1e-8


class CompiledTaskStep:
    """The compiled step of one law (see the module docstring).

    Args:
        law: The law, reset (its context and nominal model built).
    """

    def __init__(self, law: TaskComputedTorque) -> None:
        assert law.context is not None and law.model is not None
        assert law.compiled_kind is not None
        self.kind: str = law.compiled_kind
        self.fk: bool = law.compiled_fk
        self.function = task_step(self.kind, self.fk, INVERSE_TOLERANCE)
        self.inputs, self.outputs = layout(self.kind, self.fk)
        self.row = np.zeros(self.function.n_in)
        g = law.context.geometry
        d = g.drives
        self.set("points", np.concatenate([g.base_points.ravel(),
                                           g.platform_points.ravel()]))
        self.set("params", law.model.parameters)
        for name in ("rotor_inertia", "viscous", "coulomb"):
            self.set(name.split("_")[0], np.broadcast_to(
                np.asarray(getattr(d, name), dtype=float), (6,)))
        self.set("gains", np.array([law.gains.kp, law.gains.kd, float(law.context.dt)]))
        self.home = home_pose(g)
        law.compiled_constants(self)

    def set(self, name: str, value: np.ndarray | float) -> None:
        """Write an input field (:func:`~controllers.solvers.compiled_task_ctc.layout`)."""
        self.row[self.inputs[name]] = value

    def set_pose(self, R: np.ndarray, t: np.ndarray) -> None:
        """The input pose (the FK guess, or the measured pose)."""
        self.row[0:9] = R.T.ravel()
        self.row[9:12] = t

    def step(self, law: TaskComputedTorque, observation: Observation, tr: float,
             q: np.ndarray, qd: np.ndarray) -> Command | None:
        """The command of this period, or None off the happy path."""
        R0, t0 = law.guess if law.guess is not None else self.home
        self.set_pose(R0, t0)
        prepared = law.compiled_inputs(self, observation, tr, q)
        if prepared is None:
            return None
        rows, note = prepared
        if rows is not None and int(rows.sum()) < 6:
            return None
        row, out = self.row, self.outputs
        row[self.inputs["q"]] = q
        row[self.inputs["q_dot"]] = qd
        y = self.function.single(row)
        residual = out["fk_residual"].start
        tolerance = FK_TOLERANCE if self.fk else FIT_TOLERANCE
        calls = 1
        while not y[residual] < tolerance:
            if calls >= FK_MAX_CALLS or not math.isfinite(float(y[residual])):
                return None
            row[0:12] = y[0:12]
            y = self.function.single(row)
            calls += 1
        if y[out["solved"].start] != 1.0 or not math.isfinite(float(y @ y)):
            return None
        # the squared singular values of the masked Jacobian (LAPACK syevd of L^T L)
        w, _, info = _eigenvalues(y[out["factor"]].reshape(6, 6), compute_v=0)
        if info != 0 or not (w[-1] > 0 and w[0] > law.solver.threshold**2 * w[-1]):
            return None
        law.guess = (y[0:9].reshape(3, 3).T, y[9:12])
        e = y[out["error"]]
        if rows is not None:
            e = e[rows]
        return Command.of_forces(y[out["forces"]], error=e,
                                 error_norm=math.sqrt(float(e @ e)), rank=6,
                                 condition=math.sqrt(float(w[-1] / w[0])),
                                 features_used=len(e),
                                 notes=[] if note is None else [note])


__all__ = ["FIT_TOLERANCE", "FK_MAX_CALLS", "FK_TOLERANCE", "CompiledTaskStep"]
