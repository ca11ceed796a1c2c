"""Force-level predictive control (issue 37) in CasADi: ``leg-edge-force-mpc`` and its
pose variant ``pose-force-mpc``.

- :mod:`controllers.force_mpc.problem`: the prediction (the nominal closed-chain
  dynamics with the drives' friction and rotor inertia, integrated as the dynamic world
  integrates them) and the condensed Gauss-Newton QP data, one compiled C function;
- :mod:`controllers.force_mpc.controller`: the receding horizon (warm start,
  real-time iteration, the drives' force limits as bounds, DAQP), falling back to
  ``leg-edge-ctc`` (``cartesian-ctc`` for the pose variant);
- :mod:`controllers.force_mpc.variants`: the two feature sets (the edges, the pose).
"""

from controllers.force_mpc.controller import ForceMPCLaw
from controllers.force_mpc.variants import LegEdgeForceMPC, PoseForceMPC

__all__ = ["ForceMPCLaw", "LegEdgeForceMPC", "PoseForceMPC"]
