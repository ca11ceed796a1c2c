"""Leg-edge task (seeds 002/003), two 3-row blocks per leg (``docs/math.md`` section 6):

- normals (interpretation planes, any camera): ``e = n x n*``, ``L = -[n*]_x H M_i``;
- image lines (perspective camera, ``l ∝ K^-T n``): ``e = l x l*``,
  ``L = -[l*]_x J_l H M_i``.

:func:`edge_block` is the one definition of an edge's block (the rank-one ``L = a g^T``
of ``docs/math.md``; the motion of a normal is ``n_dot = H M_i tau = -z (g^T tau)``): the
task evaluates it (:func:`block_function`), the compiled law cores are generated from it
(:mod:`controllers.law_kernel`), and the second-order term differentiates its error.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import lru_cache

import casadi as ca
import numpy as np

from controllers.tasks.base import (
    Task,
    TaskState,
    evaluate_blocks,
    evaluate_reference,
    leg_rates,
    map_blocks,
    reference_function,
    second_order_function,
    sx_unit,
    unit,
)

#: Edge feature kinds.
EDGE_KINDS = ("normals", "lines")


def line_of_normal(normal: ca.SX, line_matrix_inv_t: ca.SX) -> ca.SX:
    """The unit image line ``l = K^-T n / |K^-T n|`` of an edge normal (``docs/math.md``
    section 5; ``line_matrix_inv_t`` is ``K^-T``, (3, 3))."""
    return sx_unit(line_matrix_inv_t @ normal)


def normal_of_line(line: ca.SX, line_matrix_t: ca.SX) -> ca.SX:
    """The unit edge normal ``n = K^T l / |K^T l|`` of an image line (``line_matrix_t`` is
    ``K^T``, (3, 3))."""
    return sx_unit(line_matrix_t @ line)


def leg_direction_of_edges(first: ca.SX, second: ca.SX) -> ca.SX:
    """The leg direction ``u = (n_2 x n_1) / |n_2 x n_1|`` of a leg's two edge normals
    (``vision/legs.py`` order)."""
    return sx_unit(ca.cross(second, first))


def _edge_motion(normal: ca.SX, u: ca.SX, base_point: ca.SX, length: ca.SX,
                 inv_length: ca.SX) -> tuple[ca.SX, ca.SX]:
    """``z`` (3, 1) and ``g`` (6, 1) of the rank-one ``H M = -z g^T``: the normal moves at
    ``n_dot = -z (g^T tau)`` (:mod:`controllers.interaction`)."""
    w = ca.cross(u, normal)
    z = u - w * (ca.dot(base_point, u) / ca.dot(base_point, w))
    r = normal - ca.dot(normal, u) * u
    B = base_point + length * u
    return z, ca.vertcat(r * inv_length, ca.cross(B, r) * inv_length)


def edge_block(feature: ca.SX, desired: ca.SX, normal: ca.SX, u: ca.SX, base_point: ca.SX,
               length: ca.SX, inv_length: ca.SX, line_matrix_t: ca.SX | None = None,
               line_matrix_inv_t: ca.SX | None = None) -> tuple[ca.SX, ca.SX, ca.SX]:
    """Error ``f x f*`` (3, 1) and the rank-one Jacobian ``L = a g^T`` of one edge.

    Normals (``f = n``): ``a = f* x z``; image lines (``f = l``, both line matrices
    given): ``a = f* x J_l z`` with ``J_l = |K^T l| (I - l l^T) K^-T``.

    Args:
        feature: (3, 1) measured normal or unit line.
        desired: (3, 1) its desired value.
        normal: (3, 1) the edge normal (``feature`` itself for normals).
        u: (3, 1) unit leg direction.
        base_point: (3, 1) ``A`` [m].
        length: Leg length ``q`` [m].
        inv_length: ``1 / q`` [1/m].
        line_matrix_t: ``K^T`` (lines only).
        line_matrix_inv_t: ``K^-T`` (lines only).

    Returns:
        ``e`` (3, 1), ``a`` (3, 1), ``g`` (6, 1).
    """
    e = ca.cross(feature, desired)
    z, g = _edge_motion(normal, u, base_point, length, inv_length)
    if line_matrix_t is not None and line_matrix_inv_t is not None:
        y = line_matrix_inv_t @ z
        y = y - feature * ca.dot(feature, y)
        y = y * ca.sqrt(ca.dot(line_matrix_t @ feature, line_matrix_t @ feature))
        return e, ca.cross(desired, y), g
    return e, ca.cross(desired, z), g


@lru_cache(maxsize=2)
def block_function(kind: str) -> ca.Function:
    """``(n, f*, u, A, q, K^T, K^-T) -> (e, L)`` of :func:`edge_block` on the edge normal
    ``n`` (the feature is ``n``, or its line :func:`line_of_normal`; ``L = a g^T``, (3, 6);
    the line matrices are unused for normals)."""
    n, fs, u, A = (ca.SX.sym(k, 3) for k in ("n", "f_star", "u", "A"))
    q = ca.SX.sym("q")
    Kt, Kit = ca.SX.sym("Kt", 3, 3), ca.SX.sym("Kit", 3, 3)
    if kind == "lines":
        e, a, g = edge_block(line_of_normal(n, Kit), fs, n, u, A, q, 1.0 / q, Kt, Kit)
    else:
        e, a, g = edge_block(n, fs, n, u, A, q, 1.0 / q)
    return ca.Function(f"leg_edge_{kind}_block", [n, fs, u, A, q, Kt, Kit], [e, a @ g.T])


def _edge_state_rate(s: ca.SX, p: ca.SX, tau: ca.SX) -> ca.SX:
    """``(n_dot, u_dot, q_dot)`` of an edge normal and its leg."""
    n, u, q, A = s[:3], s[3:6], s[6], p[:3]
    udot, qdot = leg_rates(u, A, q, tau)
    z, g = _edge_motion(n, u, A, q, 1.0 / q)
    return ca.vertcat(-z * ca.dot(g, tau), udot, qdot)


def _error(kind: str) -> Callable[[ca.SX, ca.SX], ca.SX]:
    # state (n, u, q), parameters (A, desired, K^-T row-major)
    def error(s: ca.SX, p: ca.SX) -> ca.SX:
        n = s[:3]
        f = line_of_normal(n, ca.reshape(p[6:15], 3, 3).T) if kind == "lines" else n
        return ca.cross(f, p[3:6])

    return error


@lru_cache(maxsize=2)
def _second_order(kind: str) -> ca.Function:
    return second_order_function(f"leg_edge_{kind}_second_order", 7, 15, _error(kind),
                                 _edge_state_rate)


@lru_cache(maxsize=2)
def reference_block(kind: str) -> ca.Function:
    """:func:`~controllers.tasks.base.reference_function` of one edge: state
    ``(n, u, q)`` (7), parameters ``(A, f*, K^-T row-major)`` (15)."""
    return reference_function(f"leg_edge_{kind}_reference", 7, 15, _error(kind),
                              _edge_state_rate)


@lru_cache(maxsize=2)
def second_order_block(kind: str) -> ca.Function:
    """``(s, p, tau) -> L_dot tau`` of one edge (layout of :func:`reference_block`)."""
    return _second_order(kind)


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

    def _blocks(self, state: TaskState) -> list[np.ndarray]:
        n = len(state)
        normals, u2, A2, q2 = self._per_edge(state)
        k = 12 * n
        Kt = np.broadcast_to(self.line_matrix.T.reshape(1, 9, order="F"), (k, 9))
        Kit = np.broadcast_to(self.line_matrix_inv_t.reshape(1, 9, order="F"), (k, 9))
        return map_blocks(block_function(self.kind), normals,
                          self._star(n).reshape(-1, 3), u2, A2, q2, Kt, Kit)

    def error(self, state: TaskState) -> np.ndarray:
        return self._blocks(state)[0].reshape(len(state), 36)

    def _per_edge(self, state: TaskState
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per edge (12 n rows): the normals, and their legs' directions, base points and
        lengths."""
        if state.normals is None:
            raise ValueError("LegEdgeTask needs the state's normals")
        u2 = np.repeat(state.directions, 2, axis=-2).reshape(-1, 3)
        A2 = np.repeat(state.base_points, 2, axis=-2).reshape(-1, 3)
        q2 = np.repeat(state.lengths, 2, axis=-1).reshape(-1)
        return state.normals.reshape(-1, 3), u2, A2, q2

    def jacobian(self, state: TaskState) -> np.ndarray:
        return self._blocks(state)[1].reshape(len(state), 36, 6)

    def _edge_rows(self, state: TaskState, twist: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per edge (12 n rows): the state, the parameters and the twist."""
        n = len(state)
        normals, u2, A2, q2 = self._per_edge(state)
        s = np.concatenate([normals, u2, q2[:, None]], axis=1)
        kit = np.broadcast_to(self.line_matrix_inv_t.reshape(9), (12 * n, 9))
        p = np.concatenate([A2, self._star(n).reshape(-1, 3), kit], axis=1)
        tau = np.repeat(np.asarray(twist, dtype=float).reshape(n, 6), 12, axis=0)
        return s, p, tau

    def jacobian_dot_twist(self, state: TaskState, twist: np.ndarray) -> np.ndarray:
        s, p, tau = self._edge_rows(state, twist)
        return evaluate_blocks(_second_order(self.kind), s, p, tau).reshape(len(state), 36)

    def reference_terms(self, state: TaskState, twist: np.ndarray, rate: np.ndarray,
                        acceleration: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``e_t``, ``e_tt`` (n, 36) of desired features moving at ``rate`` with
        ``acceleration`` (each (n, 6, 2, 3))."""
        n = len(state)
        s, p, tau = self._edge_rows(state, twist)
        pd, pdd = (np.zeros((12 * n, 15)) for _ in range(2))
        pd[:, 3:6] = np.asarray(rate, float).reshape(-1, 3)
        pdd[:, 3:6] = np.asarray(acceleration, float).reshape(-1, 3)
        e_t, e_tt = evaluate_reference(reference_block(self.kind), s, p, tau, pd, pdd)
        return e_t.reshape(n, 36), e_tt.reshape(n, 36)
