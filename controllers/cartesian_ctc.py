"""Cartesian computed torque: ``cartesian-ctc`` (pose from the encoders) and
``vision-ctc`` (pose from the legs the camera sees, Paccot et al. ICRA 2008).

Both regulate the platform-pose task (:class:`~controllers.tasks.PlatformPoseTask`,
``e = (t - t*, log(R R*^T))``, base frame) with the
:class:`~controllers.solvers.computed_torque.ComputedTorqueSolver`: the pose error obeys
``e_ddot + 2 zeta omega_n e_dot + omega_n^2 e = 0`` when the model is exact. They
command leg forces and need ``Observation.q_dot`` (the dynamic world).

Models (never the world's truth): the context's NOMINAL geometry (base and platform
points, strokes, speed limit), its nominal inertia and drives (the dynamic model), the
ESTIMATED base points ``A_i`` and camera pose (``vision-ctc``).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg.lapack import dgesdd as _svd

from controllers.base import ControllerContext, Goal, Observation, ObservationBatch
from controllers.ctc_status import Status, status_reason
from controllers.task_ctc import CompiledTaskStep, TaskComputedTorque
from controllers.task_ctc_inputs import camera_and_base_points, goal_pose_of
from controllers.task_ctc_rows import TaskRows
from controllers.tasks.platform_pose import PLATFORM_POSE
from hexapod.geometry import HexapodGeometry
from hexapod.kinematics import Transform

#: Smallest second singular value of the seen platform points about their centroid,
#: relative to the platform radius, for a pose fit (collinear points give none).
SPREAD = 1e-2


class CartesianCTC(TaskComputedTorque):
    """Cartesian computed torque with the pose from the forward kinematics of the encoders.

    Model: the nominal geometry's forward kinematics of the encoder lengths gives the
    pose, ``tau = K^-1 q_dot`` its twist (``K`` the nominal inverse Jacobian); the
    nominal dynamic model maps the platform acceleration to leg forces. The reference
    pose, twist and acceleration come from ``context.reference`` (base frame) or a
    quintic line to the fixed ``goal.rotation``/``goal.translation`` (the nominal base
    frame). Under a geometric calibration error the encoders' pose is wrong and so is
    the pose the robot settles at (the joint-space baseline's weakness, kept).

    Args:
        natural_frequency: Natural frequency ``f_n`` [Hz] of the error's second-order
            response (default 2 Hz: ``omega_n dt = 0.25`` at 20 ms).
        damping: Damping ratio ``zeta`` of that response (default 1).
        smooth_goal: Reach a fixed goal along a quintic line (False: a step).
    """

    name = "cartesian-ctc"
    features = frozenset({"lengths"})
    compiled_kind = PLATFORM_POSE
    batch_measurement: tuple[str, str, str, str | None] | tuple[()] | None = ()

    def take_goal(self, goal: Goal) -> None:
        """The fixed goal pose (``goal.rotation``, ``goal.translation``)."""
        self._goal = goal_pose_of(self.name, goal, self._geometry())

    def goal_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """The fixed goal pose."""
        return self._goal

    def _geometry(self) -> HexapodGeometry | None:
        """The nominal geometry a goal pose is checked on (None before a reset)."""
        return None if self.context is None else self.context.geometry

    def compiled_inputs(self, step: CompiledTaskStep, observation: Observation, tr: float,
                        q: np.ndarray) -> tuple[np.ndarray | None, str | None] | str:
        """The reference (the pose comes from the encoders in the compiled step)."""
        step.set("reference", self.reference_row(tr))
        return None, None

    def reference_row(self, tr: float) -> np.ndarray:
        """(24,) the reference at ``tr`` [s] as the compiled step takes it: ``R*``
        (row-major), ``t*``, twist, twist rate (:meth:`pose_reference`; without a
        reference the fixed goal at rest)."""
        if self.reference is None:
            R, t = self.goal_pose()
            return np.concatenate([R.ravel(), t, np.zeros(12)])
        return self.pose_reference(tr)

    def batch_grid(self) -> tuple[np.ndarray, np.ndarray | None] | None:
        """The reference on the control grid (:meth:`pose_grid`), every row known."""
        return None if self.reference is None else (self.pose_grid(), None)



class VisionCTC(CartesianCTC):
    """Cartesian computed torque with the pose the camera sees of the legs (Paccot et al.
    2008, with leg observation instead of a target on the platform).

    Measurement: the platform joints ``B_i = A_i + q_i u_i`` in the camera frame from the
    ESTIMATED base points ``A_i`` (context), the leg directions ``u_i`` seen (the
    observation's directions, else those of the edge normals, ``u = n2 x n1``) and the
    encoder lengths; the rigid fit (Kabsch) of the NOMINAL platform points to them gives
    the pose, expressed in the base frame through the ESTIMATED camera pose. Hidden legs
    are left out (at least three non-collinear joints, else a refusal with the reason).
    The twist is ``K(x)^-1 q_dot`` with the nominal inverse Jacobian at that visual pose,
    as Paccot et al. did (the camera gives the pose, the encoders its rate).

    Goal: the pose reconstructed the same way from the TAUGHT goal (its directions or
    edge normals and ``goal.lengths``), so that a bias of the reconstruction is the same
    at the goal and cancels there; without taught directions, ``goal.rotation`` and
    ``goal.translation``. A reference trajectory (``context.reference``) is moved by the
    rigid offset between its end pose and that taught pose (it ends at the taught goal).

    Args:
        natural_frequency: Natural frequency ``f_n`` [Hz] of the error's second-order
            response (default 2 Hz).
        damping: Damping ratio ``zeta`` of that response (default 1).
        smooth_goal: Reach a fixed goal along a quintic line (False: a step).
    """

    name = "vision-ctc"
    features = frozenset({"lengths", "directions"})
    compiled_fk = False
    batch_measurement = ("directions", "direction_visible", "directions", "seen")

    def prepare(self, context: ControllerContext) -> None:
        """Check the camera and base points; anchor a reference at the taught goal.

        Raises:
            ContextError: No camera pose, or base points not (6, 3) finite.
        """
        cam, _ = camera_and_base_points(self.name, context)
        self._base_from_camera = cam.inverse()
        #: Whether each set of legs seen is collinear on the platform (by its mask).
        self._collinear_sets: dict[bytes, bool] = {}
        self._offset: Transform | None = None
        taught = self._taught(context.goal)
        if context.reference is not None and taught is not None:
            end = context.reference.at(np.array([context.reference.duration]))
            Re, te = end.rotation[0], end.translation[0]
            Rd = taught[0] @ Re.T
            self._offset = Transform(Rd, taught[1] - Rd @ te)

    def take_goal(self, goal: Goal) -> None:
        """The taught visual goal pose, else ``goal.rotation``/``goal.translation``."""
        taught = self._taught(goal)
        self._goal = (taught if taught is not None
                      else goal_pose_of(self.name, goal, self._geometry()))

    def _taught(self, goal: Goal) -> tuple[np.ndarray, np.ndarray] | None:
        if goal.lengths is None or (goal.directions is None and goal.normals is None):
            return None
        u, seen = directions_seen(goal.directions, goal.normals, None, None)
        pose = self._visual_pose(np.asarray(goal.lengths, dtype=float), u, seen)
        return None if isinstance(pose, str) else pose

    def _visual_pose(self, q: np.ndarray, u: np.ndarray, seen: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray] | str:
        assert self.context is not None
        seen = seen & np.isfinite(q)
        n = int(seen.sum())
        if n < 3:
            return status_reason(Status.TOO_FEW_LEGS, legs=np.flatnonzero(seen).tolist())
        A = np.asarray(self.context.base_points)
        E = np.asarray(self.context.geometry.platform_points)
        if n < 6:
            if self.collinear(seen):
                return status_reason(Status.COLLINEAR_LEGS,
                                     legs=np.flatnonzero(seen).tolist())
            A, q, u, E = A[seen], q[seen], u[seen], E[seen]
        Rc, tc = rigid_fit(A + q[:, None] * u, E)
        bc = self._base_from_camera
        return bc.rotation @ Rc, bc.rotation @ tc + bc.translation

    def anchor(self, R: np.ndarray, t: np.ndarray, twist: np.ndarray, twist_rate: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``context.reference`` moved rigidly to end at the taught goal (``R' = D R``,
        ``t' = D t + d``: the twist and its rate turn with ``D``); the smooth line as it
        is."""
        ctx = self.context
        if self._offset is None or ctx is None or self.reference is not ctx.reference:
            return R, t, twist, twist_rate
        D = self._offset.rotation

        def turn(x: np.ndarray) -> np.ndarray:  # (m, 6) -> each half turned by D
            return (x.reshape(-1, 2, 3) @ D.T).reshape(-1, 6)  # type: ignore[no-any-return]

        return (D @ R, t @ D.T + self._offset.translation, turn(twist), turn(twist_rate))

    def compiled_inputs(self, step: CompiledTaskStep, observation: Observation, tr: float,
                        q: np.ndarray) -> tuple[np.ndarray | None, str | None] | str:
        """The leg directions seen and which legs the compiled step fits the pose to (the
        legs seen; fewer than three: its status says so; collinear ones on the platform
        give no pose: the reason), and the reference."""
        u = every_seen(observation.directions, observation.direction_visible)
        note = None
        if u is not None and u.shape == (6, 3):  # every leg seen: the common case
            step.views["seen"][:] = 1.0
        else:  # directions_seen decides, off the common case
            u, seen = directions_seen(observation.directions, observation.normals,
                                      observation.direction_visible,
                                      observation.edge_visible)
            step.views["seen"][:] = seen
            if not seen.all():
                legs = np.flatnonzero(seen).tolist()
                if len(legs) >= 3 and self.collinear(seen):
                    return status_reason(Status.COLLINEAR_LEGS, legs=legs)
                u = np.where(seen[:, None], u, 0.0)  # a hidden leg's stand-in (not read)
                note = f"pose from legs {legs}"
        step.row[step.inputs["directions"]] = u.ravel()
        step.set("reference", self.reference_row(tr))
        return None, note

    def collinear(self, seen: np.ndarray) -> bool:
        """Whether the platform points of the legs ``seen`` (6,) are collinear (their
        second singular value about their centroid below :data:`SPREAD` times the
        platform's radius): no pose fits them. Found once per set of legs."""
        key = np.asarray(seen, dtype=bool).tobytes()
        known = self._collinear_sets.get(key)
        if known is None:
            assert self.context is not None
            E = np.asarray(self.context.geometry.platform_points)
            s = np.linalg.svd(E[seen] - E[seen].mean(axis=0), compute_uv=False)
            known = bool(s[1] < SPREAD * float(np.linalg.norm(E, axis=1).max()))
            self._collinear_sets[key] = known
        return known

    def batch_partly_seen(self, rows_batch: TaskRows, step: CompiledTaskStep,
                          X: np.ndarray, observations: ObservationBatch,
                          candidates: np.ndarray
                          ) -> dict[int, tuple[np.ndarray | None, str | None]]:
        """The candidate rows with three to five legs seen, not collinear on the
        platform: their directions (a hidden leg's 0.0) and legs seen, as
        :meth:`compiled_inputs` writes them (every task row used, its note); the others
        are left to it (which refuses them)."""
        if (observations.directions is None or observations.direction_visible is None
                or np.shape(observations.directions)[1:] != (6, 3)):
            return {}
        inputs = step.inputs
        done: dict[int, tuple[np.ndarray | None, str | None]] = {}
        for j in np.flatnonzero(candidates).tolist():
            u = np.asarray(observations.directions[j], dtype=float)
            seen = np.asarray(observations.direction_visible[j], dtype=bool).copy()
            with np.errstate(invalid="ignore"):
                seen &= np.all(np.isfinite(u), axis=-1)
            count = int(seen.sum())
            if count < 3 or count == 6:
                continue
            law = rows_batch.laws[int(observations.trials[j])]
            if not isinstance(law, VisionCTC) or law.collinear(seen):
                continue
            X[j, inputs["directions"]] = np.where(seen[:, None], u, 0.0).ravel()
            X[j, inputs["seen"]] = seen
            done[j] = (None, f"pose from legs {np.flatnonzero(seen).tolist()}")
        return done

    def compiled_constants(self, step: CompiledTaskStep) -> None:
        """The estimated base points (camera frame) and camera pose."""
        assert self.context is not None
        bc = self._base_from_camera
        step.set("base", np.asarray(self.context.base_points, dtype=float).ravel())
        step.set("frame", np.concatenate([bc.rotation.ravel(), bc.translation]))


def directions_seen(directions: np.ndarray | None, normals: np.ndarray | None,
                    direction_visible: np.ndarray | None, edge_visible: np.ndarray | None
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Leg directions (6, 3) and which are seen (6,): the given directions, else those of
    both edge normals of a leg; a non-finite one is not seen."""
    from vision.legs import directions_from_edges

    if directions is not None:
        u = np.asarray(directions, dtype=float)
        seen = np.ones(6, bool) if direction_visible is None else np.asarray(
            direction_visible, bool).copy()
    elif normals is not None:
        with np.errstate(invalid="ignore", divide="ignore"):
            u = directions_from_edges(np.asarray(normals, dtype=float))
        seen = np.ones(6, bool) if edge_visible is None else np.all(
            np.asarray(edge_visible, bool), axis=-1)
    else:
        return np.full((6, 3), np.nan), np.zeros(6, bool)
    seen &= np.all(np.isfinite(u), axis=-1)
    return u, seen


def all_seen(visible: np.ndarray | None) -> bool:
    """No visibility flags, or all of them set (none zero: ``count_nonzero``, the
    cheapest test of an array)."""
    if visible is None:
        return True
    return bool(np.count_nonzero(visible) == np.size(visible))


def every_seen(values: np.ndarray | None, visible: np.ndarray | None) -> np.ndarray | None:
    """``values`` as a float array when given, all marked seen (:func:`all_seen`) and
    finite (a NaN or inf makes the sum so); else None, where :func:`directions_seen`
    decides (when both answer, they give the same values)."""
    if values is None:
        return None
    x = np.asarray(values, dtype=float)
    return x if all_seen(visible) and math.isfinite(x.sum()) else None


def rigid_fit(points: np.ndarray, model_points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rigid fit ``(R, t) = argmin sum_i |R m_i + t - p_i|^2`` (Kabsch, a proper
    rotation) of :func:`controllers.mpc.prediction.fit_pose` with equal weights, by one
    direct LAPACK call (``gesdd``, as ``numpy.linalg.svd``) for the step's budget.

    Args:
        points: (n, 3) target points ``p_i`` [m].
        model_points: (n, 3) model points ``m_i`` [m] (at least three, not collinear).
    """
    pc = points.mean(axis=0)
    mc = model_points.mean(axis=0)
    U, _, Vt, info = _svd((points - pc).T @ (model_points - mc))
    if info != 0:
        from controllers.mpc.prediction import fit_pose

        return fit_pose(points, model_points)
    R = U @ Vt
    det = (R[0, 0] * (R[1, 1] * R[2, 2] - R[1, 2] * R[2, 1])
           - R[0, 1] * (R[1, 0] * R[2, 2] - R[1, 2] * R[2, 0])
           + R[0, 2] * (R[1, 0] * R[2, 1] - R[1, 1] * R[2, 0]))
    if det < 0:  # a reflection: the last singular direction turned
        U[:, 2] = -U[:, 2]
        R = U @ Vt
    return R, pc - R @ mc
