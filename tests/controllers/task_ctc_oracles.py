"""The numpy task-space computed-torque step, the test oracle of the compiled one.

``cartesian-ctc``, ``vision-ctc``, ``leg-edge-ctc``, ``leg-direction-ctc`` and a plugin
feature's CTC step through their compiled function only
(:mod:`controllers.solvers.compiled_task_ctc`, :mod:`controllers.features.ctc_step`);
this is the step they replaced, kept to check the compiled one against: the law's
measurement by numpy (:func:`numpy_measure`: the forward kinematics of
:func:`hexapod.fk.forward_kinematics`, the SVD rigid fit of the legs seen, the features
seen), its task towards the reference (:func:`numpy_desired_at`: the numpy tasks of
:mod:`controllers.tasks`) and the step (:func:`numpy_task_step`: the tasks' error,
Jacobian and second-order terms, the SVD solve of
:func:`tests.controllers.ctc_solver_oracle.acceleration`,
:meth:`hexapod.dynamics.DynamicModel.inverse`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controllers.base import Command, Observation
from controllers.cartesian_ctc import CartesianCTC, VisionCTC, directions_seen
from controllers.feature_ctc import FeatureCTC
from controllers.features.ctc import FeatureComputedTorque
from controllers.solvers.compiled_task_ctc import REFERENCE
from controllers.solvers.computed_torque import task_in_model_twist
from controllers.task_ctc import TaskComputedTorque
from controllers.task_ctc_inputs import line_to
from controllers.tasks import FeatureTask, PlatformPoseTask, Task, TaskState
from hexapod.fk import forward_kinematics
from hexapod.kinematics import Transform
from tests.controllers.ctc_solver_oracle import acceleration


@dataclass
class Measured:
    """What a law measured this period.

    Attributes:
        rotation: (3, 3) platform orientation for the dynamic model (base frame).
        translation: (3,) platform position [m].
        twist: (6,) model twist ``(v [m/s], w [rad/s])`` (base frame, origin velocity).
        state: The task state (one row), in the task's frame.
        frame: The task's frame from the base (None: the base frame itself).
        rows: (m,) bool, the task rows to use (None: all).
        note: A diagnostic (e.g. legs left out).
        inverse_jacobian: (6, 6) nominal ``K`` at the pose, or None.
    """

    rotation: np.ndarray
    translation: np.ndarray
    twist: np.ndarray
    state: TaskState
    frame: Transform | None = None
    rows: np.ndarray | None = None
    note: str | None = None
    inverse_jacobian: np.ndarray | None = None


def pose_measurement(model: object, R: np.ndarray, t: np.ndarray, q: np.ndarray,
                     q_dot: np.ndarray) -> Measured:
    """The pose task's measurement at ``(R, t)``: twist ``K^-1 q_dot`` (nominal ``K``)."""
    K = model.terms_batch(R[None], t[None], np.zeros((1, 6)))[2][0]  # type: ignore[attr-defined]
    twist = np.linalg.solve(K, q_dot)
    state = TaskState(np.zeros((1, 6, 3)), np.zeros((1, 6, 3)), q[None], None, R[None],
                      t[None])
    return Measured(R, t, twist, state, inverse_jacobian=K)


def encoder_pose(law: TaskComputedTorque, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The nominal forward kinematics of ``q`` [m] from the law's guess (not updated)."""
    assert law.context is not None
    fk = forward_kinematics(law.context.geometry, q, guess=law.guess, check_stroke=False)
    return fk.rotation, fk.translation


def numpy_measure(law: TaskComputedTorque, observation: Observation, q: np.ndarray,
                  q_dot: np.ndarray) -> Measured | str:
    """The law's measurement of this period by numpy, or why there is none."""
    assert law.model is not None
    if isinstance(law, VisionCTC):
        u, seen = directions_seen(observation.directions, observation.normals,
                                  observation.direction_visible, observation.edge_visible)
        pose = law._visual_pose(q, u, seen)
        if isinstance(pose, str):
            return pose
        m = pose_measurement(law.model, pose[0], pose[1], q, q_dot)
        if not np.all(seen):
            m.note = f"pose from legs {np.flatnonzero(seen).tolist()}"
        return m
    R, t = encoder_pose(law, q)
    m = pose_measurement(law.model, R, t, q, q_dot)
    if isinstance(law, CartesianCTC):
        return m
    assert isinstance(law, FeatureCTC)
    feats = law.features_seen(observation)
    if isinstance(feats, str):
        return feats
    u, normals, rows = feats
    m.state = TaskState(law._A[None], u[None], q[None],
                        None if normals is None else normals[None])
    m.frame, m.rows = law._frame, rows
    return m


def numpy_desired_at(law: TaskComputedTorque, tr: float | None
                     ) -> tuple[Task, np.ndarray | None, np.ndarray | None]:
    """The task towards the reference at ``tr`` [s] of the reference's clock (None: the
    fixed goal itself) with its desired value's rate and acceleration (None: at rest)."""
    if isinstance(law, CartesianCTC):
        if tr is None or law.reference is None:
            return PlatformPoseTask(*law.goal_pose()), None, None
        ref = REFERENCE.views(law.pose_reference(tr))
        return PlatformPoseTask(ref["R"], ref["t"]), ref["twist"], ref["twist_rate"]
    assert isinstance(law, FeatureCTC)
    if tr is None or law.reference is None:
        return numpy_task(law, law._taught), None, None
    s, s_dot, s_ddot = (x.reshape(law._taught.shape) for x in feature_reference(law, tr))
    return numpy_task(law, s), s_dot, s_ddot


def numpy_task(law: FeatureCTC, desired: np.ndarray) -> Task:
    """The numpy task of the law's feature towards ``desired`` features (a plugin
    feature's :class:`~controllers.tasks.FeatureTask`)."""
    if isinstance(law, FeatureComputedTorque):
        return FeatureTask(law.feature, np.asarray(desired).reshape(6, law.feature.rows))
    task: Task = law.observed_feature.task_of(desired)
    return task


def feature_reference(law: FeatureCTC, tr: float) -> np.ndarray:
    """(3, m) the law's anchored model features at ``tr`` [s], their rate and
    acceleration (NaN where its model's camera does not see them): from its control
    grid on the grid (built on first use), else computed."""
    i = law._grid_index(tr)
    if i is None:
        return law.feature_rows(np.array([tr]))[0]
    _, rows, known, _ = law.reference_grid()
    return np.where(known[i], rows[i].reshape(3, -1), np.nan)


def numpy_start(law: TaskComputedTorque, t: float, m: Measured) -> None:
    """Start the fixed goal's reference at ``t`` from the pose measured by numpy."""
    law.clock[0:2] = (1.0, t)
    if law.smooth_goal:
        assert law.context is not None
        law.reference = line_to(law.context, m.rotation, m.translation, *law.goal_pose())


def numpy_task_step(law: TaskComputedTorque, t: float, m: Measured, qd: np.ndarray,
                    limited: bool = True) -> Command:
    """The step by numpy at ``t`` [s] from the measurement ``m`` (the law started),
    under the law's saturation and integral action when ``limited``."""
    assert law.model is not None and law.context is not None
    task, rate, acc = numpy_desired_at(law, None if law.reference is None
                                       else t - law.reference_start)
    e = task.error(m.state)[0]
    L_task = task.jacobian(m.state)[0]
    L, twist_task, gdot = task_in_model_twist(L_task, m.translation, m.twist, m.frame)
    ldot = task.jacobian_dot_twist(m.state, twist_task[None])[0] + gdot
    e_t = e_tt = None
    if rate is not None and acc is not None:
        e_t, e_tt = (x[0] for x in task.reference_terms(m.state, twist_task[None],
                                                        rate[None], acc[None]))
    if law.integral_gain:  # - Kp Ki int e dt in the desired e_ddot
        term = law.integral_term(len(e))
        e_tt = term if e_tt is None else e_tt + term
    rows = np.all(np.isfinite(L), axis=1) & np.isfinite(e) & np.isfinite(ldot)
    if e_t is not None and e_tt is not None:
        rows &= np.isfinite(e_t) & np.isfinite(e_tt)
    if m.rows is not None:
        rows &= m.rows
    sol = acceleration(
        law.solver, e[rows], L[rows], ldot[rows], m.twist, None if e_t is None else e_t[rows],
        None if e_tt is None else e_tt[rows])
    if sol.reason is not None:
        return law.refuse(sol.reason, e[rows])
    f, _ = law.solver.forces(law.model, m.rotation, m.translation, m.twist, sol.acc,
                             qd, hold=float(law.context.dt),
                             inverse_jacobian=m.inverse_jacobian)
    if not np.all(np.isfinite(f)):
        return law.refuse(f"non-finite leg forces {f}")
    if limited:
        f = law.limited(f, np.concatenate([m.rotation.T.ravel(), m.translation]), qd, e,
                        rows)
    notes = [] if m.note is None else [m.note]
    return Command.of_forces(f, error=e[rows], error_norm=float(np.linalg.norm(e[rows])),
                             rank=sol.rank, condition=sol.condition,
                             features_used=int(rows.sum()), notes=notes)


def numpy_law_step(law: TaskComputedTorque, observation: Observation) -> Command:
    """The law's whole step by numpy (the readings finite; a fixed goal started from the
    numpy measurement), its pose guess advanced as the numpy law's was."""
    q = np.asarray(observation.lengths, dtype=float)
    qd = np.asarray(observation.q_dot, dtype=float)
    m = numpy_measure(law, observation, q, qd)
    if isinstance(m, str):
        return law.refuse(m)
    if not isinstance(law, VisionCTC):  # the encoders' pose: the next guess
        assert law.compiled is not None
        law.compiled.guess = (m.rotation, m.translation)
    if not law.started:
        numpy_start(law, float(observation.t), m)
    return numpy_task_step(law, float(observation.t), m, qd)


__all__ = ["Measured", "encoder_pose", "numpy_desired_at", "numpy_law_step", "numpy_measure",
           "numpy_start", "numpy_task_step", "pose_measurement"]
