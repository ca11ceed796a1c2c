"""The computed-torque step of a :class:`~controllers.tasks.leg_feature.LegFeature` as one
compiled function, built from the same symbolic parts as the built-in task steps
(:mod:`controllers.solvers.compiled_task_ctc`): the encoders' pose and the model's state
(:mod:`controllers.solvers.compiled_ctc`), per leg the feature's error, interaction,
``L_dot tau`` and the reference's ``e_t``, ``e_tt`` (by automatic differentiation of the
feature), and the built-in steps' solve and forces (:func:`~controllers.solvers.
compiled_task_ctc.sx_task_outputs`). Its layouts are the built-in direction kind's with
``6 rows`` task rows, so :class:`~controllers.task_ctc_compiled.CompiledTaskStep` drives
it (:class:`FeatureTaskStep` gives it the feature's function).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import casadi as ca

from controllers.solvers.compiled_ctc import sx_encoder_pose, sx_model_state
from controllers.solvers.compiled_task_ctc import (
    FK_CALLS,
    model_twist,
    sx_task_outputs,
    task_layouts,
)
from controllers.task_ctc_compiled import CompiledTaskStep
from controllers.tasks.leg_feature import LegFeature
from hexapod.compiled import CompiledFunction, Layout
from hexapod.dynamics.model import INVERSE_TOLERANCE

if TYPE_CHECKING:
    from controllers.features.ctc import FeatureComputedTorque


def ctc_layouts(feature: LegFeature) -> tuple[Layout, Layout]:
    """Input and output layouts of the feature's step (module docstring)."""
    m = 6 * feature.rows
    extra = (("directions", (6, 3)), ("base", (6, 3)), ("mask", m), ("frame", 12),
             ("reference_features", (3, m)))
    return task_layouts(f"computed-torque {feature.name}", extra, m)


def ctc_function(feature: LegFeature) -> ca.Function:
    """The step of a feature (see the module docstring)."""
    inputs = ctc_layouts(feature)[0]
    x = ca.SX.sym("x", inputs.size)
    v = inputs.split(x)
    q, points = v["q"], v["points"]
    R_t, residual = sx_encoder_pose(v["pose"], q, points, FK_CALLS)
    state = sx_model_state(R_t, v["q_dot"], points, v["params"])
    twist = state[1]
    G, gdot = model_twist(R_t[9:12], twist, v["frame"])
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
    L = ca.vertcat(*Ls)
    out = sx_task_outputs(v, R_t, ca.mmax(ca.fabs(residual)), state, ca.vertcat(*es), L @ G,
                          ca.vertcat(*ldots) + L @ gdot, ca.vertcat(*ets), ca.vertcat(*etts),
                          v["mask"], INVERSE_TOLERANCE)
    return ca.Function(f"hexapod_ctc_{feature.c_name}_step", [x], [ca.cse(ca.densify(out))])


def feature_ctc_step(feature: LegFeature) -> CompiledFunction:
    """The compiled step of a feature (one per feature instance; cached on disk)."""
    cache = feature.__dict__.setdefault("_compiled_cores", {})
    if "_ctc" not in cache:
        inputs, outputs = ctc_layouts(feature)
        cache["_ctc"] = CompiledFunction(ctc_function(feature), inputs=inputs, outputs=outputs)
    return cache["_ctc"]  # type: ignore[no-any-return]


class FeatureTaskStep(CompiledTaskStep):
    """:class:`~controllers.task_ctc_compiled.CompiledTaskStep` on a feature's step (its
    :meth:`make_function` hook; the pose from the encoders).

    Args:
        law: The law, reset (its context and nominal model built).
    """

    def __init__(self, law: FeatureComputedTorque) -> None:
        #: The feature whose step this is.
        self.feature = law.feature
        super().__init__(law, kind=law.feature.name, fk=True)

    def make_function(self) -> CompiledFunction:
        """The feature's compiled step (:func:`feature_ctc_step`)."""
        return feature_ctc_step(self.feature)
