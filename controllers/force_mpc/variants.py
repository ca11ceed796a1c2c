"""The force-level predictive controllers of :class:`~controllers.force_mpc.controller.
ForceMPCLaw`'s two feature sets: ``leg-edge-force-mpc`` (the edge normals the camera
sees, ``leg-edge-ctc``'s reference and fallback) and ``pose-force-mpc`` (the pose of the
encoders' nominal forward kinematics, ``cartesian-ctc``'s)."""

from __future__ import annotations

import numpy as np

from controllers.base import ControllerContext, Observation
from controllers.cartesian_ctc import CartesianCTC
from controllers.feature_ctc import LegEdgeCTC
from controllers.force_mpc.controller import MAX_ITER, ForceMPCLaw
from controllers.force_mpc.problem import NS
from controllers.task_ctc import DAMPING, NATURAL_FREQUENCY_HZ
from controllers.task_ctc_inputs import camera_and_base_points
from controllers.tasks.leg_edge import EDGE_NORMALS
from controllers.tasks.platform_pose import PLATFORM_POSE

#: Default force-rate weight of the pose variant [1/N^2] (see :class:`PoseForceMPC`): the
#: edges' 1e-8 scaled by the two features' sensitivities to a translation gives 4e-10,
#: with which the plan chattered at the Coulomb friction's reversals on the tests' 10 mm
#: circle; 1e-9 halved that (``docs/dynamic-world.md``): a choice on that one case.
POSE_RATE_WEIGHT = 1e-9


class LegEdgeForceMPC(ForceMPCLaw):
    """Force-level predictive control on the leg edges (see the module docstring)."""

    name = "leg-edge-force-mpc"
    features = frozenset({"lengths", EDGE_NORMALS.field})
    feature = EDGE_NORMALS
    law_class = LegEdgeCTC

    def camera_constants(self, context: ControllerContext, v: dict[str, np.ndarray]) -> None:
        """The estimated camera's rotation and base points, the legs' radius.

        Raises:
            ContextError: No camera pose, or base points not (6, 3) finite.
        """
        cam, A_cam = camera_and_base_points(self.name, context)
        v["camera_R"][:] = np.asarray(cam.rotation, dtype=float).T.ravel()  # column-major
        v["camera_A"][:] = A_cam
        v["camera_radius"][:] = context.geometry.leg_radius

    def _features(self, observation: Observation
                  ) -> tuple[np.ndarray | None, np.ndarray] | str:
        """The observed normals (36,) and the rows seen (36,) bool, or why not."""
        if observation.normals is None:
            return "needs the edge normals (Observation.normals)"
        n = np.asarray(observation.normals, dtype=float)
        if n.shape != (6, 2, 3):
            return f"edge normals of shape {n.shape}, expected (6, 2, 3)"
        seen = np.all(np.isfinite(n), axis=-1)
        if observation.edge_visible is not None:
            seen &= np.asarray(observation.edge_visible, dtype=bool).reshape(6, 2)
        if int(seen.sum()) < 6:
            return f"fewer than six edges seen ({int(seen.sum())})"
        return n.ravel(), np.repeat(seen.ravel(), 3)

    def used(self, mask: np.ndarray) -> int | str:
        """The edges used, or why they are too few (fewer than six seen and known)."""
        edges = int(mask.sum()) // 3
        return edges if edges >= 6 else f"fewer than six edges seen and known ({edges})"

    def _reference(self, tr: float) -> tuple[np.ndarray, np.ndarray]:
        """The reference features (N, 36) of the stages at ``tr + k dt``, ``k = 1..N``,
        [s] on the reference's clock, and the rows known at every stage (36,) bool."""
        N, dt = self.horizon, self._dt
        law = self.law
        out = np.empty((N, NS))
        known = np.ones(NS, dtype=bool)
        if law.reference is None:
            taught = np.asarray(law.context.goal.normals if law.context is not None
                                else None, dtype=float).ravel()
            fine = np.isfinite(taught)
            out[:] = np.where(fine, taught, 0.0)
            return out, fine
        for k in range(N):
            ref, rows = law.compiled_reference(tr + (k + 1) * dt)
            out[k] = ref[:NS]
            if rows is not None:
                known &= rows
        return out, known


class PoseForceMPC(ForceMPCLaw):
    """Force-level predictive control on the platform pose (the pose variant): the
    features are the pose ``(t, R)`` of the encoders' nominal forward kinematics (base
    frame), the reference ``cartesian-ctc``'s (the trajectory's pose, or a quintic line
    to ``goal.rotation``/``goal.translation``), its fallback ``cartesian-ctc``.

    Args:
        rate_weight: Weight of the force rate [1/N^2] (the pose's residuals, metres and
            the chordal ``|R - R*|``, are smaller than the edges' for the same motion:
            a smaller default).
    """

    name = "pose-force-mpc"
    features = frozenset({"lengths"})
    feature = PLATFORM_POSE
    law_class = CartesianCTC

    def __init__(self, horizon: int = 10, substeps: int = 4, error_weight: float = 1.0,
                 terminal_weight: float = 1.0, rate_weight: float = POSE_RATE_WEIGHT,
                 effort_weight: float = 0.0, max_iter: int = MAX_ITER,
                 natural_frequency: float = NATURAL_FREQUENCY_HZ, damping: float = DAMPING,
                 smooth_goal: bool = True, friction_smoothing: float = 3e-3,
                 compiled: bool = True) -> None:
        super().__init__(horizon, substeps, error_weight, terminal_weight, rate_weight,
                         effort_weight, max_iter, natural_frequency, damping, smooth_goal,
                         friction_smoothing, compiled)

    def _features(self, observation: Observation
                  ) -> tuple[np.ndarray | None, np.ndarray] | str:
        """The pose of the encoders (filled in later); the rows' weights: 1 for the
        position [1/m^2], ``r^2 / 2`` for the nine of ``R`` (``|R - R*|^2 = 2 |dphi|^2``
        for a small rotation ``dphi``), ``r`` the nominal platform joints' mean distance
        to the platform's origin: the pose error weighs as the joints' displacement."""
        assert self.context is not None
        r = float(np.linalg.norm(self.context.geometry.platform_points, axis=1).mean())
        return None, np.concatenate([np.ones(3), np.full(9, r * r / 2)])

    def _reference(self, tr: float) -> tuple[np.ndarray, np.ndarray]:
        """The reference poses ``(t*, R*)`` of the stages, or the goal pose."""
        N, dt, law = self.horizon, self._dt, self.law
        out = np.empty((N, 12))
        if law.reference is None:
            R, t = law.goal_pose()
            out[:] = np.concatenate([t, np.asarray(R, dtype=float).T.ravel()])
        else:
            for k in range(N):
                row = law.pose_reference(tr + (k + 1) * dt)
                out[k, 0:3] = row[9:12]
                out[k, 3:12] = row[0:9].reshape(3, 3).T.ravel()
        return out, np.ones(12, dtype=bool)
