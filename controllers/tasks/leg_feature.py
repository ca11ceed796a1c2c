"""A leg feature defined once, as a CasADi expression: the built-in leg directions and a
plugin's own feature alike.

A :class:`LegFeature` is a function of ONE leg seen in the camera frame: its unit
direction ``u_i``, its length ``q_i`` and its (estimated) base point ``A_i``, e.g. the
leg direction ``u_i`` (:data:`controllers.tasks.leg_direction.LEG_DIRECTIONS`) or the
platform joint ``B_i = A_i + q_i u_i`` (``tests/controllers/plugin_feature_joints.py``).
The feature is written ONCE, symbolically (:meth:`LegFeature.value`, optionally
:meth:`LegFeature.error`, and :meth:`LegFeature.block` where a closed form exists);
everything else is derived from it by automatic differentiation: the desired value of a
goal, the block of one leg (error and interaction, the leg moving with the platform twist
by :func:`~controllers.tasks.base.leg_rates`, ``docs/math.md`` §3), the second-order and
reference terms, and the feature along a pose trajectory (the computed-torque reference).

From a feature, :func:`controllers.features.controllers_for` builds the pseudo-inverse,
limit-QP, predictive and computed-torque controllers, and :class:`FeatureTask` is its
numpy :class:`~controllers.tasks.base.Task`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from functools import cached_property

import casadi as ca
import numpy as np

from controllers.tasks.base import (
    LegBlockTask,
    TaskState,
    evaluate_legs,
    leg_state_rate,
    map_blocks,
    reference_function,
    second_order_function,
)


class LegFeature(ABC):
    """One feature of each of the six legs (camera frame); see the module docstring.

    Subclasses set :attr:`name` (the prefix of the controllers' registry names) and
    :attr:`rows`, and define :meth:`value`. The derived CasADi functions are built once
    per instance (cached properties); the compiled kernels are cached by the content
    hash of their function (:class:`hexapod.compiled.CompiledFunction`), so two
    instances of one feature share their C code.
    """

    #: Prefix of the controllers' names (``<name>-pinv``, ``-qp``, ``-mpc``, ``-ctc``).
    name: str = "feature"
    #: Rows of one leg's feature.
    rows: int = 3
    #: What a leg's block is called in the notes.
    unit: str = "legs"

    @abstractmethod
    def value(self, u: ca.SX, q: ca.SX, A: ca.SX) -> ca.SX:
        """The feature (``rows``, 1) of one leg (symbolic).

        Args:
            u: (3, 1) unit leg direction (camera frame).
            q: Leg length [m].
            A: (3, 1) base point ``A_i`` (camera frame) [m].
        """

    def error(self, f: ca.SX, f_star: ca.SX) -> ca.SX:
        """The error (``rows``, 1) of a feature ``f`` towards ``f_star`` (``f - f*``)."""
        return f - f_star

    #: Law-core inputs giving the legs' desired state, where the DESIRED or MEAN
    #: interaction evaluates ``L`` (:meth:`desired_state`).
    desired_state_inputs: tuple[tuple[str, int], ...] = (("desired_directions", 18),
                                                         ("desired_lengths", 6))

    def desired_state(self, inputs: dict[str, ca.SX], leg: int) -> tuple[ca.SX, ca.SX]:
        """The desired direction (3, 1) and length of leg ``leg`` from the law core's
        inputs (by name: :attr:`desired_state_inputs`)."""
        return (inputs["desired_directions"][3 * leg:3 * leg + 3],
                inputs["desired_lengths"][leg])

    def check(self) -> None:
        """Check the definition once, where it is made (:func:`~controllers.features.
        controllers_for`): :attr:`rows` a positive integer, :meth:`value` and
        :meth:`error` symbolic columns of that many rows.

        Raises:
            ValueError: Naming the feature, the method and the shapes.
        """
        rows = self.rows
        if isinstance(rows, bool) or not isinstance(rows, int) or rows < 1:
            raise ValueError(f"feature {self.name!r}: rows must be a positive integer, got "
                             f"{rows!r}")
        u, A, q = ca.SX.sym("u", 3), ca.SX.sym("A", 3), ca.SX.sym("q")
        for what, make in (("value(u, q, A)", lambda: self.value(u, q, A)),
                           ("error(f, f_star)", lambda: self.error(
                               ca.SX.sym("f", rows), ca.SX.sym("f_star", rows)))):
            try:
                out = ca.SX(make())
            except Exception as exc:
                raise ValueError(f"feature {self.name!r}: {what} failed on symbols (it must "
                                 f"be CasADi expressions): {type(exc).__name__}: {exc}"
                                 ) from exc
            if out.shape != (rows, 1):
                raise ValueError(f"feature {self.name!r}: {what} returned shape {out.shape}, "
                                 f"rows = {rows} declares ({rows}, 1)")

    # ------------------------------------------------------------------ derived
    def _leg_error(self, s: ca.SX, p: ca.SX) -> ca.SX:
        """Error of the leg state ``s = (u, q)`` with parameters ``p = (A, f*)``."""
        return self.error(self.value(s[:3], s[3], p[:3]), p[3:])

    @cached_property
    def value_function(self) -> ca.Function:
        """``(u, q, A) -> f`` of one leg."""
        u, A = ca.SX.sym("u", 3), ca.SX.sym("A", 3)
        q = ca.SX.sym("q")
        return ca.Function(f"{self.c_name}_value", [u, q, A], [self.value(u, q, A)])

    @cached_property
    def _derived_block(self) -> ca.Function:
        """``(u, q, A, f*) -> (e, L)`` by automatic differentiation of :meth:`error`."""
        u, A, fs = ca.SX.sym("u", 3), ca.SX.sym("A", 3), ca.SX.sym("f_star", self.rows)
        q, tau = ca.SX.sym("q"), ca.SX.sym("tau", 6)
        s, p = ca.vertcat(u, q), ca.vertcat(A, fs)
        e = self._leg_error(s, p)
        L = ca.jacobian(ca.jtimes(e, s, leg_state_rate(s, p, tau)), tau)
        return ca.Function(f"{self.c_name}_derived_block", [u, q, A, fs], [e, L])

    def block(self, u: ca.SX, q: ca.SX, A: ca.SX, f_star: ca.SX) -> tuple[ca.SX, ca.SX]:
        """Error (rows, 1) and interaction (rows, 6) of one leg (symbolic): by automatic
        differentiation of :meth:`error` along the leg's motion; a feature with a closed
        form may return it instead (the same values)."""
        e, L = self._derived_block(u, q, A, f_star)
        return e, L

    @cached_property
    def block_function(self) -> ca.Function:
        """``(u, q, A, f*) -> (e, L)`` of :meth:`block`: ``L`` (rows, 6), ``e_dot = L tau``."""
        u, A, fs = ca.SX.sym("u", 3), ca.SX.sym("A", 3), ca.SX.sym("f_star", self.rows)
        q = ca.SX.sym("q")
        return ca.Function(f"{self.c_name}_block", [u, q, A, fs], list(self.block(u, q, A, fs)))

    @cached_property
    def second_order(self) -> ca.Function:
        """``(s, p, tau) -> L_dot tau`` of one leg, ``s = (u, q)``, ``p = (A, f*)``."""
        return second_order_function(f"{self.c_name}_second_order", 4, 3 + self.rows,
                                     self._leg_error, leg_state_rate)

    @cached_property
    def reference(self) -> ca.Function:
        """``(s, p, tau, p_dot, p_ddot) -> (e_t, e_tt)`` of one leg (layout of
        :attr:`second_order`)."""
        return reference_function(f"{self.c_name}_reference", 4, 3 + self.rows,
                                  self._leg_error, leg_state_rate)

    @cached_property
    def c_name(self) -> str:
        """The feature's name as a C identifier (the kernels' names)."""
        return "".join(c if c.isalnum() else "_" for c in self.name)

    @cached_property
    def motion_function(self) -> ca.Function:
        """``(R, t, twist, twist_rate, A, E, frame) -> (f, f_dot, f_ddot)`` of the six
        legs (6 rows each) along a pose trajectory: the platform pose ``(R, t)``
        (``R`` row-major, base frame), its twist ``(t_dot, w)`` and twist rate
        ``(t_ddot, w_dot)`` (base frame), the base points ``A`` (camera frame, 18), the
        platform points ``E`` (platform frame, 18) and the camera pose ``frame``
        (``camera_from_base``: rotation row-major, translation)."""
        Rv, t = ca.SX.sym("R", 9), ca.SX.sym("t", 3)
        tw, twr = ca.SX.sym("twist", 6), ca.SX.sym("twist_rate", 6)
        A, E, frame = ca.SX.sym("A", 18), ca.SX.sym("E", 18), ca.SX.sym("frame", 12)
        R = ca.reshape(Rv, 3, 3).T
        Rc, pc = ca.reshape(frame[:9], 3, 3).T, frame[9:]
        feats = []
        for i in range(6):
            Ai = A[3 * i:3 * i + 3]
            d = Rc @ (R @ E[3 * i:3 * i + 3] + t) + pc - Ai
            q = ca.sqrt(ca.dot(d, d))
            feats.append(self.value(d / q, q, Ai))
        f = ca.vertcat(*feats)
        s = ca.vertcat(Rv, t)
        W, Wd = ca.skew(tw[3:]), ca.skew(twr[3:])
        sd = ca.vertcat(ca.reshape((W @ R).T, 9, 1), tw[:3])
        sdd = ca.vertcat(ca.reshape(((Wd + W @ W) @ R).T, 9, 1), twr[:3])
        v = ca.SX.sym("v", 12)  # s_dot held as its own symbol for the second derivative
        f_dot = ca.jtimes(f, s, v)
        f_ddot = ca.jtimes(f_dot, s, v) + ca.jtimes(f, s, sdd)
        return ca.Function(f"{self.c_name}_motion", [Rv, t, tw, twr, A, E, frame],
                           [f, ca.substitute(f_dot, v, sd), ca.substitute(f_ddot, v, sd)])

    # ------------------------------------------------------------------ numeric
    def desired(self, directions: np.ndarray, lengths: np.ndarray,
                base_points: np.ndarray) -> np.ndarray:
        """(6, rows) the feature of six legs (a goal's directions (6, 3), lengths (6,)
        [m], the base points (6, 3) [m]), evaluated by CasADi."""
        out = self.value_function.map(6)(np.asarray(directions, float).T,
                                          np.asarray(lengths, float).reshape(1, 6),
                                          np.asarray(base_points, float).T)
        return np.asarray(out, dtype=float).T.reshape(6, self.rows)


class FeatureTask(LegBlockTask):
    """A :class:`LegFeature` of the six legs towards a desired value, as a
    :class:`~controllers.tasks.base.Task` (the numpy path of the computed torque).

    Args:
        feature: The feature.
        desired: (6, rows) or (n, 6, rows) desired values.
    """

    def __init__(self, feature: LegFeature, desired: np.ndarray) -> None:
        self.feature = feature
        self.name = feature.name
        self.block = feature.rows
        self.desired = np.asarray(desired, dtype=float)

    def _params(self, state: TaskState) -> np.ndarray:
        n, r = len(state), self.feature.rows
        A = np.broadcast_to(state.base_points, (n, 6, 3))
        star = np.broadcast_to(self.desired.reshape(-1, 6, r), (n, 6, r))
        return np.concatenate([A, star], axis=-1)

    def _blocks(self, state: TaskState) -> list[np.ndarray]:
        p = self._params(state).reshape(6 * len(state), -1)
        return map_blocks(self.feature.block_function, state.directions.reshape(-1, 3),
                          state.lengths.reshape(-1), p[:, :3], p[:, 3:])

    def jacobian_dot_twist(self, state: TaskState, twist: np.ndarray) -> np.ndarray:
        out = evaluate_legs(self.feature.second_order, state, self._params(state), twist)
        return out.reshape(len(state), -1)

    def reference_terms(self, state: TaskState, twist: np.ndarray, rate: np.ndarray,
                        acceleration: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        n, r = len(state), self.feature.rows
        s = np.concatenate([state.directions, state.lengths[..., None]], axis=-1)
        p = self._params(state).reshape(6 * n, -1)
        pd, pdd = np.zeros_like(p), np.zeros_like(p)
        pd[:, 3:] = np.asarray(rate, float).reshape(-1, r)
        pdd[:, 3:] = np.asarray(acceleration, float).reshape(-1, r)
        tau = np.repeat(np.asarray(twist, float).reshape(n, 6), 6, axis=0)
        e_t, e_tt = map_blocks(self.feature.reference, s.reshape(-1, 4), p, tau, pd, pdd)
        return e_t.reshape(n, 6 * r), e_tt.reshape(n, 6 * r)
