"""The task interface (in the manner of Pink's ``Task``) and the state tasks read.

A task is a pure object: from a :class:`TaskState` (one row per trial) it gives the
error ``e``, the Jacobian ``L`` (``e_dot = L tau`` for the platform twist ``tau = (v, w)``
in the frame of the state, at its origin), the second-order term ``L_dot tau`` and, for a
moving desired value, the reference terms ``e_t`` and ``e_tt``. Each feature task
defines its block once, as a CasADi expression of one leg or edge: its error and
Jacobian map it over the rows (:func:`map_blocks`), the compiled law cores are generated
from it, and the other terms differentiate it (:func:`second_order_function`,
:func:`reference_function`); ``tests/controllers/test_tasks.py`` checks each against
finite differences of the true kinematics.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import casadi as ca
import numpy as np

from vision.legs import leg_edges


@dataclass(frozen=True)
class TaskState:
    """What the tasks read, one row per trial (the camera frame for the vision tasks).

    Attributes:
        base_points: (n, 6, 3) base points ``A_i`` [m].
        directions: (n, 6, 3) unit leg directions ``u_i``.
        lengths: (n, 6) leg lengths ``q_i`` [m].
        normals: (n, 6, 2, 3) edge normals, or None.
        rotation: (n, 3, 3) platform orientation, or None.
        translation: (n, 3) platform position [m], or None.
    """

    base_points: np.ndarray
    directions: np.ndarray
    lengths: np.ndarray
    normals: np.ndarray | None = None
    rotation: np.ndarray | None = None
    translation: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.lengths.shape[0])

    @staticmethod
    def at_pose(base_points: np.ndarray, platform_points: np.ndarray, rotation: np.ndarray,
                translation: np.ndarray, leg_radius: float) -> TaskState:
        """The exact state of robots at platform poses (the reference of the tests).

        Args:
            base_points: (6, 3) or (n, 6, 3) ``A_i`` in the task frame [m].
            platform_points: (6, 3) ``E_i`` in the platform frame [m].
            rotation: (n, 3, 3) platform orientations in the task frame.
            translation: (n, 3) platform positions in the task frame [m].
            leg_radius: Leg radius [m] (for the edge normals).
        """
        R = np.asarray(rotation, dtype=float)
        t = np.asarray(translation, dtype=float)
        A = np.broadcast_to(np.asarray(base_points, dtype=float), (len(R), 6, 3))
        B = np.einsum("nij,kj->nki", R, platform_points) + t[:, None, :]
        d = B - A
        q = np.sqrt(np.einsum("nki,nki->nk", d, d))
        u = d / q[..., None]
        normals, _ = leg_edges(A, u, leg_radius)
        return TaskState(np.array(A), u, q, normals, R, t)


class Task(ABC):
    """A feature with its error, its Jacobian and the second-order term."""

    #: Name (diagnostics).
    name: str = "task"
    #: Rows of one feature block (3 for a unit-vector feature).
    block: int = 3

    @abstractmethod
    def error(self, state: TaskState) -> np.ndarray:
        """(n, m) the task error."""

    @abstractmethod
    def jacobian(self, state: TaskState) -> np.ndarray:
        """(n, m, 6) ``L`` with ``e_dot = L tau``."""

    @abstractmethod
    def jacobian_dot_twist(self, state: TaskState, twist: np.ndarray) -> np.ndarray:
        """(n, m) ``L_dot tau`` along the motion with the constant twist ``tau`` (n, 6)."""

    def reference_terms(self, state: TaskState, twist: np.ndarray, rate: np.ndarray,
                        acceleration: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``e_t`` and ``e_tt`` (n, m) of the desired value moving at ``rate`` with
        ``acceleration`` (the desired value's shape with a leading trial axis; for a pose
        task the reference's twist and its rate), the state moving with the twist ``tau``
        (n, 6) (:func:`reference_function`).

        Raises:
            NotImplementedError: The task has no moving reference.
        """
        raise NotImplementedError(f"{self.name}: no moving reference")


class LegBlockTask(Task):
    """A task whose error and Jacobian are :attr:`block` rows per leg, a block function
    mapped over the legs (or edges) of every row (:meth:`_blocks`)."""

    @abstractmethod
    def _blocks(self, state: TaskState) -> Sequence[np.ndarray]:
        """The errors and Jacobians of every leg's block (any shape, in leg order)."""

    def error(self, state: TaskState) -> np.ndarray:
        return np.reshape(self._blocks(state)[0], (len(state), 6 * self.block))

    def jacobian(self, state: TaskState) -> np.ndarray:
        return np.reshape(self._blocks(state)[1], (len(state), 6 * self.block, 6))


def leg_rates(u: ca.SX, A: ca.SX, q: ca.SX, tau: ca.SX) -> tuple[ca.SX, ca.SX]:
    """``u_dot`` and ``q_dot`` of a leg moved by the platform twist (``docs/math.md`` §3):
    the platform joint ``B = A + q u`` moves at ``B_dot = v + w x B``."""
    B = A + q * u
    Bdot = tau[:3] + ca.cross(tau[3:], B)
    qdot = ca.dot(u, Bdot)
    return (Bdot - qdot * u) / q, qdot


def leg_state_rate(s: ca.SX, p: ca.SX, tau: ca.SX) -> ca.SX:
    """``(u_dot, q_dot)`` of the leg state ``s = (u, q)``, parameters ``p = (A, ...)``."""
    return ca.vertcat(*leg_rates(s[:3], p[:3], s[3], tau))


def second_order_function(name: str, n_state: int, n_param: int,
                          error: Callable[[ca.SX, ca.SX], ca.SX],
                          state_rate: Callable[[ca.SX, ca.SX, ca.SX], ca.SX]) -> ca.Function:
    """``(s, p, tau) -> L_dot tau`` of one feature block, by automatic differentiation.

    With ``e(s, p)`` the block's error and ``s_dot(s, p, tau)`` the motion of its state,
    ``e_dot = de/ds s_dot = L(s) tau`` and ``L_dot tau = d(L(s) tau)/ds s_dot``.
    """
    s = ca.SX.sym("s", n_state)
    p = ca.SX.sym("p", n_param)
    tau = ca.SX.sym("tau", 6)
    sdot = state_rate(s, p, tau)
    edot = ca.jtimes(error(s, p), s, sdot)
    return ca.Function(name, [s, p, tau], [ca.jtimes(edot, s, sdot)])


def reference_function(name: str, n_state: int, n_param: int,
                       error: Callable[[ca.SX, ca.SX], ca.SX],
                       state_rate: Callable[[ca.SX, ca.SX, ca.SX], ca.SX]) -> ca.Function:
    """``(s, p, tau, p_dot, p_ddot) -> (e_t, e_tt)`` of one feature block whose parameters
    ``p`` (the desired value) move, by automatic differentiation.

    With ``e(s, p(t))``, the state moving at ``s_dot(s, p, tau)``:
    ``e_dot = e_s s_dot + e_p p_dot = L tau + e_t`` and, the twist held,
    ``e_ddot = L tau_dot + L_dot tau + e_tt`` with
    ``e_tt = e_pp[p_dot, p_dot] + e_p p_ddot + 2 d(L tau)/dp p_dot``.
    """
    s = ca.SX.sym("s", n_state)
    p = ca.SX.sym("p", n_param)
    tau = ca.SX.sym("tau", 6)
    pd = ca.SX.sym("p_dot", n_param)
    pdd = ca.SX.sym("p_ddot", n_param)
    e = error(s, p)
    e_t = ca.jtimes(e, p, pd)
    l_tau = ca.jtimes(e, s, state_rate(s, p, tau))
    e_tt = ca.jtimes(e_t, p, pd) + ca.jtimes(e, p, pdd) + 2.0 * ca.jtimes(l_tau, p, pd)
    return ca.Function(name, [s, p, tau, pd, pdd], [e_t, e_tt])


def leg_second_order(name: str, n_param: int, error: Callable[[ca.SX, ca.SX], ca.SX]
                     ) -> ca.Function:
    """:func:`second_order_function` of a per-leg feature: state ``(u, q)`` (4), parameters
    ``(A, ...)`` (``n_param``, the base point first), the leg moved by :func:`leg_rates`."""
    return second_order_function(name, 4, n_param, error, leg_state_rate)


def evaluate_legs(function: ca.Function, state: TaskState, params: np.ndarray,
                  twist: np.ndarray) -> np.ndarray:
    """A :func:`leg_second_order` function over every leg of every row: (n, 6, out).

    Args:
        function: The per-leg function.
        state: The rows' state (directions and lengths).
        params: (n, 6, n_param) the per-leg parameters.
        twist: (n, 6) the rows' twists.
    """
    n = len(state)
    s = np.concatenate([state.directions, state.lengths[..., None]], axis=-1)
    tau = np.repeat(np.asarray(twist, dtype=float).reshape(n, 6), 6, axis=0)
    out = map_blocks(function, s.reshape(-1, 4), params.reshape(n * 6, -1), tau)[0]
    return out.reshape(n, 6, -1)


def reference_parts(v: dict[str, ca.SX]) -> tuple[ca.SX, ca.SX, ca.SX]:
    """The desired features, their rate and acceleration (thirds of the
    ``reference_features`` input block of a compiled computed-torque step)."""
    ref = v["reference_features"]
    m = ref.shape[0] // 3
    return ref[0:m], ref[m:2 * m], ref[2 * m:3 * m]


def stack_blocks(blocks: Sequence[Sequence[ca.SX]]
                 ) -> tuple[ca.SX, ca.SX, ca.SX, ca.SX, ca.SX]:
    """The ``(e, L, L_dot tau, e_t, e_tt)`` of every block, each term stacked over the
    blocks (a feature's part of a compiled computed-torque step)."""
    e, L, ldot, e_t, e_tt = (ca.vertcat(*terms) for terms in zip(*blocks, strict=True))
    return e, L, ldot, e_t, e_tt


def sx_unit(v: ca.SX) -> ca.SX:
    """``v / |v|`` of a (3, 1) expression."""
    return v / ca.sqrt(ca.dot(v, v))


def map_blocks(function: ca.Function, *columns: np.ndarray) -> list[np.ndarray]:
    """A block function over ``k`` blocks (CasADi ``map``): each input (k, ...), a block's
    matrix flattened column-major (vectors as they are); each output (k, rows, cols).

    Args:
        function: One block (inputs and outputs of fixed shapes).
        columns: The inputs, block first.
    """
    k = columns[0].shape[0]
    args = []
    for j, c in enumerate(columns):
        rows, cols = function.size1_in(j), function.size2_in(j)
        # a block's (rows, cols) input, column-major in its row of c, side by side
        block = np.asarray(c, dtype=float).reshape(k, cols, rows).transpose(2, 0, 1)
        args.append(block.reshape(rows, k * cols))
    outs = function.map(k)(*args) if k else [
        np.zeros((function.size1_out(j), 0)) for j in range(function.n_out())]
    if function.n_out() == 1:
        outs = [outs]
    res = []
    for j, out in enumerate(outs):
        rows, cols = function.size1_out(j), function.size2_out(j)
        res.append(np.asarray(out, dtype=float).reshape(rows, k, cols).transpose(1, 0, 2))
    return res


def unit(x: np.ndarray) -> np.ndarray:
    """Rows scaled to unit norm."""
    return x / np.sqrt(np.einsum("...k,...k->...", x, x))[..., None]


__all__ = ["Task", "TaskState", "evaluate_legs", "leg_rates", "leg_second_order",
           "leg_state_rate", "map_blocks", "reference_function", "reference_parts",
           "second_order_function", "stack_blocks", "sx_unit", "unit"]
