"""Visual predictive control (Allibert, Courtial & Chaumette, IEEE T-RO 2010) in CasADi.

- :mod:`controllers.mpc.prediction`: the local and global prediction models (their
  CasADi blocks, the pose fit);
- :mod:`controllers.mpc.problem`: the condensed Gauss-Newton QP (single shooting),
  its data computed by one compiled C function;
- :mod:`controllers.mpc.solver`: the QP (unconstrained shortcut, DAQP generated to
  C), the SQP iterations and the base both predictive families share;
- :mod:`controllers.mpc.controller`: ``leg-edge-mpc`` and ``leg-direction-mpc``
  (receding horizon, warm start, fallback to the one-step QP law).
"""

from controllers.mpc.controller import LegDirectionMPCController, LegEdgeMPCController, MPCLaw
from controllers.mpc.solver import SolveStats

__all__ = [
    "LegDirectionMPCController",
    "LegEdgeMPCController",
    "MPCLaw",
    "SolveStats",
]
