"""Leg-direction task (seeds 001/003): ``e_i = u_i x u_i*``, ``L_i = -[u_i*]_x M_i``
(``docs/math.md`` sections 3 and 6), one 3-row block per leg.

:func:`direction_block` is the one definition of the block: the task evaluates it
(:func:`block_function`), the compiled law core is generated from it
(:mod:`controllers.law_kernel`), and the second-order term differentiates its error.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any

import casadi as ca
import numpy as np

from controllers.tasks.base import (
    LegBlockTask,
    TaskState,
    evaluate_legs,
    evaluate_reference,
    leg_rates,
    leg_second_order,
    map_blocks,
    reference_function,
    sx_skew,
)
from controllers.tasks.feature_kind import BuiltinFeature
from controllers.tasks.leg_feature import LegFeature
from hexapod.compiled import Shape


def direction_block(u: ca.SX, desired: ca.SX, base_point: ca.SX, length: ca.SX
                    ) -> tuple[ca.SX, ca.SX]:
    """Error ``u x u*`` (3, 1) and Jacobian ``-[u*]_x M`` (3, 6) of one leg.

    ``M = (1/q) P(u) [I, -[B]_x]`` with ``P(u) = I - u u^T`` and ``B = A + q u``.

    Args:
        u: (3, 1) unit leg direction.
        desired: (3, 1) desired direction ``u*``.
        base_point: (3, 1) ``A`` [m].
        length: Leg length ``q`` [m].
    """
    e = ca.cross(u, desired)
    P = ca.SX.eye(3) - u @ u.T
    C = -(sx_skew(desired) @ P) * (1.0 / length)  # one division per leg
    B = base_point + length * u
    return e, ca.horzcat(C, -(C @ sx_skew(B)))


@lru_cache(maxsize=1)
def block_function() -> ca.Function:
    """``(u, u*, A, q) -> (e, L)`` of :func:`direction_block`."""
    u, us, A = (ca.SX.sym(k, 3) for k in ("u", "u_star", "A"))
    q = ca.SX.sym("q")
    return ca.Function("leg_direction_block", [u, us, A, q], list(direction_block(u, us, A, q)))


def _error(s: ca.SX, p: ca.SX) -> ca.SX:
    # state (u, q), parameters (A, u*)
    return direction_block(s[:3], p[3:6], p[:3], s[3])[0]


@lru_cache(maxsize=1)
def _second_order() -> ca.Function:
    return leg_second_order("leg_direction_second_order", 6, _error)


@lru_cache(maxsize=1)
def second_order_block() -> ca.Function:
    """``(s, p, tau) -> L_dot tau`` of one leg: state ``(u, q)`` (4), parameters
    ``(A, u*)`` (6)."""
    return _second_order()


@lru_cache(maxsize=1)
def reference_block() -> ca.Function:
    """:func:`~controllers.tasks.base.reference_function` of one leg (layout of
    :func:`second_order_block`)."""
    return reference_function(
        "leg_direction_reference", 4, 6, _error,
        lambda s, p, tau: ca.vertcat(*leg_rates(s[:3], p[:3], s[3], tau)))


class LegDirectionTask(LegBlockTask):
    """The six leg directions towards their desired values.

    Args:
        desired: (6, 3) or (n, 6, 3) desired unit directions ``u_i*``.
    """

    name = "leg-directions"

    def __init__(self, desired: np.ndarray) -> None:
        self.desired = np.asarray(desired, dtype=float)

    def _star(self, n: int) -> np.ndarray:
        return np.broadcast_to(self.desired, (n, 6, 3))

    def _blocks(self, state: TaskState) -> list[np.ndarray]:
        n = len(state)
        return map_blocks(block_function(), state.directions.reshape(-1, 3),
                          self._star(n).reshape(-1, 3), state.base_points.reshape(-1, 3),
                          state.lengths.reshape(-1))

    def jacobian_dot_twist(self, state: TaskState, twist: np.ndarray) -> np.ndarray:
        n = len(state)
        p = np.concatenate([state.base_points, self._star(n)], axis=-1)
        return evaluate_legs(_second_order(), state, p, twist).reshape(n, 18)

    def reference_terms(self, state: TaskState, twist: np.ndarray, rate: np.ndarray,
                        acceleration: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``e_t``, ``e_tt`` (n, 18) of desired directions moving at ``rate`` with
        ``acceleration`` (each (n, 6, 3))."""
        n = len(state)
        s = np.concatenate([state.directions, state.lengths[..., None]], axis=-1)
        p = np.concatenate([state.base_points, self._star(n)], axis=-1).reshape(6 * n, 6)
        tau = np.repeat(np.asarray(twist, dtype=float).reshape(n, 6), 6, axis=0)
        pd, pdd = (np.zeros((6 * n, 6)) for _ in range(2))
        pd[:, 3:] = np.asarray(rate, float).reshape(-1, 3)
        pdd[:, 3:] = np.asarray(acceleration, float).reshape(-1, 3)
        e_t, e_tt = evaluate_reference(reference_block(), s.reshape(6 * n, 4), p, tau, pd,
                                       pdd)
        return e_t.reshape(n, 18), e_tt.reshape(n, 18)


class LegDirections(LegFeature, BuiltinFeature):
    """The leg directions as a :class:`~controllers.tasks.leg_feature.LegFeature` (the
    shape of a plugin's feature) and a built-in feature object
    (:class:`~controllers.tasks.feature_kind.BuiltinFeature`): ``f_i = u_i``, error
    ``u_i x u_i*``, block :func:`direction_block` (the closed form); the desired state of
    the DESIRED / MEAN interaction is ``(u_i*, q_i*)``, the desired feature itself and
    the goal lengths. Read from ``Observation.directions``."""

    name = "leg-direction"
    rows = 3
    desired_state_inputs = (("desired_lengths", 6),)
    kind = field = ctc_name = "directions"
    visibility = "direction_visible"
    shape = (6, 3)
    units = 6
    task_rows = 18

    def value(self, u: ca.SX, q: ca.SX, A: ca.SX) -> ca.SX:
        return u

    def error(self, f: ca.SX, f_star: ca.SX) -> ca.SX:
        return ca.cross(f, f_star)

    def block(self, u: ca.SX, q: ca.SX, A: ca.SX, f_star: ca.SX) -> tuple[ca.SX, ca.SX]:
        return direction_block(u, f_star, A, q)

    def desired_state(self, inputs: dict[str, ca.SX], leg: int) -> tuple[ca.SX, ca.SX]:
        return inputs["desired"][3 * leg:3 * leg + 3], inputs["desired_lengths"][leg]

    def task_of(self, desired: np.ndarray, **options: Any) -> LegDirectionTask:
        return LegDirectionTask(desired)

    # ------------------------------------------------------------------ prediction
    def sx_of_legs(self, us: list[ca.SX], A: list[ca.SX], radius: ca.SX | float,
                   line_inv_t: ca.SX | None = None) -> list[ca.SX]:
        return list(us)

    def model_features(self, base_points: np.ndarray, directions: np.ndarray, radius: float,
                       line_matrix: np.ndarray | None) -> np.ndarray:
        return directions

    # ------------------------------------------------------------------ computed torque
    def ctc_blocks(self, fk: bool) -> tuple[tuple[str, Shape], ...]:
        """The measured leg ``directions`` (6 x 3)."""
        return (("directions", (6, 3)),)

    def sx_ctc_task(self, v: dict[str, ca.SX], q: ca.SX, R: ca.SX, t: ca.SX, tau_s: ca.SX
                    ) -> tuple[ca.SX, ca.SX, ca.SX, ca.SX, ca.SX]:
        """Leg after leg (:func:`block_function`, :func:`second_order_block`,
        :func:`reference_block`)."""
        A, directions = v["base"], v["directions"]
        ref = v["reference_features"]
        m = ref.shape[0] // 3
        des, rate, acc = ref[0:m], ref[m:2 * m], ref[2 * m:3 * m]
        es, Ls, ldots, ets, etts = [], [], [], [], []
        zeros3 = ca.SX.zeros(3)
        for i in range(6):
            Ai, qi = A[3 * i:3 * i + 3], q[i]
            ui, us = directions[3 * i:3 * i + 3], des[3 * i:3 * i + 3]
            e, L = block_function()(ui, us, Ai, qi)
            s, p = ca.vertcat(ui, qi), ca.vertcat(Ai, us)
            es.append(e)
            Ls.append(L)
            ldots.append(second_order_block()(s, p, tau_s))
            e_t, e_tt = reference_block()(
                s, p, tau_s, ca.vertcat(zeros3, rate[3 * i:3 * i + 3]),
                ca.vertcat(zeros3, acc[3 * i:3 * i + 3]))
            ets.append(e_t)
            etts.append(e_tt)
        return (ca.vertcat(*es), ca.vertcat(*Ls), ca.vertcat(*ldots), ca.vertcat(*ets),
                ca.vertcat(*etts))


#: The leg directions (the feature of ``leg-direction``'s compiled law core).
LEG_DIRECTIONS = LegDirections()
