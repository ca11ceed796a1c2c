"""Controllers: turn observations into leg velocities behind one plugin interface.

Built-in controllers are registered in :data:`controllers.registry.registry` here:

- ``leg-direction``: leg directions, ``u x u*`` (seeds 001/003);
- ``leg-edge``: leg edges, pixel lines or normals (seeds 002/003);
- ``leg-edge-qp``, ``leg-direction-qp``: the same features with the QP of
  ``docs/math.md`` section 6 (stroke and leg-speed limits, OSQP);
- ``leg-edge-mpc``, ``leg-direction-mpc``: visual predictive control over a
  horizon (local or global prediction model, strokes, speeds, visibility and
  tilt constraints; CasADi, DAQP), falling back to the QP laws;
- ``model-based``: forward kinematics of the nominal model + pose servoing;
- ``joint-space``: leg lengths to the nominal inverse kinematics of the goal;
- ``computed-torque``: joint-space computed torque on the encoder lengths with the
  nominal dynamic model, commanding leg forces (the dynamic world only);
- ``cartesian-ctc``, ``vision-ctc``: Cartesian computed torque on the platform pose, from
  the encoders' forward kinematics or from the legs the camera sees (Paccot et al. 2008);
- ``leg-edge-ctc``, ``leg-direction-ctc``: computed torque in the space of the leg
  features (Özgür et al. 2011), all on the computed-torque solver
  (:mod:`controllers.solvers.computed_torque`);
- ``leg-edge-force-mpc``, ``pose-force-mpc``: force-level predictive controllers on the
  leg edges or on the platform pose (the nominal closed-chain dynamics over a horizon,
  the drives' force limits as bounds; CasADi, DAQP), falling back to ``leg-edge-ctc`` or
  ``cartesian-ctc``;
- ``latency-compensated``: any of them (``law``) fed the image features predicted over
  the image's delay with the nominal model (:mod:`controllers.latency`).

The vision laws are (task, solver) pairs: the features are tasks
(:mod:`controllers.tasks`), the pseudo-inverse and the limit QP are solvers
(:mod:`controllers.solvers`), and what a law carries between periods is an estimator
dataclass (:mod:`controllers.estimators`). A controller says what it commands
(:class:`Actuation`: leg velocities, or leg forces).
"""

from controllers.base import (
    Actuation,
    Command,
    Controller,
    ControllerContext,
    Goal,
    Observation,
    Registry,
    observation_problem,
    registry,
)
from controllers.cartesian_ctc import CartesianCTC, VisionCTC
from controllers.computed_torque import ComputedTorqueController
from controllers.feature_ctc import LegDirectionCTC, LegEdgeCTC
from controllers.force_mpc import LegEdgeForceMPC, PoseForceMPC
from controllers.joint import JointSpaceController
from controllers.latency import LatencyCompensated
from controllers.leg_direction import LegDirectionController
from controllers.leg_edge import LegEdgeController
from controllers.model_based import ModelBasedController
from controllers.mpc import LegDirectionMPCController, LegEdgeMPCController
from controllers.qp import LegDirectionQPController, LegEdgeQPController

#: The built-in controllers, by registry name.
BUILTINS = {
    "leg-direction": LegDirectionController,
    "leg-edge": LegEdgeController,
    "leg-edge-qp": LegEdgeQPController,
    "leg-direction-qp": LegDirectionQPController,
    "leg-edge-mpc": LegEdgeMPCController,
    "leg-direction-mpc": LegDirectionMPCController,
    "model-based": ModelBasedController,
    "joint-space": JointSpaceController,
    "computed-torque": ComputedTorqueController,
    "cartesian-ctc": CartesianCTC,
    "vision-ctc": VisionCTC,
    "leg-edge-ctc": LegEdgeCTC,
    "leg-direction-ctc": LegDirectionCTC,
    "leg-edge-force-mpc": LegEdgeForceMPC,
    "pose-force-mpc": PoseForceMPC,
    "latency-compensated": LatencyCompensated,
}

for _name, _factory in BUILTINS.items():
    registry.register(_name, _factory)

__all__ = [
    "BUILTINS",
    "Actuation",
    "CartesianCTC",
    "Command",
    "ComputedTorqueController",
    "Controller",
    "ControllerContext",
    "Goal",
    "JointSpaceController",
    "LatencyCompensated",
    "LegDirectionCTC",
    "LegDirectionController",
    "LegDirectionMPCController",
    "LegDirectionQPController",
    "LegEdgeCTC",
    "LegEdgeController",
    "LegEdgeForceMPC",
    "LegEdgeMPCController",
    "LegEdgeQPController",
    "ModelBasedController",
    "Observation",
    "PoseForceMPC",
    "Registry",
    "VisionCTC",
    "observation_problem",
    "registry",
]
