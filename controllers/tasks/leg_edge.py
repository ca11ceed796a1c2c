"""Leg-edge task (seeds 002/003), two 3-row blocks per leg (``docs/math.md`` section 6):

- normals (interpretation planes, any camera): ``e = n x n*``, ``L = -[n*]_x H M_i``;
- image lines (perspective camera, ``l ∝ K^-T n``): ``e = l x l*``,
  ``L = -[l*]_x J_l H M_i``.

The Jacobians are the rank-one blocks of :mod:`controllers.interaction`; the motion of
a normal is ``n_dot = H M_i tau = -z (g^T tau)``.
"""

from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np

from controllers.interaction import cross, edge_line_task, edge_normal_task
from controllers.tasks.base import (
    Task,
    TaskState,
    evaluate_blocks,
    leg_rates,
    second_order_function,
    unit,
)

#: Edge feature kinds.
EDGE_KINDS = ("normals", "lines")


def _unit(x: ca.SX) -> ca.SX:
    return x / ca.sqrt(ca.dot(x, x))


def _edge_state_rate(s: ca.SX, p: ca.SX, tau: ca.SX) -> ca.SX:
    """``(n_dot, u_dot, q_dot)`` of an edge normal and its leg."""
    n, u, q, A = s[:3], s[3:6], s[6], p[:3]
    udot, qdot = leg_rates(u, A, q, tau)
    w = ca.cross(u, n)
    z = u - w * (ca.dot(A, u) / ca.dot(A, w))
    r = n - ca.dot(n, u) * u
    B = A + q * u
    g_tau = (ca.dot(r, tau[:3]) + ca.dot(ca.cross(B, r), tau[3:])) / q
    return ca.vertcat(-z * g_tau, udot, qdot)


@lru_cache(maxsize=2)
def _second_order(kind: str) -> ca.Function:
    # state (n, u, q), parameters (A, desired, K^-T row-major)
    def error(s: ca.SX, p: ca.SX) -> ca.SX:
        n = s[:3]
        if kind == "lines":
            Kit = ca.reshape(p[6:15], 3, 3).T
            n = _unit(Kit @ n)
        return ca.cross(n, p[3:6])

    return second_order_function(f"leg_edge_{kind}_second_order", 7, 15, error,
                                 _edge_state_rate)


class LegEdgeTask(Task):
    """The twelve leg edges (two per leg, ``(6, 2)`` order) towards their desired values.

    Args:
        desired: (6, 2, 3) or (n, 6, 2, 3) desired normals (``kind="normals"``) or
            unit image lines (``kind="lines"``).
        kind: ``"normals"`` or ``"lines"``.
        line_matrix: (3, 3) ``K`` of the perspective camera (lines only).
    """

    name = "leg-edges"

    def __init__(self, desired: np.ndarray, kind: str = "normals",
                 line_matrix: np.ndarray | None = None) -> None:
        if kind not in EDGE_KINDS:
            raise ValueError(f"kind: expected one of {', '.join(EDGE_KINDS)}, got {kind!r}")
        if kind == "lines" and line_matrix is None:
            raise ValueError("kind 'lines' needs the camera's line_matrix")
        self.desired = np.asarray(desired, dtype=float)
        self.kind = kind
        self.line_matrix = np.eye(3) if line_matrix is None else np.asarray(line_matrix, float)
        self.line_matrix_inv_t = np.linalg.inv(self.line_matrix).T

    def features(self, state: TaskState) -> np.ndarray:
        """(n, 6, 2, 3) the measured features of the state: its normals, or their lines."""
        if state.normals is None:
            raise ValueError("LegEdgeTask needs the state's normals")
        if self.kind == "lines":
            return unit(state.normals @ self.line_matrix_inv_t.T)
        return state.normals

    def _star(self, n: int) -> np.ndarray:
        return np.ascontiguousarray(np.broadcast_to(self.desired, (n, 6, 2, 3)))

    def error(self, state: TaskState) -> np.ndarray:
        n = len(state)
        return cross(self.features(state), self._star(n)).reshape(n, 36)

    def _per_edge(self, state: TaskState) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        u2 = np.repeat(state.directions, 2, axis=-2).reshape(-1, 3)
        A2 = np.repeat(state.base_points, 2, axis=-2).reshape(-1, 3)
        q2 = np.repeat(state.lengths, 2, axis=-1).reshape(-1)
        return u2, A2, q2

    def jacobian(self, state: TaskState) -> np.ndarray:
        n = len(state)
        u2, A2, q2 = self._per_edge(state)
        normals = self.features(state) if self.kind == "normals" else state.normals
        assert normals is not None
        star = self._star(n).reshape(-1, 3)
        if self.kind == "lines":
            L = edge_line_task(self.features(state).reshape(-1, 3), star,
                               normals.reshape(-1, 3), u2, A2, q2, self.line_matrix,
                               self.line_matrix_inv_t)
        else:
            L = edge_normal_task(normals.reshape(-1, 3), star, u2, A2, q2)
        return L.reshape(n, 36, 6)

    def jacobian_dot_twist(self, state: TaskState, twist: np.ndarray) -> np.ndarray:
        n = len(state)
        if state.normals is None:
            raise ValueError("LegEdgeTask needs the state's normals")
        u2, A2, q2 = self._per_edge(state)
        s = np.concatenate([state.normals.reshape(-1, 3), u2, q2[:, None]], axis=1)
        kit = np.broadcast_to(self.line_matrix_inv_t.reshape(9), (12 * n, 9))
        p = np.concatenate([A2, self._star(n).reshape(-1, 3), kit], axis=1)
        tau = np.repeat(np.asarray(twist, dtype=float).reshape(n, 6), 12, axis=0)
        return evaluate_blocks(_second_order(self.kind), s, p, tau).reshape(n, 36)
