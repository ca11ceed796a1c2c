"""Solvers: what turns one period's tasks into a command.

In the manner of Pink's solver: a task (:mod:`controllers.tasks`, or the stacked
:class:`~controllers.law_tools.TaskStep` a vision law builds from them) says what to regulate;
a solver says how. A controller is a (task, solver) pair: ``leg-edge`` is the leg-edge
task with :class:`DampedPseudoInverse`, ``leg-edge-qp`` the same task with
:class:`LimitQPSolver`, ``leg-edge-mpc`` the predictive controller
(:mod:`controllers.mpc`) over the same task, falling back to the limit QP.

- :class:`DampedPseudoInverse` (:mod:`~controllers.solvers.pseudo_inverse`):
  ``tau = -lambda (L^T L + mu^2 I)^+ L^T e`` with the adaptive gain ``lambda``;
- :class:`LimitQPSolver` (:mod:`~controllers.solvers.limit_qp`): the same objective
  under stroke and leg-speed bounds, OSQP (:mod:`~controllers.solvers.osqp_limits`);
- the predictive controller: :mod:`controllers.mpc` (horizon, SQP, DAQP), which takes
  the tasks of its fallback law (:meth:`~controllers.laws.VisionLaw.tasks`).

The computed-torque solver (:mod:`~controllers.solvers.computed_torque`) is second
order: from a task's error dynamics it chooses the platform acceleration and maps it
through the nominal dynamic model to leg forces (the ``*-ctc`` laws).
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
