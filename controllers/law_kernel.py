"""The per-step numeric core of the vision laws, compiled to C (one call per step).

A law's step is a few hundred floating-point operations over some sixty numpy calls: the
cost is the calls. The core is one CasADi SX expression built from the tasks' own blocks
(:meth:`~controllers.tasks.leg_feature.LegFeature.block`,
:func:`controllers.tasks.leg_edge.edge_block`), generated to C and called on preallocated
buffers (:class:`hexapod.compiled.CompiledFunction`). One call gives the stacked error,
``N = L^T W L`` and ``b = L^T W e`` with ``L`` at the current, desired or mean features (a
feature of weight zero left out exactly), the leg directions (measured, or the law's
estimate where a leg is not ``measured``) and the law part every feature shares
(:func:`~controllers.law_algebra.law_tail`). Layouts: :func:`law_layouts`. The numpy
formulas of ``tests/controllers/interaction_oracle.py`` are the tests' oracle.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import lru_cache, partial

import casadi as ca
import numpy as np

from controllers.law_algebra import WeightedNormal, law_tail
from controllers.law_tools import INTERACTIONS
from controllers.tasks.leg_edge import (
    EDGE_LINES,
    EDGE_NORMALS,
    EdgeFeature,
    edge_block,
    leg_direction_of_edges,
)
from controllers.tasks.leg_feature import LegFeature
from hexapod.compiled import CompiledFunction, Layout, code_key

#: Law parameters after the feature block: gain ``(lambda0, lambda_inf, lambda0')``,
#: squared threshold, squared damping (or the QP regularization).
LAW_INPUTS = (("gain", 3), ("threshold2", 1), ("damping2", 1))
#: Per-leg inputs of every core: the leg directions the law knows (used where a leg is
#: not ``measured``), and ``measured`` (1: the leg's direction comes from the features).
_LEG_INPUTS = (("leg_directions", 18), ("measured", 6))
#: After the error: ``|e|``, sum of ``N`` (a finiteness check), the rank (eigenvalues of
#: ``N`` above ``threshold^2 w_max``), the condition ``sqrt(w_max / w_min)`` (inf when
#: singular), the gain [1/s], ``tau`` (6), ``q_dot`` (6), finiteness check of ``q_dot``,
#: ``N`` (36, row-major), ``b`` (6), ``J_inv`` (36).
LAW_OUTPUTS = (("error_norm", 1), ("n_sum", 1), ("rank", 1), ("condition", 1), ("gain", 1),
               ("tau", 6), ("qdot", 6), ("qdot_check", 1), ("N", 36), ("b", 6), ("J", 36))

#: A feature a law core is built for: a leg feature or the leg edges.
Feature = LegFeature | EdgeFeature


@lru_cache(maxsize=64)
def law_layouts(feature: Feature, interaction: str = "current") -> tuple[Layout, Layout]:
    """The input and output layouts of a law core (made once per feature and
    interaction; shared, never changed).

    Input, a leg feature: measured ``u`` (6 x 3), the desired feature (6 x rows), ``A`` (6 x
    3), ``q``, the weights (6), :data:`_LEG_INPUTS`, and for the DESIRED / MEAN interaction
    the legs' desired state (:attr:`~controllers.tasks.leg_feature.LegFeature.
    desired_state_inputs`); the edges: the 12 lines or normals, desired, ``K``, ``K^-1``
    (row-major; identities for normals), ``A``, ``q``, the weights (12),
    :data:`_LEG_INPUTS`, and for DESIRED / MEAN the desired normals (12 x 3), leg
    directions ``u*`` (6 x 3) and lengths ``q*``; then :data:`LAW_INPUTS`. Output: the
    error, :data:`LAW_OUTPUTS`, the leg directions (18).
    """
    if isinstance(feature, EdgeFeature):
        name, n_error = "edge law", 36
        block: tuple[tuple[str, int], ...] = (
            ("features", 36), ("desired", 36), ("K", 9), ("K_inv", 9), ("base_points", 18),
            ("lengths", 6), ("weights", 12), *_LEG_INPUTS)
        goal_state: tuple[tuple[str, int], ...] = (
            ("desired_normals", 36), ("desired_directions", 18), ("desired_lengths", 6))
    else:
        name, n_error = f"{feature.name} law", 6 * feature.rows
        block = (("features", 18), ("desired", 6 * feature.rows), ("base_points", 18),
                 ("lengths", 6), ("weights", 6), *_LEG_INPUTS)
        goal_state = feature.desired_state_inputs
    inputs = block if interaction == "current" else (*block, *goal_state)
    return (Layout([*inputs, *LAW_INPUTS], f"{name} input"),
            Layout([("error", n_error), *LAW_OUTPUTS, ("directions", 18)], f"{name} output"))


def _check_interaction(interaction: str) -> None:
    if interaction not in INTERACTIONS:
        raise ValueError(f"interaction: expected one of {', '.join(INTERACTIONS)}, "
                         f"got {interaction!r}")


def _rows(x: ca.SX, n: int) -> list[ca.SX]:
    """The (3, 1) rows of a stacked (3 n, 1) vector."""
    return [x[3 * i:3 * i + 3] for i in range(n)]


def _leg_directions(v: dict[str, ca.SX], measured: list[ca.SX]) -> list[ca.SX]:
    """Per leg: the direction measured this period, else the given one."""
    given = _rows(v["leg_directions"], 6)
    m = v["measured"]
    return [ca.if_else(m[i] != 0, u, d) for i, (u, d) in enumerate(zip(measured, given,
                                                                         strict=True))]


def feature_law_function(feature: LegFeature, interaction: str = "current",
                         lean: bool = False) -> ca.Function:
    """The law core of a leg feature: per leg the feature's block ``(e_i, L_i)``
    (:meth:`~controllers.tasks.leg_feature.LegFeature.block`; for the ``interaction``
    ``"desired"`` or ``"mean"``, ``L_i`` at the legs' desired state or the mean), weighted
    into ``N`` and ``b``, then :func:`law_tail` (``lean``: the batched laws' core)."""
    _check_interaction(interaction)
    r = feature.rows
    inputs = law_layouts(feature, interaction)[0]
    x = ca.SX.sym("x", inputs.size)
    v = inputs.split(x)
    u = _rows(v["features"], 6)
    star = [v["desired"][r * i:r * i + r] for i in range(6)]
    A = _rows(v["base_points"], 6)
    q = [v["lengths"][i] for i in range(6)]
    w = v["weights"]
    acc = WeightedNormal()
    errors = []
    for i in range(6):
        ei, L = feature.block(u[i], q[i], A[i], star[i])
        if interaction != "current":
            us, qs = feature.desired_state(v, i)
            _, Ld = feature.block(us, qs, A[i], star[i])
            L = Ld if interaction == "desired" else 0.5 * (Ld + L)
        acc.add_dense(ei, L, w[i])
        errors.append(ei)
    directions = _leg_directions(v, u)
    tail = law_tail(ca.vertcat(*acc.used_errors), acc.N, acc.b, directions, A,
                    x[inputs["gain"].start:], lean)
    name = f"hexapod_{feature.c_name}_law" + (
        "" if interaction == "current" else f"_{interaction}") + ("_lean" if lean else "")
    return ca.Function(name, [x], [ca.vertcat(*errors, *tail, *directions)])


def _edge_function(feature: EdgeFeature, interaction: str = "current",
                   lean: bool = False) -> ca.Function:
    """Leg-edge law on pixel lines or normals (rank-one blocks, ``docs/math.md`` §6): the
    edge feature's measured normal and line matrices
    (:meth:`~controllers.tasks.leg_edge.EdgeFeature.sx_normal`,
    :meth:`~controllers.tasks.leg_edge.EdgeFeature.line_matrices`)."""
    inputs = law_layouts(feature, interaction)[0]
    x = ca.SX.sym("x", inputs.size)
    v = inputs.split(x)
    feat = _rows(v["features"], 12)
    star = _rows(v["desired"], 12)
    Kt = ca.reshape(v["K"], 3, 3)  # column-major read of a row-major K: K^T
    Kinv_t = ca.reshape(v["K_inv"], 3, 3)  # (K^-1)^T
    lines = feature.line_matrices(Kt, Kinv_t)
    A = _rows(v["base_points"], 6)
    q = [v["lengths"][i] for i in range(6)]
    w = v["weights"]
    n = [feature.sx_normal(f, Kt) for f in feat]
    u = _leg_directions(v, [leg_direction_of_edges(n[2 * i], n[2 * i + 1])
                            for i in range(6)])
    acc = WeightedNormal()
    errors = []
    inv_q = [1.0 / qi for qi in q]  # one division per leg
    if interaction != "current":
        n_star = _rows(v["desired_normals"], 12)
        u_star = _rows(v["desired_directions"], 6)
        q_star = [v["desired_lengths"][i] for i in range(6)]
        inv_q_star = [1.0 / qi for qi in q_star]
    for k in range(12):
        i = k // 2
        ek, a, g = edge_block(feat[k], star[k], n[k], u[i], A[i], q[i], inv_q[i], *lines)
        errors.append(ek)
        if interaction == "current":
            acc.add_rank_one(ek, a, g, w[k])
            continue
        # The Jacobian at the desired features: the block of the desired edge itself.
        _, ad, gd = edge_block(star[k], star[k], n_star[k], u_star[i], A[i], q_star[i],
                               inv_q_star[i], *lines)
        if interaction == "desired":
            acc.add_rank_one(ek, ad, gd, w[k])
        else:
            acc.add_dense(ek, 0.5 * (ad @ gd.T + a @ g.T), w[k])
    tail = law_tail(ca.vertcat(*acc.used_errors), acc.N, acc.b, u, A,
                    x[inputs["gain"].start:], lean)
    return ca.Function(_edge_name(feature, interaction, lean), [x],
                       [ca.vertcat(*errors, *tail, *u)])


def _edge_name(feature: EdgeFeature, interaction: str, lean: bool) -> str:
    return (f"hexapod_edge_law_{feature.kind}_w"
            + ("" if interaction == "current" else f"_{interaction}") + ("_lean" if lean else ""))


#: The modules that write the leg edges' law cores (their
#: :func:`~hexapod.compiled.code_key`).
EDGE_KEY_MODULES = ("controllers.law_algebra", "controllers.law_kernel", "controllers.law_tools",
                    "controllers.tasks.base", "controllers.tasks.feature_kind",
                    "controllers.tasks.joint_length", "controllers.tasks.leg_edge",
                    "controllers.tasks.leg_feature", "hexapod.layout")


# --------------------------------------------------------------------------- runtime
@dataclass
class LawResult:
    """One evaluation of a law kernel (fresh arrays, safe to keep in a command): the
    stacked ``error`` (m,), the :data:`LAW_OUTPUTS` by name (``tau = -lambda L^+ e``,
    ``qdot = J_inv tau`` [m/s], ``qdot_finite`` from ``qdot_check``; ``N``, ``J`` (6, 6))
    and the leg ``directions`` (6, 3) ``J`` used."""

    error: np.ndarray
    error_norm: float
    n_sum: float
    rank: int
    condition: float
    gain: float
    tau: np.ndarray
    qdot: np.ndarray
    qdot_finite: bool
    N: np.ndarray
    b: np.ndarray
    J: np.ndarray
    directions: np.ndarray


class LawKernel:
    """A compiled law core with a preallocated input vector: constants written once
    (:meth:`set`), the measured features and lengths each step into :attr:`inputs`, then
    :meth:`evaluate`.

    Args:
        function: The compiled core, with its layouts (:func:`law_layouts`), or what builds
            it on first use (then ``layouts`` are its layouts): a batched law steps its
            trials by the lean core alone, and a process that never evaluates the full core
            never builds its graph.
        lean: Builds the lean core of the same law (:func:`law_tail`), on first use.
        layouts: The core's input and output layouts (when ``function`` builds it).
    """

    def __init__(self, function: CompiledFunction | Callable[[], CompiledFunction],
                 lean: Callable[[], CompiledFunction] | None = None,
                 layouts: tuple[Layout, Layout] | None = None) -> None:
        self._function: CompiledFunction | None = None
        if isinstance(function, CompiledFunction):
            self._function = function
            layouts = function.inputs, function.outputs
        elif layouts is None:
            raise ValueError("LawKernel: a core built on first use needs its layouts")
        self._make = function
        self._lean = lean
        #: The input vector (constants set once, features and lengths each step).
        self.input_vector = np.zeros(layouts[0].size)
        #: Where each named input lies in :attr:`input_vector`.
        self.slices = layouts[0]
        #: Views of the input vector by name (write into them).
        self.inputs = layouts[0].views(self.input_vector)
        #: Where each named output lies in the output vector.
        self.outputs = layouts[1]
        self._at = {k: self.outputs.index(k) for k in ("error_norm", "n_sum", "rank",
                                                       "condition", "gain", "qdot_check")}
        # Every feature used, every leg direction measured (the common case).
        for name in ("weights", "measured"):
            if name in self.inputs:
                self.inputs[name][:] = 1.0

    def __getstate__(self) -> dict[str, object]:
        """A copy's state: the input vector, not its views by name (a copy's would be
        arrays of their own, written but never evaluated) nor the compiled core (ctypes;
        found again on first use)."""
        state = self.__dict__.copy()
        del state["inputs"]
        state["_function"] = None  # (a core given is its ``_make``)
        return state

    def __setstate__(self, state: dict[str, object]) -> None:
        self.__dict__.update(state)
        self.inputs = self.slices.views(self.input_vector)

    @property
    def function(self) -> CompiledFunction:
        """The full core (built on first use)."""
        if self._function is None:
            self._function = self._make() if callable(self._make) else self._make
        return self._function

    @property
    def lean_function(self) -> CompiledFunction:
        """The lean core (the batched laws' one; :attr:`function` without a lean one)."""
        return self.function if self._lean is None else self._lean()

    def set(self, name: str, value: np.ndarray | float | Sequence[float]) -> None:
        """Write an input (any shape with the right number of values)."""
        self.inputs[name][:] = np.asarray(value, dtype=float).reshape(-1)

    def evaluate(self) -> LawResult:
        """One call of the core on the current inputs."""
        return self.result((self._function or self.function).single(self.input_vector))

    def result(self, y: np.ndarray) -> LawResult:
        """The result of the full core's output ``y`` (n_out,) (its arrays views of it)."""
        o, at = self.outputs.slices, self._at
        return LawResult(
            error=y[o["error"]], error_norm=float(y[at["error_norm"]]),
            n_sum=float(y[at["n_sum"]]), rank=int(y[at["rank"]]),
            condition=float(y[at["condition"]]), gain=float(y[at["gain"]]),
            tau=y[o["tau"]], qdot=y[o["qdot"]], qdot_finite=y[at["qdot_check"]] == 0.0,
            N=y[o["N"]].reshape(6, 6), b=y[o["b"]], J=y[o["J"]].reshape(6, 6),
            directions=y[o["directions"]].reshape(6, 3))


@lru_cache(maxsize=64)
def _compiled_core(feature: Feature, interaction: str, lean: bool, compiled: bool
                   ) -> CompiledFunction:
    """The compiled core of a feature (shared by its kernels; cached on disk by content
    hash)."""
    layouts = law_layouts(feature, interaction)
    if feature is EDGE_NORMALS or feature is EDGE_LINES:  # built only without a library
        return CompiledFunction(partial(_edge_function, feature, interaction, lean), compiled,
                                *layouts, key=(_edge_name(feature, interaction, lean), code_key(
                                    EDGE_KEY_MODULES, feature.kind, interaction, lean)))
    make = _edge_function if isinstance(feature, EdgeFeature) else feature_law_function
    return CompiledFunction(make(feature, interaction, lean),  # type: ignore[arg-type]
                            compiled, *layouts)


def feature_law_kernel(feature: Feature, interaction: str = "current",
                       compiled: bool = True) -> LawKernel:
    """A kernel of a feature's law (its own input buffer; shared compiled code).

    Args:
        feature: A leg feature (:data:`~controllers.tasks.leg_direction.LEG_DIRECTIONS`,
            a plugin's) or the leg edges (``EDGE_LINES``, ``EDGE_NORMALS``).
        interaction: ``"current"``, ``"desired"`` or ``"mean"``.
        compiled: C code (False: the CasADi virtual machine evaluates the same core).

    Raises:
        ValueError: An unknown interaction.
    """
    _check_interaction(interaction)
    return LawKernel(partial(_compiled_core, feature, interaction, False, compiled),
                     partial(_compiled_core, feature, interaction, True, compiled),
                     law_layouts(feature, interaction))
