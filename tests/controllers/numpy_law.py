"""The numpy oracle of the vision laws' compiled cores.

The laws compute every step with their compiled core (:mod:`controllers.law_kernel`,
generated from the tasks' CasADi blocks). This module computes the same tasks with the
numpy formulas of :mod:`tests.controllers.interaction_oracle` (an independent implementation, itself
tested against finite differences of the true kinematics) and the LAPACK solve of
:func:`solve_normal_damped` (handed to the law's solver as the core's result would be,
:func:`numpy_solution`): :func:`numpy_law` is a law whose
:meth:`~controllers.laws.VisionLaw.tasks` is replaced by :func:`numpy_tasks`. The
feature selection and the estimate (which features are used, dead-reckoned and
approximated directions) are the law's own (``_select``): what is checked is the
arithmetic of the error, the interaction matrix, the rank, the solve and ``J_inv``.
"""

from __future__ import annotations

import math
import types
from dataclasses import dataclass
from typing import Any

import numpy as np

from controllers import registry
from controllers.base import Command, Observation
from controllers.law_tools import TaskStep
from controllers.leg_edge import LegEdgeController
from hexapod.kinematics import inverse_jacobian
from tests.controllers.interaction_oracle import (
    cross,
    direction_task,
    edge_line_factors,
    edge_line_task,
    edge_normal_factors,
    edge_normal_task,
)


def _unit(x: np.ndarray) -> np.ndarray:
    return x / np.sqrt(np.einsum("...k,...k->...", x, x))[..., None]


@dataclass
class Stack:
    """The features of one step: error blocks (m, 3), the interaction blocks (m, 3, 6) or
    their rank-one factors ``a`` (m, 3), ``g`` (m, 6), the used blocks (None: all)."""

    error: np.ndarray
    interaction: np.ndarray | None
    used: np.ndarray | None
    notes: list[str]
    a: np.ndarray | None = None
    g: np.ndarray | None = None

    def normal_equations(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The used error ``e`` (k,), ``L^T L`` (6, 6) and ``L^T e`` (6,)."""
        used = self.used
        err = self.error if used is None else self.error[used]
        if self.interaction is not None:
            L = (self.interaction if used is None else self.interaction[used]).reshape(-1, 6)
            e = err.reshape(-1)
            return e, L.T @ L, L.T @ e
        assert self.a is not None and self.g is not None
        a = self.a if used is None else self.a[used]
        g = self.g if used is None else self.g[used]
        w = np.einsum("ij,ij->i", a, a)
        c = np.einsum("ij,ij->i", a, err)
        return err.reshape(-1), (g.T * w) @ g, g.T @ c


def direction_stack(law: Any, obs: Observation, q: np.ndarray) -> Stack:
    """Leg directions: ``e_i = u_i x u_i*``, ``L_i = -[u_i*]_x M_i``."""
    vis = np.asarray(obs.direction_visible, dtype=bool) & law._goal_visible
    if vis.all():
        u = np.asarray(obs.directions, dtype=float)
        law.estimate.measured_all(u)
        used, notes = None, []
    else:
        sel = law._select(obs, q)
        u, used, notes = sel.features, sel.used, sel.notes
    us = law.desired_features()
    A = law.base_points
    e = cross(u, us)
    if law.interaction == "current":
        _, L = direction_task(u, us, A, q, error=False)
    else:
        _, L = direction_task(us, us, A, law._desired_lengths(q), error=False)
        if law.interaction == "mean":
            _, Lc = direction_task(u, us, A, q, error=False)
            L = 0.5 * (L + Lc)
    return Stack(e, L, used, notes)


def _edge_factors(law: Any, feat: np.ndarray, n: np.ndarray, u: np.ndarray, q: np.ndarray,
                  star: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rank-one factors of the edge blocks at (feat, n, u, q) towards ``star``."""
    q2 = np.repeat(q, 2)
    u2 = np.repeat(u, 2, axis=0)
    A2 = np.repeat(law.base_points, 2, axis=0)
    n12 = n.reshape(12, 3)
    if law.use_lines:
        K = law.line_matrix
        return edge_line_factors(feat.reshape(12, 3), star, n12, u2, A2, q2, K,
                                 np.linalg.inv(K).T)
    return edge_normal_factors(n12, star, u2, A2, q2)


def _desired_edge_interaction(law: Any, q_star: np.ndarray) -> np.ndarray:
    q2 = np.repeat(q_star, 2)
    u2 = np.repeat(law._u_star, 2, axis=0)
    A2 = np.repeat(law.base_points, 2, axis=0)
    ns = law._n_star.reshape(12, 3)
    with np.errstate(divide="ignore", invalid="ignore"):  # the goal's hidden edges: NaN rows
        if law.use_lines:
            K = law.line_matrix
            ls = law.desired_features()
            return edge_line_task(ls, ls, ns, u2, A2, q2, K, np.linalg.inv(K).T)
        return edge_normal_task(ns, ns, u2, A2, q2)


def edge_stack(law: Any, obs: Observation, q: np.ndarray) -> Stack:
    """Leg edges: ``e = f x f*``, ``L = -[f*]_x (J_l) H M_i`` (rank one per edge)."""
    vis = np.asarray(obs.edge_visible, dtype=bool) & law._goal_visible
    used: np.ndarray | None = None
    if vis.all():
        feat = np.asarray(obs.lines if law.use_lines else obs.normals, dtype=float)
        notes: list[str] = []
    else:
        sel = law._select(obs, q)
        feat, used, notes = sel.features.reshape(6, 2, 3), sel.used, sel.notes
    n = _unit(feat @ law.line_matrix) if law.use_lines else feat
    star = law.desired_features()
    u = _unit(cross(n[:, 1], n[:, 0]))
    est = law.estimate
    if used is None:
        est.measured_all(u)
    else:
        est.directions[sel.measured] = u[sel.measured]
        est.in_use[sel.measured] = u[sel.measured]
        u = np.where(np.isfinite(est.in_use[:, :1]), est.in_use, u)
    e = cross(feat.reshape(12, 3), star)
    if law.interaction == "current":
        a, g = _edge_factors(law, feat, n, u, q, star)
        return Stack(e, None, used, notes, a=a, g=g)
    L = _desired_edge_interaction(law, law._desired_lengths(q))
    if law.interaction == "mean":
        a, g = _edge_factors(law, feat, n, u, q, star)
        L = 0.5 * (L + a[:, :, None] * g[:, None, :])
    return Stack(e, L, used, notes)


def solve_normal_damped(N: np.ndarray, b: np.ndarray, threshold: float, damping2: float
                        ) -> tuple[np.ndarray, int, float]:
    """``x = (L^T L + mu^2 I)^+ L^T e`` (6,) from ``N = L^T L`` (6, 6) and ``b = L^T e``:
    ``sum_j (v_j^T b) / (w_j + damping2) v_j`` over the eigenvalues ``w_j > threshold^2
    w_max`` of ``N`` (the singular values of ``L`` below ``threshold * s_max`` count as
    zero), with the rank and the condition ``s_max / s_min`` (inf when singular)."""
    w, V = np.linalg.eigh(N)
    w_max = w[-1]
    if not w_max > 0:
        return np.zeros(len(b)), 0, math.inf
    keep = w > (threshold * threshold) * w_max
    rank = int(np.count_nonzero(keep))
    cond = math.sqrt(w_max / w[0]) if w[0] > 0 else math.inf
    c = V.T @ b
    if rank == len(w):
        c /= w + damping2
    else:
        c = np.where(keep, c / np.where(keep, w + damping2, 1.0), 0.0)
    return V @ c, rank, cond


def numpy_solution(solver: Any, N: np.ndarray, b: np.ndarray, lam: float, J: np.ndarray
                   ) -> types.SimpleNamespace:
    """What a solver reads of the compiled core's result, by numpy: ``tau = -lambda
    (L^T L + mu^2 I)^+ L^T e`` (:func:`solve_normal_damped` with the solver's threshold
    and ``damping2``), its rank and condition, ``qdot = J_inv tau`` and whether it is
    finite."""
    x, rank, cond = solve_normal_damped(N, b, solver.threshold, solver.damping2)
    tau = x * -lam
    qdot = J @ tau
    return types.SimpleNamespace(tau=tau, rank=rank, condition=cond, qdot=qdot,
                                 qdot_finite=bool(np.all(np.isfinite(qdot))))


def numpy_tasks(law: Any, observation: Observation, q: np.ndarray) -> TaskStep | Command:
    """:meth:`controllers.laws.VisionLaw.tasks` computed with numpy (``compiled``: the
    numpy solve, :func:`numpy_solution`)."""
    est = law.estimate
    stack = edge_stack if isinstance(law, LegEdgeController) else direction_stack
    st = stack(law, observation, q)  # dead-reckons hidden legs with the last twist
    est.halted()
    e, N, b = st.normal_equations()
    error_norm = math.sqrt(float(e @ e))
    if not (math.isfinite(error_norm) and math.isfinite(float(N.sum()))):
        return Command.refuse("non-finite error or interaction matrix (degenerate features)",
                              e)
    u = est.in_use
    unknown = np.flatnonzero(~np.isfinite(u[:, 0]))
    if len(unknown):
        model = law._model_directions(q)
        if model is None:
            return Command.refuse(
                f"direction of leg {int(unknown[0])} unknown (hidden since reset, no "
                "desired direction, no nominal model prediction): cannot build the "
                "inverse Jacobian", e)
        u = u.copy()
        u[unknown] = model[unknown]
        est.in_use[:] = u
        st.notes.append("nominal-model directions (forward kinematics of the measured "
                        "lengths) for never-seen legs " + ", ".join(map(str, unknown)))
    J = inverse_jacobian(law.base_points, u)
    lam = law.gain(float(np.abs(e).max()) if e.size else 0.0)
    return TaskStep(e, error_norm, N, b, lam, J, st.notes,
                    numpy_solution(law.solver, N, b, lam, J))


def numpy_law(name: str, **options: Any) -> Any:
    """The registered law ``name`` with its tasks computed by :func:`numpy_tasks`."""
    law = registry.create(name, **options)
    law.tasks = types.MethodType(numpy_tasks, law)
    return law
