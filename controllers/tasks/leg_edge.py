"""Leg-edge task (seeds 002/003), two 3-row blocks per leg (``docs/math.md`` section 6):

- normals (interpretation planes, any camera): ``e = n x n*``, ``L = -[n*]_x H M_i``;
- image lines (perspective camera, ``l ∝ K^-T n``): ``e = l x l*``,
  ``L = -[l*]_x J_l H M_i``.

:func:`edge_block` is the one definition of an edge's block (the rank-one ``L = a g^T``
of ``docs/math.md``; the motion of a normal is ``n_dot = H M_i tau = -z (g^T tau)``).
The two edge features are objects, :data:`EDGE_NORMALS` and :data:`EDGE_LINES`
(:class:`EdgeFeature`, a :class:`~controllers.tasks.feature_kind.BuiltinFeature`): each
owns its blocks (:attr:`EdgeFeature.block_function`, its second-order and reference
terms, which differentiate its error), its prediction from the legs and its part of the
compiled computed-torque step; the task evaluates them, the compiled law cores
(:mod:`controllers.law_kernel`) are generated from the same :func:`edge_block`.
"""

from __future__ import annotations

from functools import cached_property
from typing import Any

import casadi as ca
import numpy as np

from controllers.exceptions import ContextError
from controllers.tasks.base import (
    LegBlockTask,
    TaskState,
    leg_rates,
    map_blocks,
    reference_function,
    reference_parts,
    second_order_function,
    stack_blocks,
    sx_unit,
    unit,
)
from controllers.tasks.feature_kind import BuiltinFeature
from hexapod.compiled import Shape


def line_of_normal(normal: ca.SX, line_matrix_inv_t: ca.SX) -> ca.SX:
    """The unit image line ``l = K^-T n / |K^-T n|`` of an edge normal (``docs/math.md``
    section 5; ``line_matrix_inv_t`` is ``K^-T``, (3, 3))."""
    return sx_unit(line_matrix_inv_t @ normal)


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


def sx_edge_normals(A: ca.SX, u: ca.SX, r: ca.SX | float) -> tuple[ca.SX, ca.SX]:
    """The two edge normals of a leg (``docs/math.md`` section 4, ``vision/legs.py`` order)."""
    h = ca.cross(A, u)
    hn = ca.sqrt(ca.dot(h, h))
    hh = h / hn
    w = ca.cross(u, hh)
    s = r / hn
    c = ca.sqrt(1 - s * s)
    return c * hh - s * w, -c * hh - s * w


def _edge_state_rate(s: ca.SX, p: ca.SX, tau: ca.SX) -> ca.SX:
    """``(n_dot, u_dot, q_dot)`` of an edge normal and its leg."""
    n, u, q, A = s[:3], s[3:6], s[6], p[:3]
    udot, qdot = leg_rates(u, A, q, tau)
    z, g = _edge_motion(n, u, A, q, 1.0 / q)
    return ca.vertcat(-z * ca.dot(g, tau), udot, qdot)


class EdgeFeature(BuiltinFeature):
    """The leg edges (two per leg, ``(6, 2)`` order) as one feature: edge normals
    (:data:`EDGE_NORMALS`, ``f = n``) or unit image lines (:data:`EDGE_LINES`,
    ``f = l = K^-T n / |K^-T n|``); both are measured through the edge normal ``n`` and
    share :func:`edge_block`.

    Args:
        kind: ``"normals"`` or ``"lines"`` (the observation field, and the name in the
            kernels').
        lines: The feature is the image line of the normal (the line matrices are used).
    """

    units = 12
    task_rows = 36
    shape = (6, 2, 3)
    visibility = "edge_visible"
    field: str

    def __init__(self, kind: str, lines: bool) -> None:
        self.kind = self.field = kind
        self.lines = lines
        # the computed-torque steps and the force MPC are written on the normals
        self.ctc_name = None if lines else "edges"
        self.force_mpc_name = None if lines else "hexapod_force_mpc"
        self.stage_features = 0 if lines else 36

    # ------------------------------------------------------------------ blocks
    def sx_feature(self, normal: ca.SX, line_matrix_inv_t: ca.SX) -> ca.SX:
        """The feature of an edge normal: the normal, or its line :func:`line_of_normal`."""
        return line_of_normal(normal, line_matrix_inv_t) if self.lines else normal

    def sx_normal(self, feature: ca.SX, line_matrix_t: ca.SX) -> ca.SX:
        """The edge normal of a measured feature: itself, or the normal of a line,
        ``K^T l / |K^T l|`` (``line_matrix_t`` is ``K^T``)."""
        return sx_unit(line_matrix_t @ feature) if self.lines else feature

    def line_matrices(self, line_matrix_t: ca.SX, line_matrix_inv_t: ca.SX
                      ) -> tuple[ca.SX, ca.SX] | tuple[None, None]:
        """The line matrices :func:`edge_block` takes (None for the normals)."""
        return (line_matrix_t, line_matrix_inv_t) if self.lines else (None, None)

    @cached_property
    def block_function(self) -> ca.Function:
        """``(n, f*, u, A, q, K^T, K^-T) -> (e, L)`` of :func:`edge_block` on the edge
        normal ``n`` (the feature is ``n``, or its line :func:`line_of_normal`;
        ``L = a g^T``, (3, 6); the line matrices are unused for normals)."""
        n, fs, u, A = (ca.SX.sym(k, 3) for k in ("n", "f_star", "u", "A"))
        q = ca.SX.sym("q")
        Kt, Kit = ca.SX.sym("Kt", 3, 3), ca.SX.sym("Kit", 3, 3)
        e, a, g = edge_block(self.sx_feature(n, Kit), fs, n, u, A, q, 1.0 / q,
                             *self.line_matrices(Kt, Kit))
        return ca.Function(f"leg_edge_{self.kind}_block", [n, fs, u, A, q, Kt, Kit],
                           [e, a @ g.T])

    def _error(self, s: ca.SX, p: ca.SX) -> ca.SX:
        # state (n, u, q), parameters (A, desired, K^-T row-major)
        return ca.cross(self.sx_feature(s[:3], ca.reshape(p[6:15], 3, 3).T), p[3:6])

    @cached_property
    def second_order_block(self) -> ca.Function:
        """``(s, p, tau) -> L_dot tau`` of one edge (layout of :attr:`reference_block`)."""
        return second_order_function(f"leg_edge_{self.kind}_second_order", 7, 15,
                                     self._error, _edge_state_rate)

    @cached_property
    def reference_block(self) -> ca.Function:
        """:func:`~controllers.tasks.base.reference_function` of one edge: state
        ``(n, u, q)`` (7), parameters ``(A, f*, K^-T row-major)`` (15)."""
        return reference_function(f"leg_edge_{self.kind}_reference", 7, 15, self._error,
                                  _edge_state_rate)

    def task_of(self, desired: np.ndarray, **options: Any) -> LegEdgeTask:
        return LegEdgeTask(desired, self, **options)

    # ------------------------------------------------------------------ prediction
    def sx_of_legs(self, us: list[ca.SX], A: list[ca.SX], radius: ca.SX | float,
                   line_inv_t: ca.SX | None = None) -> list[ca.SX]:
        out = []
        for Ai, ui in zip(A, us, strict=True):
            for n in sx_edge_normals(Ai, ui, radius):
                out.append(line_of_normal(n, line_inv_t)
                           if line_inv_t is not None and self.lines else n)
        return out

    def model_features(self, base_points: np.ndarray, directions: np.ndarray, radius: float,
                       line_matrix: np.ndarray | None) -> np.ndarray:
        from vision.legs import leg_edges

        n, _ = leg_edges(base_points, directions, radius)
        if self.lines:
            n = n @ np.linalg.inv(self._checked(line_matrix))  # rows: (K^-T n)^T
            n = n / np.linalg.norm(n, axis=-1, keepdims=True)
        return n.reshape(12, 3)  # type: ignore[no-any-return]

    def features_of(self, normals: np.ndarray, line_matrix_inv_t: np.ndarray) -> np.ndarray:
        """(..., 3) the features of edge normals (..., 3): the normals, or their unit
        lines ``K^-T n / |K^-T n|`` (numpy; ``line_matrix_inv_t`` is ``K^-T``)."""
        return unit(normals @ line_matrix_inv_t.T) if self.lines else normals

    def normals_of(self, features: np.ndarray, line_matrix: np.ndarray) -> np.ndarray:
        """(..., 3) the edge normals of features (..., 3): the normals themselves, or the
        unit normals ``K^T l / |K^T l|`` of lines (numpy; rows ``(K^T l)^T = l^T K``)."""
        return unit(features @ line_matrix) if self.lines else features

    def line_inv_t(self, line_matrix: np.ndarray | None) -> np.ndarray:
        if self.lines:
            return np.linalg.inv(self._checked(line_matrix)).T  # type: ignore[no-any-return]
        return np.eye(3)

    # ------------------------------------------------------------------ the law's reset
    def line_matrix_of(self, camera: Any, who: str) -> np.ndarray | None:
        """The (3, 3) line matrix ``K`` the feature reads ``camera`` through: the camera's
        ``line_matrix`` for lines (checked), None for normals (any camera).

        Args:
            camera: The controller context's camera.
            who: The controller's name (in the error).

        Raises:
            ContextError: Lines of a camera that is not perspective or has no
                ``line_matrix`` (naming its kind), or a ``line_matrix`` that is not an
                invertible finite 3x3 matrix.
        """
        if not self.lines:
            return None
        kind = getattr(camera, "kind", None)
        if kind != "perspective" or getattr(camera, "line_matrix", None) is None:
            raise ContextError(who, "camera", f"pixel lines need a perspective camera with a "
                                              f"line_matrix, got {kind!r}")
        K = np.asarray(camera.line_matrix, dtype=float)
        if K.shape != (3, 3) or not np.all(np.isfinite(K)) or abs(np.linalg.det(K)) < 1e-300:
            raise ContextError(who, "camera.line_matrix", "not an invertible 3x3 matrix")
        return K

    def desired_of(self, goal: Any, visible: np.ndarray, line_matrix: np.ndarray,
                   line_matrix_inv_t: np.ndarray, who: str
                   ) -> tuple[np.ndarray | None, np.ndarray | None, np.ndarray]:
        """A goal's desired lines and normals, each (6, 2, 3), and the edges usable.

        Normals: ``(None, goal.normals, visible)`` (the law checks the normals). Lines:
        the goal's ``lines``, else the unit lines of its ``normals`` (an estimated
        camera), zero where not ``visible`` or not finite; the goal's normals, else the
        unit normals of those lines; ``visible`` less the non-finite lines.

        Args:
            goal: The :class:`~controllers.base.Goal` (its ``normals`` and ``lines``).
            visible: (6, 2) edges the goal shows.
            line_matrix: ``K`` (3, 3) of the camera (:meth:`line_matrix_of`).
            line_matrix_inv_t: ``K^-T`` (3, 3).
            who: The controller's name (in the errors).

        Raises:
            ContextError: A goal field of another shape than (6, 2, 3), or lines wanted
                and the goal gives neither lines nor normals.
        """
        normals = goal_edges(goal.normals, "goal.normals", who)
        if not self.lines:
            return None, normals, visible
        lines = goal_edges(goal.lines, "goal.lines", who)
        if lines is not None:
            l_star = lines
        elif normals is not None:  # desired lines from desired normals (estimated camera)
            l_star = unit(normals @ line_matrix_inv_t.T)
        else:
            raise ContextError(who, "goal.lines", "missing (and no goal.normals)")
        visible = visible & np.all(np.isfinite(l_star), axis=-1)
        l_star = np.where(visible[..., None], l_star, 0.0)
        if normals is None:
            normals = unit(np.where(visible[..., None], l_star, np.array([0, 0, 1.0]))
                           @ line_matrix)
        return l_star, normals, visible

    def desired_input(self, lines: np.ndarray | None, normals: np.ndarray) -> np.ndarray:
        """The desired features the law core takes: ``lines`` of the lines feature (of
        :meth:`desired_of`), ``normals`` of the normals feature."""
        if self.lines:
            assert lines is not None, "desired lines of the lines feature"
            return lines
        return normals

    def _checked(self, line_matrix: np.ndarray | None) -> np.ndarray:
        if line_matrix is None:
            raise ValueError(f"feature {self.kind!r} needs the camera's line_matrix")
        return line_matrix

    # ------------------------------------------------------------------ computed torque
    def ctc_blocks(self, fk: bool) -> tuple[tuple[str, Shape], ...]:
        """The normals (6 x 2 x 3), the leg ``directions`` (6 x 3) and ``of_normals``
        (1.0: the directions of the normals, ``unit(n_2 x n_1)``)."""
        if self.lines:
            raise self._unsupported("compiled computed-torque step")
        return (("normals", (6, 2, 3)), ("directions", (6, 3)), ("of_normals", 1))

    def sx_ctc_task(self, v: dict[str, ca.SX], q: ca.SX, R: ca.SX, t: ca.SX, tau_s: ca.SX
                    ) -> tuple[ca.SX, ca.SX, ca.SX, ca.SX, ca.SX]:
        """Edge after edge (the normals' blocks, :attr:`block_function`)."""
        if self.lines:
            raise self._unsupported("compiled computed-torque step")
        A, directions = v["base"], v["directions"]
        des, rate, acc = reference_parts(v)
        eye = ca.reshape(ca.SX.eye(3), 9, 1)
        zeros3 = ca.SX.zeros(3)
        blocks = []
        for i in range(6):
            Ai, qi = A[3 * i:3 * i + 3], q[i]
            normals = v["normals"]
            n1, n2 = normals[6 * i:6 * i + 3], normals[6 * i + 3:6 * i + 6]
            ui = ca.if_else(v["of_normals"][0], leg_direction_of_edges(n1, n2),
                            directions[3 * i:3 * i + 3])
            for j, n in enumerate((n1, n2)):
                k = 6 * i + 3 * j
                ns = des[k:k + 3]
                s = ca.vertcat(n, ui, qi)
                p = ca.vertcat(Ai, ns, eye)
                blocks.append((
                    *self.block_function(n, ns, ui, Ai, qi, ca.SX.eye(3), ca.SX.eye(3)),
                    self.second_order_block(s, p, tau_s),
                    *self.reference_block(s, p, tau_s,
                                          ca.vertcat(zeros3, rate[k:k + 3], ca.SX.zeros(9)),
                                          ca.vertcat(zeros3, acc[k:k + 3], ca.SX.zeros(9)))))
        return stack_blocks(blocks)

    # ------------------------------------------------------------------ force MPC
    def sx_stage_features(self, t: ca.SX, R_column_major: ca.SX, normals: list[ca.SX]
                          ) -> ca.SX:
        if self.lines:
            raise self._unsupported("force-MPC features")
        return ca.vertcat(*normals)


def goal_edges(value: Any, field: str, who: str) -> np.ndarray | None:
    """A goal's (6, 2, 3) edge field as floats (None when it has none).

    Raises:
        ContextError: Another shape (naming the controller ``who``, the field and the
            shape).
    """
    if value is None:
        return None
    arr = np.asarray(value, dtype=float)
    if arr.shape != (6, 2, 3):
        raise ContextError(who, field, f"expected shape (6, 2, 3), got {arr.shape}")
    return arr


#: The leg edges as interpretation-plane normals (any camera).
EDGE_NORMALS = EdgeFeature("normals", lines=False)
#: The leg edges as unit image lines (a perspective camera's ``line_matrix``).
EDGE_LINES = EdgeFeature("lines", lines=True)
#: The edge features by their option value (``edge_feature``, ``LegEdgeTask``'s kind).
EDGE_KINDS = {f.kind: f for f in (EDGE_NORMALS, EDGE_LINES)}


def edge_feature(kind: str | EdgeFeature) -> EdgeFeature:
    """The edge feature of an option value (``"normals"`` or ``"lines"``), or the
    feature itself.

    Raises:
        ValueError: Another value (naming it and the choices).
    """
    if isinstance(kind, EdgeFeature):
        return kind
    try:
        return EDGE_KINDS[kind]
    except (KeyError, TypeError):
        raise ValueError(f"kind: expected one of {', '.join(EDGE_KINDS)}, "
                         f"got {kind!r}") from None


class LegEdgeTask(LegBlockTask):
    """The twelve leg edges (two per leg, ``(6, 2)`` order) towards their desired values.

    Args:
        desired: (6, 2, 3) or (n, 6, 2, 3) desired normals (:data:`EDGE_NORMALS`) or
            unit image lines (:data:`EDGE_LINES`).
        kind: The edge feature, or its name (``"normals"`` or ``"lines"``).
        line_matrix: (3, 3) ``K`` of the perspective camera (lines only).
    """

    name = "leg-edges"
    block = 6  # two edges of 3 rows per leg

    def __init__(self, desired: np.ndarray, kind: str | EdgeFeature = "normals",
                 line_matrix: np.ndarray | None = None) -> None:
        self.feature = edge_feature(kind)
        self.line_matrix_inv_t = self.feature.line_inv_t(line_matrix)  # checked for lines
        self.desired = np.asarray(desired, dtype=float)
        self.line_matrix = np.eye(3) if line_matrix is None else np.asarray(line_matrix, float)

    def _star(self, n: int) -> np.ndarray:
        return np.ascontiguousarray(np.broadcast_to(self.desired, (n, 6, 2, 3)))

    def _blocks(self, state: TaskState) -> list[np.ndarray]:
        n = len(state)
        normals, u2, A2, q2 = self._per_edge(state)
        k = 12 * n
        Kt = np.broadcast_to(self.line_matrix.T.reshape(1, 9, order="F"), (k, 9))
        Kit = np.broadcast_to(self.line_matrix_inv_t.reshape(1, 9, order="F"), (k, 9))
        return map_blocks(self.feature.block_function, normals,
                          self._star(n).reshape(-1, 3), u2, A2, q2, Kt, Kit)

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
        return map_blocks(self.feature.second_order_block, s, p, tau)[0].reshape(len(state), 36)

    def reference_terms(self, state: TaskState, twist: np.ndarray, rate: np.ndarray,
                        acceleration: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``e_t``, ``e_tt`` (n, 36) of desired features moving at ``rate`` with
        ``acceleration`` (each (n, 6, 2, 3))."""
        n = len(state)
        s, p, tau = self._edge_rows(state, twist)
        pd, pdd = (np.zeros((12 * n, 15)) for _ in range(2))
        pd[:, 3:6] = np.asarray(rate, float).reshape(-1, 3)
        pdd[:, 3:6] = np.asarray(acceleration, float).reshape(-1, 3)
        e_t, e_tt = map_blocks(self.feature.reference_block, s, p, tau, pd, pdd)
        return e_t.reshape(n, 36), e_tt.reshape(n, 36)
