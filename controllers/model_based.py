"""Model-based baseline (what the seeds argue against; ``docs/math.md`` section 6): the
nominal forward kinematics of the leg lengths (Newton, warm-started), a pose servo to the
goal pose (``w = lambda log(R* R^T)``, ``v = lambda (t* - t) - w x t``), the twist mapped
through the nominal inverse Jacobian.

Everything after the forward kinematics (the pose error with ``log`` on SO(3), its
half-turn case included, :func:`sx_log_so3`; gain, twist, ``q_dot``, the twist in the
camera frame, the condition number of ``J_inv``) is one CasADi expression compiled to C
(:func:`pose_servo_kernel`), whose ``status`` output is a row's refusal reason. Its test
oracle: ``tests/controllers/model_based_oracle.py``. The step is C around the compiled
forward kinematics and this kernel over the rows of a batch
(:mod:`controllers.model_based_rows`); the per-trial ``step`` is a batch of one.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from functools import lru_cache

import casadi as ca
import numpy as np

from controllers.base import Controller
from controllers.data import CommandBatch, ControllerContext, Goal, ObservationBatch
from controllers.estimators import PoseEstimate
from controllers.exceptions import ContextError
from controllers.law_algebra import jacobi_eigen
from controllers.law_tools import Gain, check_count, check_flag, check_number, gain_formula
from controllers.model_based_rows import PoseServoRows
from controllers.task_ctc_inputs import goal_pose_of
from hexapod.compiled import CompiledFunction, Layout
from hexapod.exceptions import HexapodError
from hexapod.fk import forward_kinematics
from hexapod.geometry import HexapodGeometry
from hexapod.kinematics import Transform
from hexapod.workspace import home_pose

#: Input of the compiled pose servo: R (row-major), t, R*, t*, A (6 x 3), eB (6 x 3),
#: gain (lambda0, lambda_inf, lambda0'), camera_from_base rotation and translation.
SERVO_INPUTS = Layout([("R", (3, 3)), ("t", 3), ("R_star", (3, 3)), ("t_star", 3),
                       ("A", (6, 3)), ("E", (6, 3)), ("gain", 3), ("Rc", (3, 3)), ("pc", 3)],
                      "pose servo input")
#: Output: e (6), |e|, tau (6), q_dot (6), camera twist (6), condition, status (0: a
#: command; :data:`NON_FINITE`: a NaN or infinite value in ``e``, ``qdot`` or the twist).
SERVO_OUTPUTS = Layout([("e", 6), ("norm", 1), ("tau", 6), ("qdot", 6), ("twist", 6),
                        ("cond", 1), ("status", 1)], "pose servo output")
_IN, _OUT = SERVO_INPUTS, SERVO_OUTPUTS
#: The orientation error [rad] beyond which the axis comes from the symmetric part.
HALF_TURN = np.pi - 1e-3
#: Status of a row whose command is not finite.
NON_FINITE = 1
#: The refusal reason of each non-zero status.
STATUS_REASONS = {NON_FINITE: "non-finite command (numerical failure)"}


def sx_log_so3(M: ca.SX) -> ca.SX:
    """``log(M)`` (3,) [rad] of a (3, 3) rotation, the formulas of
    :func:`hexapod.se3.log_so3`: ``theta = atan2(|v| / 2, (tr M - 1) / 2)`` with ``v``
    the axial vector of ``M - M^T``; ``theta / (2 sin theta) v`` (its series below
    ``sin theta = 1e-6``); beyond :data:`HALF_TURN`, the axis is the row of
    ``(M + M^T) / 2 - cos(theta) I`` of largest diagonal entry (the first of equal ones),
    normalised, signed as ``v`` (``+`` where orthogonal), times ``theta``."""
    cos = (M[0, 0] + M[1, 1] + M[2, 2] - 1.0) / 2.0
    v = ca.vertcat(M[2, 1] - M[1, 2], M[0, 2] - M[2, 0], M[1, 0] - M[0, 1])
    theta = ca.atan2(0.5 * ca.sqrt(ca.dot(v, v)), cos)
    sin = ca.sin(theta)
    small = sin < 1e-6
    factor = ca.if_else(small, 0.5 + theta ** 2 / 12.0,
                        theta / (2.0 * ca.if_else(small, 1.0, sin)))
    B = (M + M.T) / 2.0 - ca.cos(theta) * ca.SX.eye(3)
    first = ca.logic_and(B[0, 0] >= B[1, 1], B[0, 0] >= B[2, 2])
    axis = ca.if_else(first, B[0, :].T, ca.if_else(B[1, 1] >= B[2, 2], B[1, :].T, B[2, :].T))
    axis = axis / ca.sqrt(ca.dot(axis, axis))
    sign = ca.if_else(ca.dot(axis, v) < 0.0, -1.0, 1.0)
    return ca.if_else(theta > HALF_TURN, axis * (theta * sign), factor * v)


def _pose_servo_function() -> ca.Function:
    x = ca.SX.sym("x", _IN.size)
    R = ca.reshape(x[_IN["R"]], 3, 3).T  # row-major
    t = x[_IN["t"]]
    Rs = ca.reshape(x[_IN["R_star"]], 3, 3).T
    ts = x[_IN["t_star"]]
    Rc = ca.reshape(x[_IN["Rc"]], 3, 3).T
    pc = x[_IN["pc"]]
    l0, linf, slope = (x[_IN["gain"]][k] for k in range(3))
    rot = sx_log_so3(Rs @ R.T)
    dp = ts - t
    e = ca.vertcat(-dp, -rot)
    xe = ca.mmax(ca.fabs(e))
    lam = gain_formula(xe, l0, linf, slope, ca.exp, ca.if_else)
    w = lam * rot
    tau = ca.vertcat(lam * dp - ca.cross(w, t), w)
    rows = []
    for i in range(6):
        A = x[_IN["A"]][3 * i:3 * i + 3]
        E = x[_IN["E"]][3 * i:3 * i + 3]
        leg = R @ E + t - A
        u = leg / ca.sqrt(ca.dot(leg, leg))
        rows.append(ca.horzcat(u.T, ca.cross(A, u).T))
    J = ca.vertcat(*rows)
    qdot = J @ tau
    wj, _ = jacobi_eigen(J.T @ J, vectors=False)
    w_max, w_min = wj[0], wj[0]
    for k in range(1, 6):
        w_max = ca.fmax(w_max, wj[k])
        w_min = ca.fmin(w_min, wj[k])
    cond = ca.if_else(w_min > 0, ca.sqrt(w_max / ca.if_else(w_min > 0, w_min, 1.0)), ca.inf)
    wc = Rc @ w
    twist = ca.vertcat(Rc @ tau[:3] - ca.cross(wc, pc), wc)
    # |x| <= DBL_MAX is false for NaN and inf (CasADi simplifies x - x to 0: no use).
    values = ca.vertcat(e, qdot, twist)
    finite = ca.SX(1.0)
    for k in range(values.numel()):
        finite = ca.logic_and(finite, ca.fabs(values[k]) <= np.finfo(float).max)
    status = ca.if_else(finite, 0.0, float(NON_FINITE))
    out = ca.vertcat(e, ca.sqrt(ca.dot(e, e)), tau, qdot, twist, cond, status)
    return ca.Function("hexapod_pose_servo", [x], [out])


@lru_cache(maxsize=2)
def pose_servo_kernel(compiled: bool = True) -> CompiledFunction:
    """The pose servo (everything after the forward kinematics).

    Args:
        compiled: C code (False: the CasADi virtual machine evaluates the same function).
    """
    return CompiledFunction(_pose_servo_function(), compiled, inputs=_IN, outputs=_OUT)


class ModelBasedController(Controller):
    """Forward kinematics of the measured lengths (nominal geometry) + pose servoing.

    Args:
        gain: Constant gain ``lambda`` [1/s].
        adaptive_gain: ``(lambda0, lambda_inf, lambda0')`` (overrides ``gain``), with
            ``x`` the largest entry of the pose error (metres and radians).
        fk_tolerance: Forward-kinematics residual tolerance [m].
        fk_max_iterations: Forward-kinematics iteration budget.
        compiled: The pose servo in C (False: the CasADi virtual machine evaluates the
            same function, slower).
    """

    name = "model-based"
    features = frozenset({"lengths"})

    def __init__(self, gain: float = 1.0, adaptive_gain: Sequence[float] | None = None,
                 fk_tolerance: float = 1e-11, fk_max_iterations: int = 30,
                 compiled: bool = True) -> None:
        self.gain = Gain.from_options(self.name, gain, adaptive_gain)
        self.compiled = check_flag(self.name, "compiled", compiled)
        #: The pose servo (None before :meth:`reset_trial`).
        self.kernel: CompiledFunction | None = None
        #: The servo's input row (constants written by :meth:`reset_trial`; a view of its
        #: batch's, :class:`~controllers.model_based_rows.PoseServoRows`, after the
        #: batch's reset).
        self.servo_input = np.zeros(_IN.size)
        self._rows: PoseServoRows | None = None
        self.fk_tolerance = check_number(self.name, "fk_tolerance", fk_tolerance)
        self.fk_max_iterations = check_count(self.name, "fk_max_iterations",
                                             fk_max_iterations, 1)  # (2.5 was 2)
        self.context: ControllerContext | None = None

    def reset_trial(self, context: ControllerContext) -> None:
        """Read the nominal geometry and the goal pose (or the goal lengths).

        Raises:
            ContextError: No goal pose and no goal lengths, or invalid values.
        """
        geo = context.geometry
        self.servo_input = np.zeros(_IN.size)  # its own (not a view of a former batch's)
        self._aim(context.goal, geo)
        self.context = context
        self.kernel = pose_servo_kernel(self.compiled)
        #: The last pose of the forward kinematics (its next warm start).
        self.estimate = PoseEstimate.of(*home_pose(geo))
        #: (6, 3) nominal base points ``A_i`` [m].
        self.base_points = np.asarray(geo.base_points, dtype=float)
        #: (6, 3) nominal platform points ``E_i`` in the platform frame [m].
        self.platform_points = np.asarray(geo.platform_points, dtype=float)
        pose = getattr(context.camera, "camera_from_base", None)
        cam_pose = pose if isinstance(pose, Transform) else None
        #: Where the command's twist is expressed (None: no twist).
        self.camera_from_base: Transform | None = cam_pose
        x = self.servo_input
        x[_IN["A"]] = self.base_points.reshape(18)
        x[_IN["E"]] = self.platform_points.reshape(18)
        g = self.gain
        x[_IN["gain"]] = (g.at_zero, g.at_infinity, g.slope_at_zero)
        x[_IN["Rc"]] = (np.eye(3) if cam_pose is None else cam_pose.rotation).reshape(9)
        x[_IN["pc"]] = 0.0 if cam_pose is None else cam_pose.translation

    def retarget_trial(self, goal: Goal) -> None:
        """A new goal pose, keeping the forward kinematics' warm start (the goal of each
        period of a trajectory task, :mod:`controllers.tracking`).

        Raises:
            ContextError: :meth:`reset_trial` was not called, or the goal is invalid (as in
                :meth:`reset_trial`).
        """
        if self.context is None:
            raise ContextError(self.name, "context", "retarget(goal) before reset(context)")
        self._aim(goal, self.context.geometry)
        self.context = replace(self.context, goal=goal)

    def _aim(self, goal: Goal, geo: HexapodGeometry) -> None:
        """Write the goal pose into the servo input: ``goal.rotation`` and
        ``goal.translation``, else the nominal forward kinematics of ``goal.lengths``.

        Raises:
            ContextError: Neither, or invalid values.
        """
        if goal.rotation is not None and goal.translation is not None:
            R, t = goal_pose_of(self.name, goal, geo)
        elif goal.lengths is not None:
            try:
                sol = forward_kinematics(geo, np.asarray(goal.lengths, dtype=float),
                                         check_stroke=False)
            except (HexapodError, ValueError) as exc:
                raise ContextError(self.name, "goal.lengths",
                                   f"no nominal pose for them: {exc}") from None
            R, t = sol.rotation, sol.translation
        else:
            raise ContextError(self.name, "goal", "needs rotation and translation (or lengths)")
        self.servo_input[_IN["R_star"]] = R.reshape(9)
        self.servo_input[_IN["t_star"]] = t

    # ------------------------------------------------------------------ the batch
    def reset_batch(self, contexts: Sequence[ControllerContext]) -> None:
        """One instance per context (this one first, the others built with its options),
        reset with it, then the batch's arrays (:meth:`_batch_rows`).

        Raises:
            ContextError: A context the controller cannot use.
            CompilationError: No compiled C.
        """
        super().reset_batch(contexts)
        self._rows = None
        if self.trial_instances:
            self._batch_rows()

    def _batch_rows(self) -> PoseServoRows:
        """The arrays of the trial instances' batch (:class:`PoseServoRows`), built."""
        self._rows = PoseServoRows(self.trial_instances)
        #: The forward kinematics' warm starts of every trial (the instances' rows).
        self.batch_estimate = self._rows.estimate
        return self._rows

    def __getstate__(self) -> dict[str, object]:
        """Copyable: the batch (its C context's addresses) left out, built again at the
        next step from copies of this trial's servo input and estimate."""
        state = self.__dict__.copy()
        state["_rows"] = None
        state.pop("batch_estimate", None)
        if "estimate" in state:  # (after a reset)
            state["estimate"] = PoseEstimate.of(*self.estimate.pose)
        state["servo_input"] = self.servo_input.copy()
        return state

    def step_batch(self, observations: ObservationBatch) -> CommandBatch:
        """The commands of every row (:meth:`PoseServoRows.step`: the forward kinematics,
        then the pose servo; refused, zero, with a reason where the lengths or the time
        are not finite, the forward kinematics fails or the command is not finite)."""
        self.crashes = {}
        if (unreset := self.checked_batch(observations)) is not None:
            return unreset
        out = CommandBatch.zeros(len(observations))
        rows = self._rows
        if rows is None or rows.laws is not self.trial_instances:  # (a copy: built again)
            rows = self._batch_rows()
        if len(observations):
            rows.step(observations, out)
        return out
