"""The first-order law core of a :class:`~controllers.features.feature.LegFeature`,
compiled to C like the built-in cores (:mod:`controllers.law_kernel`).

The same generic law as the built-ins, on the feature's own block: per leg the error and
interaction ``(e_i, L_i)`` of :meth:`~controllers.features.feature.LegFeature.block`,
weighted (0: the leg is left out exactly), accumulated into ``N = L^T W L`` and
``b = L^T W e`` (:class:`~controllers.law_algebra.WeightedNormal`), then the shared law
tail (:func:`~controllers.law_algebra.law_tail`: adaptive gain, rank and condition,
damped solve, ``J_inv``, ``q_dot``, the finiteness checks). Its inputs are those of the
leg-direction core (:func:`~controllers.law_kernel.direction_inputs`, CURRENT
interaction) with the desired feature (``6 rows``) in place of the desired directions,
so that the leg-direction law's reading of observations (visibility, dead reckoning of
hidden legs, the batched rows of :class:`~controllers.law_rows.KernelRows`) serves every
leg feature unchanged.
"""

from __future__ import annotations

import casadi as ca

from controllers.features.feature import LegFeature
from controllers.law_algebra import WeightedNormal, law_tail
from controllers.law_kernel import LawKernel, law_layouts
from hexapod.compiled import CompiledFunction, Layout

#: The per-leg inputs of the core (as the leg-direction core's).
_LEG_INPUTS = (("leg_directions", 18), ("measured", 6))


def feature_inputs(feature: LegFeature) -> tuple[tuple[str, int], ...]:
    """The core's feature block: measured directions ``u`` (6 x 3), the desired feature
    (6 x rows), ``A`` (6 x 3), ``q``, the weights (6), the directions the law knows and
    ``measured`` (per leg)."""
    return (("features", 18), ("desired", 6 * feature.rows), ("base_points", 18),
            ("lengths", 6), ("weights", 6), *_LEG_INPUTS)


def feature_layouts(feature: LegFeature) -> tuple[Layout, Layout]:
    """Input and output layouts of the feature's core (:func:`law_layouts`)."""
    return law_layouts(feature_inputs(feature), 6 * feature.rows, f"{feature.name} law")


def feature_law_function(feature: LegFeature, lean: bool = False) -> ca.Function:
    """The law core of a feature (see the module docstring)."""
    inputs = feature_layouts(feature)[0]
    x = ca.SX.sym("x", inputs.size)
    v = inputs.split(x)
    r = feature.rows
    u_measured = [v["features"][3 * i:3 * i + 3] for i in range(6)]
    given = [v["leg_directions"][3 * i:3 * i + 3] for i in range(6)]
    u = [ca.if_else(v["measured"][i] != 0, u_measured[i], given[i]) for i in range(6)]
    A = [v["base_points"][3 * i:3 * i + 3] for i in range(6)]
    acc = WeightedNormal()
    errors = []
    for i in range(6):
        e, L = feature.block(u_measured[i], v["lengths"][i], A[i],
                             v["desired"][r * i:r * i + r])
        acc.add_dense(e, L, v["weights"][i])
        errors.append(e)
    tail = law_tail(ca.vertcat(*acc.used_errors), acc.N, acc.b, u, A,
                    x[inputs["gain"].start:], lean)
    name = f"hexapod_{feature.c_name}_law" + ("_lean" if lean else "")
    return ca.Function(name, [x], [ca.vertcat(*errors, *tail, *u)])


def _compiled(feature: LegFeature, lean: bool, compiled: bool) -> CompiledFunction:
    key = ("_law_lean" if lean else "_law") + ("" if compiled else "_vm")
    cache = feature.__dict__.setdefault("_compiled_cores", {})
    if key not in cache:
        inputs, outputs = feature_layouts(feature)
        cache[key] = CompiledFunction(feature_law_function(feature, lean), compiled, inputs,
                                      outputs)
    return cache[key]  # type: ignore[no-any-return]


def feature_law_kernel(feature: LegFeature, compiled: bool = True) -> LawKernel:
    """A kernel of the feature's law (its own input buffer; the compiled code is shared
    by the feature's instance and cached on disk by content hash).

    Args:
        feature: The feature.
        compiled: C code (False: the CasADi virtual machine evaluates the same core).
    """
    return LawKernel(_compiled(feature, False, compiled),
                     lambda: _compiled(feature, True, compiled))
