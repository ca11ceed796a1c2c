"""Force-level predictive control (issue 37) in CasADi, ``leg-edge-force-mpc`` and
``pose-force-mpc``: the prediction and QP data compiled to C
(:mod:`~controllers.force_mpc.problem`), the receding horizon falling back to the held
computed-torque law (:mod:`~controllers.force_mpc.controller`) and the two feature sets
(:mod:`~controllers.force_mpc.variants`).
"""

from controllers.force_mpc.controller import ForceMPCLaw
from controllers.force_mpc.variants import LegEdgeForceMPC, PoseForceMPC

__all__ = ["ForceMPCLaw", "LegEdgeForceMPC", "PoseForceMPC"]
