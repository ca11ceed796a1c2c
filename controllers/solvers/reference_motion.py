"""The desired leg features along a pose reference and their first two time derivatives.

The feature laws' reference (:mod:`controllers.feature_ctc`) is the features the
ESTIMATED camera would see of the NOMINAL robot along a pose trajectory, anchored at the
taught goal: ``s*(t) = unit(s_taught + s_model(x*(t)) - s_model(end))`` per unit vector
(:func:`controllers.tracking.anchor_goals`). With the reference's pose ``x* = (R*, t*)``,
twist ``(v*, w*)`` and its rate (base frame, ``t*_dot = v*``, ``R*_dot = [w*]_x R*``;
:class:`hexapod.trajectory.PoseTrajectory`), the chain rule gives

``s*_dot = ds/dx x*_dot``,  ``s*_ddot = d2s/dx2 [x*_dot, x*_dot] + ds/dx x*_ddot``

(CasADi's automatic differentiation of the one symbolic model of the features below),
evaluated in C (:class:`hexapod.compiled.CompiledFunction`) over a whole reference's
control grid at once.

Input row (:func:`layouts`): the ``reference`` pose row
(:data:`~controllers.solvers.compiled_task_ctc.REFERENCE`: ``R*`` row-major, ``t*``,
twist, twist rate), the ``taught`` features (``m``) and the model's features at the
``end`` pose (``m``), the camera ``frame`` from the base (``R`` row-major, ``p``: 12),
the nominal base and platform ``points`` (2 x 6 x 3, point after point) and the leg
``radius``. Output: ``s*``, ``s*_dot``, ``s*_ddot`` (3 x ``m``). ``m`` is 36 for the
edge normals ((6, 2, 3) order), 18 for the directions.
"""

from __future__ import annotations

from functools import lru_cache, partial

import casadi as ca

from controllers.tasks.base import sx_unit
from controllers.tasks.feature_kind import BuiltinFeature
from controllers.tasks.leg_direction import LEG_DIRECTIONS
from controllers.tasks.leg_edge import EDGE_NORMALS
from controllers.tasks.platform_pose import REFERENCE
from hexapod.compiled import CompiledFunction, Layout, code_key

#: The features a reference is computed for (the feature computed-torque laws').
FEATURES = (EDGE_NORMALS, LEG_DIRECTIONS)


@lru_cache(maxsize=2)
def layouts(feature: BuiltinFeature) -> tuple[Layout, Layout]:
    """The input and output layouts of a feature's function (module docstring)."""
    m, kind = feature.task_rows, feature.kind
    return (Layout([("reference", REFERENCE.size), ("taught", m), ("end", m), ("frame", 12),
                    ("points", (2, 6, 3)), ("radius", 1)], f"{kind} reference input"),
            Layout([("features", m), ("rate", m), ("acceleration", m)],
                   f"{kind} reference output"))


def model_features(feature: BuiltinFeature, R: ca.SX, t: ca.SX, frame: ca.SX, A: ca.SX,
                   E: ca.SX, radius: ca.SX) -> ca.SX:
    """The features (``m``) of the robot at ``(R, t)`` (base frame) seen from ``frame``
    (``R`` row-major, ``p``), as :func:`vision.legs.observe_legs` computes them (all
    edges existing; :meth:`~controllers.tasks.feature_kind.BuiltinFeature.sx_of_legs`)."""
    Rf = ca.reshape(frame[0:9], 3, 3).T
    pf = frame[9:12]
    out: list[ca.SX] = []
    for i in range(6):
        Ai, Ei = A[3 * i:3 * i + 3], E[3 * i:3 * i + 3]
        u = sx_unit(R @ Ei + t - Ai)
        Ac, uc = Rf @ Ai + pf, Rf @ u
        out.extend(feature.sx_of_legs([uc], [Ac], radius))
    return ca.vertcat(*out)


def _build(feature: BuiltinFeature) -> ca.Function:
    m = feature.task_rows
    inputs = layouts(feature)[0]
    x = ca.SX.sym("x", inputs.size)
    v = inputs.split(x)
    frame, points, radius = v["frame"], v["points"], v["radius"][0]
    taught, end, A, E = v["taught"], v["end"], points[0:18], points[18:36]
    P = ca.SX.sym("P", 12)  # (R* row-major, t*)
    d1, d2 = ca.SX.sym("d1", 12), ca.SX.sym("d2", 12)
    R = ca.reshape(P[0:9], 3, 3).T
    model = model_features(feature, R, P[9:12], frame, A, E, radius)
    shifted = taught + model - end
    s = ca.vertcat(*[sx_unit(shifted[3 * j:3 * j + 3]) for j in range(m // 3)])
    sd = ca.jtimes(s, P, d1)
    sdd = ca.jtimes(sd, P, d1) + ca.jtimes(s, P, d2)
    chain = ca.Function("chain", [P, d1, d2, x], [s, sd, sdd])
    ref = REFERENCE.split(v["reference"])
    Rs = ca.reshape(ref["R"], 3, 3).T
    W = ca.skew(ref["twist"][3:6])
    p_dot = ca.vertcat(ca.reshape((W @ Rs).T, 9, 1), ref["twist"][0:3])
    p_ddot = ca.vertcat(ca.reshape(((ca.skew(ref["twist_rate"][3:6]) + W @ W) @ Rs).T, 9, 1),
                        ref["twist_rate"][0:3])
    out = chain(ca.vertcat(ref["R"], ref["t"]), p_dot, p_ddot, x)
    return ca.Function(f"hexapod_feature_reference_{feature.kind}", [x],
                       [ca.cse(ca.densify(ca.vertcat(*out)))])


#: The modules that write the expression (its :func:`~hexapod.compiled.code_key`).
KEY_MODULES = ("controllers.solvers.reference_motion", "controllers.tasks.base",
               "controllers.tasks.feature_kind", "controllers.tasks.leg_direction",
               "controllers.tasks.leg_edge", "controllers.tasks.leg_feature",
               "controllers.tasks.platform_pose", "hexapod.layout")


@lru_cache(maxsize=2)
def feature_motion(feature: BuiltinFeature) -> CompiledFunction:
    """``s*``, ``s*_dot``, ``s*_ddot`` of the anchored model features (module docstring).

    Args:
        feature: :data:`~controllers.tasks.leg_edge.EDGE_NORMALS` or
            :data:`~controllers.tasks.leg_direction.LEG_DIRECTIONS` (:data:`FEATURES`).
    """
    return CompiledFunction(partial(_build, feature), inputs=layouts(feature)[0],
                            outputs=layouts(feature)[1],
                            key=(f"hexapod_feature_reference_{feature.kind}",
                                 code_key(KEY_MODULES, feature.kind)))


__all__ = ["FEATURES", "feature_motion", "layouts", "model_features"]
