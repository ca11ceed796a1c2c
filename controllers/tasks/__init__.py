"""Tasks: one feature each, as a pure object (error, Jacobian, second-order term), in
the manner of Pink's tasks (``docs/plugins.md``, "Adding a task"), batched over a leading
trial axis: :class:`LegEdgeTask`, :class:`JointLengthTask`, :class:`PlatformPoseTask` and
the :class:`FeatureTask` of any :class:`LegFeature` (:data:`LEG_DIRECTIONS`, a plugin's).
The built-in features are objects (:mod:`controllers.tasks.feature_kind`).
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
