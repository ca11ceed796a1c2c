"""The limit-QP laws (``docs/math.md`` section 6): the leg-edge and leg-direction laws
with :class:`~controllers.solvers.limit_qp.LimitQPSolver` (stroke, with a margin, and
leg-speed limits, OSQP) in place of the damped pseudo-inverse."""

from __future__ import annotations

from collections.abc import Sequence

from controllers.leg_direction import LegDirectionController
from controllers.leg_edge import LegEdgeController
from controllers.solvers.limit_qp import LimitQPSolver


class LegEdgeQPController(LegEdgeController):
    """Leg-edge law as a QP with stroke (with a margin) and leg-speed limits (OSQP).

    Takes the options of :class:`~controllers.leg_edge.LegEdgeController` and those of
    :class:`~controllers.solvers.limit_qp.LimitQPSolver` (documented there).
    """

    name = "leg-edge-qp"
    OPTION_DOCS = (LimitQPSolver,)

    def __init__(self, gain: float = 1.0, adaptive_gain: Sequence[float] | None = None,
                 interaction: str = "current", threshold: float = 1e-6, damping: float = 0.0,
                 edge_feature: str = "auto", regularization: float = 1e-12,
                 stroke_margin: float | None = None, max_speed: float | None = None,
                 eps_abs: float = 1e-6, eps_rel: float = 1e-6, max_iter: int = 4000,
                 shortcut: bool | None = None, compiled: bool = True,
                 leg_rate_feedforward: bool = False) -> None:
        LegEdgeController.__init__(self, gain, adaptive_gain, interaction, threshold, damping,
                                   edge_feature, compiled, leg_rate_feedforward)
        self.solver = LimitQPSolver(self.name, self.threshold, regularization, stroke_margin,
                                    max_speed, eps_abs, eps_rel, max_iter, shortcut, damping)


class LegDirectionQPController(LegDirectionController):
    """Leg-direction law as a QP with stroke (with a margin) and leg-speed limits (OSQP).

    Takes the options of :class:`~controllers.leg_direction.LegDirectionController` and
    those of :class:`~controllers.solvers.limit_qp.LimitQPSolver` (documented there).
    """

    name = "leg-direction-qp"
    OPTION_DOCS = (LimitQPSolver,)

    def __init__(self, gain: float = 1.0, adaptive_gain: Sequence[float] | None = None,
                 interaction: str = "current", threshold: float = 1e-6, damping: float = 0.0,
                 regularization: float = 1e-12, stroke_margin: float | None = None,
                 max_speed: float | None = None, eps_abs: float = 1e-6, eps_rel: float = 1e-6,
                 max_iter: int = 4000, shortcut: bool | None = None, compiled: bool = True,
                 leg_rate_feedforward: bool = False) -> None:
        LegDirectionController.__init__(self, gain, adaptive_gain, interaction, threshold,
                                        damping, compiled, leg_rate_feedforward)
        self.solver = LimitQPSolver(self.name, self.threshold, regularization, stroke_margin,
                                    max_speed, eps_abs, eps_rel, max_iter, shortcut, damping)
