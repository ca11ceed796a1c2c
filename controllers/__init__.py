"""Controllers: turn observations into leg commands behind one plugin interface.

The built-ins (:data:`BUILTIN_SPECS`, registered in :data:`controllers.registry.registry`;
``docs/plugins.md`` and ``docs/dynamic-world.md`` describe them): the vision laws
``leg-direction`` and ``leg-edge`` (seeds 001-003), their limit QPs ``-qp`` (OSQP) and
predictive controllers ``-mpc`` (CasADi, DAQP; falling back to the QPs); the baselines
``model-based`` and ``joint-space``; the force laws ``computed-torque``,
``cartesian-ctc``, ``vision-ctc``, ``leg-edge-ctc``, ``leg-direction-ctc`` and the
force-level predictive ``leg-edge-force-mpc``, ``pose-force-mpc``; and
``latency-compensated`` (any of them fed the features predicted over the image's delay).

The vision laws are (task, solver) pairs: the features are tasks
(:mod:`controllers.tasks`), the pseudo-inverse and the limit QP are solvers
(:mod:`controllers.solvers`), and what a law carries between periods is an estimator
dataclass (:mod:`controllers.estimators`). A controller says what it commands
(:class:`Actuation`: leg velocities, or leg forces).
"""

from typing import TYPE_CHECKING

from controllers.base import Controller
from controllers.data import Command, ControllerContext, Goal, Observation, observation_problem
from controllers.registry import Registry, registry
from hexapod.actuation import Actuation
from hexapod.lazy import lazy_names

if TYPE_CHECKING:  # imported on first use (module __getattr__ below)
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

#: The built-in controllers, by registry name: the ``module:attr`` of each class. A
#: module is imported when its controller is first used (``import controllers`` imports
#: no MPC, computed torque, OSQP or Pinocchio for a study that steps a kinematic law).
BUILTIN_SPECS = {
    "leg-direction": "controllers.leg_direction:LegDirectionController",
    "leg-edge": "controllers.leg_edge:LegEdgeController",
    "leg-edge-qp": "controllers.qp:LegEdgeQPController",
    "leg-direction-qp": "controllers.qp:LegDirectionQPController",
    "leg-edge-mpc": "controllers.mpc:LegEdgeMPCController",
    "leg-direction-mpc": "controllers.mpc:LegDirectionMPCController",
    "model-based": "controllers.model_based:ModelBasedController",
    "joint-space": "controllers.joint:JointSpaceController",
    "computed-torque": "controllers.computed_torque:ComputedTorqueController",
    "cartesian-ctc": "controllers.cartesian_ctc:CartesianCTC",
    "vision-ctc": "controllers.cartesian_ctc:VisionCTC",
    "leg-edge-ctc": "controllers.feature_ctc:LegEdgeCTC",
    "leg-direction-ctc": "controllers.feature_ctc:LegDirectionCTC",
    "leg-edge-force-mpc": "controllers.force_mpc:LegEdgeForceMPC",
    "pose-force-mpc": "controllers.force_mpc:PoseForceMPC",
    "latency-compensated": "controllers.latency:LatencyCompensated",
}

#: The module of each class re-exported here (imported on first access).
_LAZY_CLASSES = {spec.rpartition(":")[2]: spec.partition(":")[0]
                 for spec in BUILTIN_SPECS.values()}

for _name, _spec in BUILTIN_SPECS.items():
    registry.register_lazy(_name, _spec)


#: The built-in classes re-exported here (and the submodules), imported on first access.
__getattr__ = lazy_names(__name__, _LAZY_CLASSES, globals())


__all__ = [
    "BUILTIN_SPECS",
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
