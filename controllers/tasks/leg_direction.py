"""Leg-direction task (seeds 001/003): ``e_i = u_i x u_i*``, ``L_i = -[u_i*]_x M_i``
(``docs/math.md`` sections 3 and 6), one 3-row block per leg."""

from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np

from controllers.interaction import cross, direction_task
from controllers.tasks.base import Task, TaskState, evaluate_legs, leg_second_order


@lru_cache(maxsize=1)
def _second_order() -> ca.Function:
    # parameters (A, u*)
    return leg_second_order("leg_direction_second_order", 6,
                            lambda s, p: ca.cross(s[:3], p[3:6]))


class LegDirectionTask(Task):
    """The six leg directions towards their desired values.

    Args:
        desired: (6, 3) or (n, 6, 3) desired unit directions ``u_i*``.
    """

    name = "leg-directions"

    def __init__(self, desired: np.ndarray) -> None:
        self.desired = np.asarray(desired, dtype=float)

    def _star(self, n: int) -> np.ndarray:
        return np.broadcast_to(self.desired, (n, 6, 3))

    def error(self, state: TaskState) -> np.ndarray:
        n = len(state)
        return cross(state.directions, self._star(n)).reshape(n, 18)

    def jacobian(self, state: TaskState) -> np.ndarray:
        n = len(state)
        _, L = direction_task(state.directions.reshape(-1, 3),
                              np.ascontiguousarray(self._star(n)).reshape(-1, 3),
                              state.base_points.reshape(-1, 3), state.lengths.reshape(-1),
                              error=False)
        return L.reshape(n, 18, 6)

    def jacobian_dot_twist(self, state: TaskState, twist: np.ndarray) -> np.ndarray:
        n = len(state)
        p = np.concatenate([state.base_points, self._star(n)], axis=-1)
        return evaluate_legs(_second_order(), state, p, twist).reshape(n, 18)
