"""Joint-length task: ``e_i = q_i - q_i*``, ``L_i = [u_i^T, (A_i x u_i)^T]`` (the rows of
the inverse Jacobian, ``docs/math.md`` section 3), one row per leg."""

from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np

from controllers.interaction import cross
from controllers.tasks.base import Task, TaskState, evaluate_legs, leg_second_order


@lru_cache(maxsize=1)
def _second_order() -> ca.Function:
    # parameters (A, q*)
    return leg_second_order("joint_length_second_order", 4, lambda s, p: s[3] - p[3])


class JointLengthTask(Task):
    """The six leg lengths towards their desired values.

    Args:
        desired: (6,) or (n, 6) desired lengths ``q*`` [m].
    """

    name = "joint-lengths"
    block = 1

    def __init__(self, desired: np.ndarray) -> None:
        self.desired = np.asarray(desired, dtype=float)

    def error(self, state: TaskState) -> np.ndarray:
        return state.lengths - self.desired

    def jacobian(self, state: TaskState) -> np.ndarray:
        u = state.directions
        return np.concatenate([u, cross(state.base_points, u)], axis=-1)

    def jacobian_dot_twist(self, state: TaskState, twist: np.ndarray) -> np.ndarray:
        n = len(state)
        star = np.broadcast_to(self.desired, (n, 6))[..., None]
        p = np.concatenate([state.base_points, star], axis=-1)
        return evaluate_legs(_second_order(), state, p, twist).reshape(n, 6)
