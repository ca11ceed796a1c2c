"""Visual predictive control (Allibert, Courtial & Chaumette, IEEE T-RO 2010) in CasADi:
the prediction models (:mod:`~controllers.mpc.prediction`), the condensed Gauss-Newton
QP compiled to C (:mod:`~controllers.mpc.problem`), the QP and SQP solves and the base
both predictive families share (:mod:`~controllers.mpc.solver`), and ``leg-edge-mpc``,
``leg-direction-mpc`` (:mod:`~controllers.mpc.controller`).
"""

from controllers.mpc.controller import LegDirectionMPCController, LegEdgeMPCController, MPCLaw
from controllers.mpc.solver import SolveStats

__all__ = [
    "LegDirectionMPCController",
    "LegEdgeMPCController",
    "MPCLaw",
    "SolveStats",
]
