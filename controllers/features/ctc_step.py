"""The computed-torque step of a :class:`~controllers.tasks.leg_feature.LegFeature` as one
compiled function, composed like the built-in task steps
(:mod:`controllers.solvers.compiled_task_ctc`) from the same symbolic parts:

- the pose from the encoder lengths (:func:`~controllers.solvers.compiled_ctc.
  sx_encoder_pose`, Newton steps from the input pose; the length residual out);
- ``K``, the twist ``K^-1 q_dot``, ``M``, ``h`` (:func:`~controllers.solvers.compiled_ctc.
  sx_model_state`), the twist brought to the camera frame;
- per leg the feature's error and interaction (:meth:`LegFeature.block`), ``L_dot tau``
  (:attr:`LegFeature.second_order`) and the reference's ``e_t``, ``e_tt``
  (:attr:`LegFeature.reference`), all by automatic differentiation of the feature;
- ``tau_dot`` the least-squares solution over the rows whose ``mask`` is 1, the leg
  forces with the drives' terms (:func:`~controllers.solvers.compiled_ctc.
  sx_mechanism_forces`).

The input and output layouts are those of the built-in direction kind
(:func:`controllers.solvers.compiled_task_ctc.layout`) with ``m = 6 rows`` task rows,
so the step is driven by :class:`~controllers.task_ctc_compiled.CompiledTaskStep`
(:class:`FeatureTaskStep`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import casadi as ca
import numpy as np

from controllers.solvers.compiled_ctc import (
    sx_encoder_pose,
    sx_mechanism_forces,
    sx_model_state,
)
from controllers.solvers.compiled_task_ctc import _COMMON, FK_CALLS, _model_twist
from controllers.task_ctc_compiled import FK_TOLERANCE, CompiledTaskStep
from controllers.tasks.leg_feature import LegFeature
from hexapod.compiled import CompiledFunction, Layout
from hexapod.dynamics.drive_model import COULOMB_SMOOTHING
from hexapod.dynamics.model import INVERSE_TOLERANCE
from hexapod.workspace import home_pose

if TYPE_CHECKING:
    from controllers.features.ctc import FeatureComputedTorque


def ctc_layouts(feature: LegFeature) -> tuple[Layout, Layout]:
    """Input and output layouts of the feature's step (module docstring)."""
    m = 6 * feature.rows
    extra = (("directions", (6, 3)), ("base", (6, 3)), ("mask", m), ("frame", 12),
             ("reference_features", (3, m)))
    out = (("pose", 12), ("K", 36), ("fk_residual", 1), ("forces", 6), ("solved", 1),
           ("error", m), ("factor", (6, 6)))
    name = f"computed-torque {feature.name}"
    return Layout(_COMMON + extra, name + " input"), Layout(out, name + " output")


def ctc_function(feature: LegFeature, inverse_tolerance: float = INVERSE_TOLERANCE
                 ) -> ca.Function:
    """The step of a feature (see the module docstring)."""
    inputs = ctc_layouts(feature)[0]
    x = ca.SX.sym("x", inputs.size)
    v = inputs.split(x)
    q, qd, points = v["q"], v["q_dot"], v["points"]
    kp, kd, hold = v["gains"][0], v["gains"][1], v["gains"][2]
    R_t, residual = sx_encoder_pose(v["pose"], q, points, FK_CALLS)
    K, twist, M, h, bias = sx_model_state(R_t, qd, points, v["params"])
    G, gdot = _model_twist(R_t[9:12], twist, v["frame"])
    tau_s = G @ twist
    r, m = feature.rows, 6 * feature.rows
    ref = v["reference_features"]
    des, rate, acc_ref = ref[0:m], ref[m:2 * m], ref[2 * m:3 * m]
    zeros3 = ca.SX.zeros(3)
    es, Ls, ldots, ets, etts = [], [], [], [], []
    for i in range(6):
        u, A = v["directions"][3 * i:3 * i + 3], v["base"][3 * i:3 * i + 3]
        rows = slice(r * i, r * i + r)
        e, L = feature.block(u, q[i], A, des[rows])
        s, p = ca.vertcat(u, q[i]), ca.vertcat(A, des[rows])
        e_t, e_tt = feature.reference(s, p, tau_s, ca.vertcat(zeros3, rate[rows]),
                                      ca.vertcat(zeros3, acc_ref[rows]))
        es.append(e)
        Ls.append(L)
        ldots.append(feature.second_order(s, p, tau_s))
        ets.append(e_t)
        etts.append(e_tt)
    e, L = ca.vertcat(*es), ca.vertcat(*Ls)
    L_model = L @ G
    ldot = ca.vertcat(*ldots) + L @ gdot
    rhs = -kd * (L_model @ twist + ca.vertcat(*ets)) - kp * e - ldot - ca.vertcat(*etts)
    mask = v["mask"]
    Q, factor = ca.qr(L_model * ca.repmat(mask, 1, 6))
    acc = ca.solve(factor, Q.T @ (mask * rhs))
    a, f, solved = sx_mechanism_forces(K, M, h, bias, acc, inverse_tolerance)
    f = f + v["rotor"] * a + v["viscous"] * qd + v["coulomb"] * ca.tanh(
        (qd + hold * a) / COULOMB_SMOOTHING)
    out = ca.vertcat(R_t, ca.reshape(K, 36, 1), ca.mmax(ca.fabs(residual)), f, solved, e,
                     ca.reshape(factor.T @ factor, 36, 1))
    return ca.Function(f"hexapod_ctc_{feature.c_name}_step", [x], [ca.cse(ca.densify(out))])


def feature_ctc_step(feature: LegFeature, compiled: bool = True) -> CompiledFunction:
    """The compiled step of a feature (one per feature instance; cached on disk)."""
    cache = feature.__dict__.setdefault("_compiled_cores", {})
    key = "_ctc" + ("" if compiled else "_vm")
    if key not in cache:
        inputs, outputs = ctc_layouts(feature)
        cache[key] = CompiledFunction(ctc_function(feature), compiled, inputs, outputs)
    return cache[key]  # type: ignore[no-any-return]


class FeatureTaskStep(CompiledTaskStep):
    """:class:`~controllers.task_ctc_compiled.CompiledTaskStep` on a feature's step.

    Args:
        law: The law, reset (its context and nominal model built).
    """

    def __init__(self, law: FeatureComputedTorque) -> None:
        assert law.context is not None and law.model is not None
        self.feature = law.feature
        self.kind = law.feature.name
        self.fk = True
        self.function = feature_ctc_step(self.feature)
        self.inputs, self.outputs = ctc_layouts(self.feature)
        self._bind(np.zeros(self.function.n_in))
        g = law.context.geometry
        d = g.drives
        self.set("points", (g.base_points, g.platform_points))
        self.set("params", law.model.parameters)
        self.set("rotor", d.rotor_inertia)
        self.set("viscous", d.viscous)
        self.set("coulomb", d.coulomb)
        self.set("gains", (law.gains.kp, law.gains.kd, float(law.context.dt)))
        self.home = home_pose(g)
        out = self.outputs
        self._residual = out.index("fk_residual")
        self._solved = out.index("solved")
        self._factor = out["factor"]
        self._error = out["error"]
        self._forces = out["forces"]
        self._pose = out["pose"]
        self._tolerance = FK_TOLERANCE
        law.compiled_constants(self)

    def __setstate__(self, state: dict[str, object]) -> None:
        row = state.pop("_row")
        self.__dict__.update(state)
        self.function = feature_ctc_step(self.feature)
        assert isinstance(row, np.ndarray)
        self._bind(row)
