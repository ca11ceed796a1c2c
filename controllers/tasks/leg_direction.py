"""Leg directions (seeds 001/003): ``e_i = u_i x u_i*``, ``L_i = -[u_i*]_x M_i``
(``docs/math.md`` sections 3 and 6), one 3-row block per leg.

:func:`direction_block` is the one definition of the block: :data:`LEG_DIRECTIONS` (a
:class:`~controllers.tasks.leg_feature.LegFeature`) evaluates it, its task is the
feature's :class:`~controllers.tasks.leg_feature.FeatureTask`, the compiled law core is
generated from it (:mod:`controllers.law_kernel`), and the second-order term
differentiates its error.
"""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np

from controllers.tasks.base import reference_parts, stack_blocks
from controllers.tasks.feature_kind import BuiltinFeature
from controllers.tasks.leg_feature import FeatureTask, LegFeature
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
    C = -(ca.skew(desired) @ P) * (1.0 / length)  # one division per leg
    B = base_point + length * u
    return e, ca.horzcat(C, -(C @ ca.skew(B)))


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

    def task_of(self, desired: np.ndarray, **options: Any) -> FeatureTask:
        """The :class:`~controllers.tasks.leg_feature.FeatureTask` towards ``desired``
        (6, 3) or (n, 6, 3)."""
        return FeatureTask(self, desired)

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
        """Leg after leg (:attr:`block_function`, :attr:`second_order`, :attr:`reference`)."""
        A, directions = v["base"], v["directions"]
        des, rate, acc = reference_parts(v)
        zeros3 = ca.SX.zeros(3)
        blocks = []
        for i in range(6):
            Ai, qi = A[3 * i:3 * i + 3], q[i]
            ui, us = directions[3 * i:3 * i + 3], des[3 * i:3 * i + 3]
            s, p = ca.vertcat(ui, qi), ca.vertcat(Ai, us)
            blocks.append((*self.block_function(ui, qi, Ai, us), self.second_order(s, p, tau_s),
                           *self.reference(s, p, tau_s, ca.vertcat(zeros3, rate[3 * i:3 * i + 3]),
                                           ca.vertcat(zeros3, acc[3 * i:3 * i + 3]))))
        return stack_blocks(blocks)


#: The leg directions (the feature of ``leg-direction``'s compiled law core).
LEG_DIRECTIONS = LegDirections()
