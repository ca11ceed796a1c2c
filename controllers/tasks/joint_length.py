"""Joint-length task: ``e_i = q_i - q_i*``, ``L_i = [u_i^T, (A_i x u_i)^T]`` (the rows of
the inverse Jacobian, ``docs/math.md`` section 3), one row per leg.

:func:`joint_length_block` is the one definition of the row: the task evaluates it and
the compiled law cores build their ``J_inv`` (``q_dot = J_inv tau``) from it.
"""

from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np

from controllers.tasks.base import (
    LegBlockTask,
    TaskState,
    evaluate_legs,
    leg_second_order,
    map_blocks,
)


def inverse_jacobian_row(u: ca.SX, base_point: ca.SX) -> ca.SX:
    """``[u^T, (A x u)^T]`` (1, 6): ``q_dot = row tau`` for the platform twist ``tau``.

    Args:
        u: (3, 1) unit leg direction.
        base_point: (3, 1) ``A`` [m].
    """
    return ca.horzcat(u.T, ca.cross(base_point, u).T)


def joint_length_block(length: ca.SX, desired: ca.SX, u: ca.SX, base_point: ca.SX
                       ) -> tuple[ca.SX, ca.SX]:
    """Error ``q - q*`` and Jacobian (:func:`inverse_jacobian_row`) of one leg."""
    return length - desired, inverse_jacobian_row(u, base_point)


@lru_cache(maxsize=1)
def block_function() -> ca.Function:
    """``(q, q*, u, A) -> (e, L)`` of :func:`joint_length_block`."""
    q, qs = ca.SX.sym("q"), ca.SX.sym("q_star")
    u, A = ca.SX.sym("u", 3), ca.SX.sym("A", 3)
    return ca.Function("joint_length_block", [q, qs, u, A],
                       list(joint_length_block(q, qs, u, A)))


@lru_cache(maxsize=1)
def _second_order() -> ca.Function:
    # state (u, q), parameters (A, q*)
    return leg_second_order("joint_length_second_order", 4,
                            lambda s, p: joint_length_block(s[3], p[3], s[:3], p[:3])[0])


class JointLengthTask(LegBlockTask):
    """The six leg lengths towards their desired values.

    Args:
        desired: (6,) or (n, 6) desired lengths ``q*`` [m].
    """

    name = "joint-lengths"
    block = 1

    def __init__(self, desired: np.ndarray) -> None:
        self.desired = np.asarray(desired, dtype=float)

    def _blocks(self, state: TaskState) -> list[np.ndarray]:
        n = len(state)
        return map_blocks(block_function(), state.lengths.reshape(-1),
                          np.broadcast_to(self.desired, (n, 6)).reshape(-1),
                          state.directions.reshape(-1, 3), state.base_points.reshape(-1, 3))

    def jacobian_dot_twist(self, state: TaskState, twist: np.ndarray) -> np.ndarray:
        n = len(state)
        star = np.broadcast_to(self.desired, (n, 6))[..., None]
        p = np.concatenate([state.base_points, star], axis=-1)
        return evaluate_legs(_second_order(), state, p, twist).reshape(n, 6)
