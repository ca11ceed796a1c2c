"""Solvers: what turns one period's tasks into a command, in the manner of Pink's solver.

A task (:mod:`controllers.tasks`, or the stacked :class:`~controllers.law_tools.TaskStep`
a vision law builds) says what to regulate, a solver how: ``leg-edge`` is the leg-edge
task with :class:`DampedPseudoInverse` (``tau = -lambda (L^T L + mu^2 I)^+ L^T e``),
``leg-edge-qp`` with :class:`LimitQPSolver` (stroke and leg-speed bounds, OSQP),
``leg-edge-mpc`` the predictive controller (:mod:`controllers.mpc`) over the same tasks.
The computed-torque solver (:mod:`~controllers.solvers.computed_torque`) is second order:
it maps a task's chosen acceleration through the nominal dynamic model to leg forces.
"""

from typing import TYPE_CHECKING

from controllers.solvers.base import Solved, Solver
from controllers.solvers.pseudo_inverse import DampedPseudoInverse
from hexapod.lazy import lazy_names

if TYPE_CHECKING:  # imported on first access (OSQP and SciPy: __getattr__ below)
    from controllers.solvers.limit_qp import LimitQPSolver, StrokeWindow, velocity_bounds

#: Names of :mod:`controllers.solvers.limit_qp` re-exported here, imported on first
#: access: OSQP (and the SciPy it imports) only for a law that builds a QP.
_LIMIT_QP = ("LimitQPSolver", "StrokeWindow", "velocity_bounds")


__getattr__ = lazy_names(__name__, dict.fromkeys(_LIMIT_QP, "controllers.solvers.limit_qp"),
                         globals())


__all__ = ["DampedPseudoInverse", "LimitQPSolver", "Solved", "Solver", "StrokeWindow",
           "velocity_bounds"]
