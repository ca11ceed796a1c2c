"""Tasks: one feature each, as a pure object (error, Jacobian, second-order term).

In the manner of Pink's tasks (``docs/plugins.md``, "Adding a task"): a task knows its
feature, never how it is solved; a solver (the damped pseudo-inverse of
:mod:`controllers.laws`, the limit QP of :mod:`controllers.qp`, the predictive
controller of :mod:`controllers.mpc`, the computed-torque solver of
:mod:`controllers.solvers.computed_torque`) combines
tasks. Every method is batched over a leading trial axis.

- ``LEG_DIRECTIONS.task_of(u*)``: ``u x u*`` (seeds 001/003), a :class:`FeatureTask`;
- :class:`LegEdgeTask`: ``n x n*`` or ``l x l*`` (seeds 002/003);
- :class:`JointLengthTask`: ``q - q*``;
- :class:`PlatformPoseTask`: ``(t - t*, log(R R*^T))``;
- :class:`LegFeature`: any feature of each leg written once as a CasADi expression (the
  leg directions :data:`~controllers.tasks.leg_direction.LEG_DIRECTIONS`, a plugin's
  own), with :class:`FeatureTask` its task (``docs/plugins.md``, "Adding a feature").

The built-in features are objects (:mod:`controllers.tasks.feature_kind`):
:data:`EDGE_NORMALS`, :data:`EDGE_LINES`, :data:`LEG_DIRECTIONS` and
:data:`PLATFORM_POSE` own their blocks, sizes, observation fields and kernel names; the
controllers' builders take them (no kind strings).
"""

from controllers.tasks.base import Task, TaskState
from controllers.tasks.feature_kind import BuiltinFeature
from controllers.tasks.joint_length import JointLengthTask
from controllers.tasks.leg_direction import LEG_DIRECTIONS
from controllers.tasks.leg_edge import EDGE_LINES, EDGE_NORMALS, EdgeFeature, LegEdgeTask
from controllers.tasks.leg_feature import FeatureTask, LegFeature
from controllers.tasks.platform_pose import PLATFORM_POSE, PlatformPoseTask

#: The built-in feature objects.
BUILTIN_FEATURES = (EDGE_NORMALS, EDGE_LINES, LEG_DIRECTIONS, PLATFORM_POSE)

__all__ = ["BUILTIN_FEATURES", "EDGE_LINES", "EDGE_NORMALS", "LEG_DIRECTIONS", "PLATFORM_POSE",
           "BuiltinFeature", "EdgeFeature", "FeatureTask", "JointLengthTask", "LegEdgeTask",
           "LegFeature", "PlatformPoseTask", "Task", "TaskState"]
