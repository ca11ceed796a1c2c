"""Leg-edge visual servoing: seed 002 (pixel lines) and seed 003 (normals on the sphere).

Features (``docs/math.md`` section 6), two per leg, stacked over the visible edges
(36 x 6 with all twelve):

- perspective camera: unit image lines ``l`` in normalised pixel coordinates,
  ``e = l x l*``, ``L = -[l*]_x J_l H M_i``;
- unified camera (or ``edge_feature="normals"``): interpretation-plane normals
  ``n``, ``e = n x n*``, ``L = -[n*]_x H M_i``.

The leg direction used by ``H``, ``M_i`` and ``J_inv`` is rebuilt from the two
edges of the leg, ``u = (n2 x n1) / |n2 x n1|`` (``vision/legs.py`` convention). The
compiled core (:mod:`controllers.law_kernel`, from the task's block
:func:`controllers.tasks.leg_edge.edge_block`) computes the step; hidden edges are its
zero-weight rows.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from controllers.base import ControllerContext, GoalBatch, Observation
from controllers.exceptions import ContextError
from controllers.interaction import cross
from controllers.law_tools import Selection, check_choice
from controllers.laws import VisionLaw
from controllers.tasks.base import unit
from controllers.tasks.leg_edge import EDGE_KINDS, EDGE_LINES, EDGE_NORMALS, EdgeFeature

#: Values of the ``edge_feature`` option.
EDGE_FEATURES = ("auto", "lines", "normals")


class LegEdgeController(VisionLaw):
    """Leg-edge law: pixel lines (perspective camera) or normals (unified camera).

    The options of :class:`~controllers.laws.VisionLaw` (``gain``, ``adaptive_gain``,
    ``interaction``, ``threshold``, ``damping``, ``compiled``, ``leg_rate_feedforward``;
    documented there), and:

    Args:
        edge_feature: ``"auto"`` (lines for a perspective camera, normals for a
            unified one), ``"lines"`` or ``"normals"`` (force the normals).
    """

    name = "leg-edge"
    features = frozenset({"lengths", EDGE_NORMALS.field})  # the edge feature's, at reset
    unit = "edges"

    def __init__(self, gain: float = 1.0, adaptive_gain: Sequence[float] | None = None,
                 interaction: str = "current", threshold: float = 1e-6, damping: float = 0.0,
                 edge_feature: str = "auto", compiled: bool = True,
                 leg_rate_feedforward: bool = False) -> None:
        super().__init__(gain, adaptive_gain, interaction, threshold, damping, compiled,
                         leg_rate_feedforward)
        self.edge_feature = check_choice(self.name, "edge_feature", edge_feature, EDGE_FEATURES)
        #: The edge feature object (``"auto"``: the camera's, chosen at reset).
        self.edge: EdgeFeature = EDGE_KINDS.get(edge_feature, EDGE_NORMALS)
        self.observed_feature = self.edge
        self.features = frozenset({"lengths", self.edge.field})
        #: (3, 3) the matrix mapping normals to image lines (identity for normals).
        self.line_matrix = np.eye(3)
        self._K_inv_t = np.eye(3)

    # ----------------------------------------------------------------- reset
    def _reset_features(self, context: ControllerContext) -> None:
        cam: Any = context.camera
        kind = getattr(cam, "kind", None)
        if self.edge_feature == "auto":
            self.edge = EDGE_LINES if kind == "perspective" else EDGE_NORMALS
        self.observed_feature = self.edge
        K = self.edge.line_matrix_of(cam, self.name)
        if K is not None:
            self.line_matrix = K
            self._K_inv_t = np.linalg.inv(K).T
        self.features = frozenset({"lengths", self.edge.field})
        self._retarget_features(context)

    def _retarget_features(self, context: ControllerContext) -> None:
        """The desired edges of ``context.goal`` (the camera part of the reset stays)."""
        goal = context.goal
        vis = np.ones((6, 2), dtype=bool)
        if goal.edge_visible is not None:
            gv = np.asarray(goal.edge_visible, dtype=bool)
            if gv.shape != (6, 2):
                raise ContextError(self.name, "goal.edge_visible",
                                   f"expected shape (6, 2), got {gv.shape}")
            vis &= gv
        l_star, n_star, vis = self.edge.desired_of(goal, vis, self.line_matrix, self._K_inv_t,
                                                   self.name)
        self._l_star = l_star
        if n_star is None:
            raise ContextError(self.name, "goal.normals", "missing")
        vis &= np.all(np.isfinite(n_star), axis=-1)
        if not vis.any():
            raise ContextError(self.name, "goal", "no visible desired edge")
        n_star = np.where(vis[..., None], n_star, 0.0)
        self._n_star = n_star
        self._goal_visible = vis
        # Desired directions (DESIRED / MEAN interaction): from the two desired edges,
        # else from goal.directions.
        if vis.all():
            us = unit(cross(n_star[:, 1], n_star[:, 0]))
        else:
            us = np.full((6, 3), np.nan)
            both = vis.all(axis=1)
            with np.errstate(invalid="ignore", divide="ignore"):
                us[both] = unit(cross(n_star[both, 1], n_star[both, 0]))
            gd = None if goal.directions is None else np.asarray(goal.directions, dtype=float)
            if gd is not None and gd.shape == (6, 3):
                missing = ~np.isfinite(us[:, 0]) & np.all(np.isfinite(gd), axis=1)
                us[missing] = gd[missing]
        if self.interaction != "current":
            unknown = ~np.isfinite(us[:, 0])
            if unknown.any():
                # Without u* the desired interaction of that leg cannot be built.
                self._goal_visible &= ~unknown[:, None]
                if not self._goal_visible.any():
                    raise ContextError(self.name, "goal", "no leg with a known desired direction")
        self._u_star_known = us.copy()
        self._u_star = np.where(np.isfinite(us), us, np.array([0.0, 0.0, 1.0]))
        # Fill values for hidden edges (finite arithmetic): a perpendicular pair per leg.
        fill = np.empty((6, 2, 3))
        fill[:, 0] = np.where(vis[:, 0, None], n_star[:, 0], [1.0, 0.0, 0.0])
        fill[:, 1] = np.where(vis[:, 1, None], n_star[:, 1], [0.0, 1.0, 0.0])
        self._feature_fill = self.edge.features_of(fill, self._K_inv_t)
        self._install_kernel(self.edge, desired=self.edge.desired_input(self._l_star, n_star),
                             K=self.line_matrix, K_inv=self._K_inv_t.T, desired_normals=n_star,
                             desired_directions=self._u_star)

    # ----------------------------------------------------------------- step
    def _select(self, obs: Observation, q: np.ndarray) -> Selection:
        vis = np.asarray(obs.edge_visible, dtype=bool) & self._goal_visible
        feat = np.where(vis[..., None], np.asarray(getattr(obs, self.edge.field), dtype=float),
                        self._feature_fill)
        both: np.ndarray = np.all(vis, axis=1)
        est = self.estimate
        est.predict_hidden(~both, self.base_points, self.dt)
        est.observed[:] = both
        known = np.isfinite(est.directions[:, 0]) | both
        legs = np.where(known[:, None], est.directions, np.nan)  # the core measures `both`
        # A leg never seen whole: its desired direction, projected on the plane of its
        # visible edge if it has one (exact at the goal).
        approx: np.ndarray = ~known & np.isfinite(self._u_star_known[:, 0])
        if approx.any():
            n = self.edge.normals_of(feat, self.line_matrix)
            us = self._u_star
            one: np.ndarray = np.any(vis, axis=1) & ~both
            n_vis = np.where(vis[:, 0, None], n[:, 0], n[:, 1])
            proj = np.where(one[:, None], unit(us - np.einsum("ik,ik->i", us, n_vis)[:, None]
                                                * n_vis), us)
            legs = np.where(approx[:, None], proj, legs)
        est.in_use[:] = legs
        vis = vis & (known | approx)[:, None]
        notes = self._notes(vis, ~both & known, approx, "partly hidden")
        return Selection(feat.reshape(12, 3), vis.reshape(12), both, legs, notes)

    @property
    def use_lines(self) -> bool:
        """The feature is the image lines (:data:`~controllers.tasks.leg_edge.EDGE_LINES`)."""
        return self.edge.lines

    def desired_features(self) -> np.ndarray:
        """(12, 3) the desired lines or normals (zeros where unknown)."""
        star = self.edge.desired_input(self._l_star, self._n_star)
        return np.asarray(star, dtype=float).reshape(12, 3)

    def _batch_desired(self, goals: GoalBatch) -> tuple[np.ndarray | None, np.ndarray]:
        """The goals' lines (or normals) as the compiled core's desired input, where every
        edge of the goal is visible and finite (and the goal gives both its lines and its
        normals in pixel-line mode): what :meth:`_retarget_features` reads then."""
        m = len(goals)
        edge = self.batch_feature
        n_star = goals.normals
        star = None if edge is None else getattr(goals, edge.field)
        if (edge is None or not self.compiled or self.interaction != "current"
                or n_star is None or star is None):
            return None, np.zeros(m, dtype=bool)
        vis_shape = (m, 6, 2) if goals.edge_visible is None else np.shape(goals.edge_visible)
        if (np.shape(n_star) != (m, 6, 2, 3) or np.shape(star) != (m, 6, 2, 3)
                or vis_shape != (m, 6, 2)):
            return None, np.zeros(m, dtype=bool)  # the instances say what is wrong
        with np.errstate(invalid="ignore"):
            ok = np.isfinite(n_star).reshape(m, 36).all(axis=1)
            ok &= np.isfinite(star).reshape(m, 36).all(axis=1)  # the normals again for normals
        if goals.edge_visible is not None:
            ok &= np.asarray(goals.edge_visible, dtype=bool).reshape(m, 12).all(axis=1)
        return np.asarray(star, dtype=float).reshape(m, 36), ok
