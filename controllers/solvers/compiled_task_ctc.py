"""The task-space computed-torque step as one compiled CasADi function per feature.

The SAME symbolic definitions as the tasks and the nominal model, composed into one C
function per :class:`~controllers.tasks.feature_kind.BuiltinFeature` (which owns its
task's blocks, :meth:`~controllers.tasks.feature_kind.BuiltinFeature.sx_ctc_task`), as
:mod:`controllers.solvers.compiled_ctc` does for the joint-space law:

- the pose: Newton steps of the forward kinematics of the encoder lengths from a guess
  (``fk=True``), or (``fk=False``, ``vision-ctc``) the rigid fit of the nominal
  platform points to the joints ``B_i = A_i + q_i u_i`` of the legs seen (camera frame,
  :func:`_rigid_fit`), brought to the base frame; its residual (or last step) is out, the
  caller calls again from the pose reached until it converges;
- ``K``, the twist ``tau = K^-1 q_dot``, ``M``, ``h`` and ``K_dot tau``;
- the task's error, Jacobian and ``L_dot tau`` brought to the model's twist (as
  :func:`~controllers.solvers.computed_torque.task_in_model_twist`), and the reference's
  ``e_t``, ``e_tt``;
- ``tau_dot`` the least-squares solution over the rows whose ``mask`` is 1 (a plain solve
  of the square pose task), then the leg forces ``K^-T (M tau_dot + h)`` plus the
  drives' terms at the velocity the legs reach over the period ``hold``.

Off the happy path the laws refuse with the reason of the output ``status``
(:mod:`controllers.ctc_status`) or of the rank test of the output ``factor`` ``L^T L``
(by LAPACK in the caller); the numpy step this replaced is the tests' oracle
(``tests/controllers/task_ctc_oracles.py``).

Inputs (:func:`layout`): :data:`COMMON_INPUTS` (``pose`` guess ``R`` column-major and
``t``; ``q``, ``q_dot``; ``points`` ``A`` then ``E``; the 19 ``params``; the drives'
``rotor``, ``viscous``, ``coulomb``; ``gains`` ``Kp``, ``Kd``, ``hold`` [s]), the
feature's blocks (the pose ``reference``, :data:`REFERENCE`; or the measured
``normals``, ``directions``, ``of_normals``, and for a camera task ``base``, ``mask``,
``frame`` (``R`` row-major, ``p``) and ``reference_features``: desired features, rate,
acceleration), last the ``integral`` term (``Kp Ki int e dt``, subtracted from the
desired ``e_ddot``). Outputs (:func:`task_layouts`): ``pose``, ``K``, ``fk_residual``,
``forces`` [N], ``solved``, ``error``, ``factor`` and ``status``.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache, partial

import casadi as ca

from controllers.ctc_status import Status
from controllers.law_algebra import rank_screen
from controllers.solvers import compiled_ctc
from controllers.solvers.compiled_ctc import (
    FK_TOLERANCE,
    MODEL_BLOCKS,
    sx_encoder_pose,
    sx_mechanism_forces,
    sx_model_state,
    sx_status,
)
from controllers.tasks.feature_kind import BuiltinFeature
from controllers.tasks.platform_pose import REFERENCE
from hexapod.compiled import CompiledFunction, Layout, Shape, code_key
from hexapod.dynamics.drive_model import COULOMB_SMOOTHING
from hexapod.dynamics.model import INVERSE_TOLERANCE

#: The input blocks every task step starts with (module docstring): the pose guess, the
#: readings, the model's constants and the gains.
COMMON_INPUTS = (("pose", 12), ("q", 6), ("q_dot", 6), *MODEL_BLOCKS, ("gains", 3))


#: Calls of the compiled forward-kinematics Newton steps (3 iterations each) per call.
FK_CALLS = 2
#: Newton steps of the rigid fit per call.
FIT_ITERATIONS = 4
#: Size of the rigid fit's last Newton step [rad] below which it has converged (the
#: next would be of its square: the fit is exact to rounding).
FIT_TOLERANCE = 1e-8


def task_layouts(name: str, extra: Sequence[tuple[str, Shape]], m: int
                 ) -> tuple[Layout, Layout]:
    """The input and output layouts of a task step of ``m`` task rows (module docstring):
    :data:`COMMON_INPUTS`, the task's own blocks ``extra``, then the ``integral`` term
    (``m``); the outputs ``pose``, ``K``, ``fk_residual``, ``forces``, ``solved``,
    ``error`` (``m``), ``factor``, ``status`` (:func:`~controllers.solvers.
    compiled_ctc.sx_status`) and the rank ``screen`` (:func:`~controllers.law_algebra.
    rank_screen`). A plugin's step (:mod:`controllers.features.ctc_step`) has them too,
    so :class:`~controllers.task_ctc_compiled.CompiledTaskStep` drives it."""
    out = (("pose", 12), ("K", 36), ("fk_residual", 1), ("forces", 6), ("solved", 1),
           ("error", m), ("factor", (6, 6)), ("status", 1), ("screen", 2))
    return (Layout((*COMMON_INPUTS, *extra, ("integral", m)), name + " input"),
            Layout(out, name + " output"))


@lru_cache(maxsize=4)
def layout(feature: BuiltinFeature, fk: bool = True) -> tuple[Layout, Layout]:
    """The input and output layouts of a feature's step (module docstring): the
    feature's blocks (:meth:`~controllers.tasks.feature_kind.BuiltinFeature.ctc_blocks`),
    and for a task in the camera frame the ``base`` points, the row ``mask``, the
    ``frame`` and the ``reference_features``."""
    m = feature.task_rows
    extra = feature.ctc_blocks(fk)
    if feature.camera_task:
        extra = (*extra, ("base", (6, 3)), ("mask", m), ("frame", 12),
                 ("reference_features", (3, m)))
    return task_layouts(f"task computed-torque {feature.ctc_name} {'fk' if fk else 'pose'}",
                        extra, m)


def _row_major(R: ca.SX) -> ca.SX:
    return ca.reshape(R.T, 9, 1)


def model_twist(translation: ca.SX, twist: ca.SX, frame: ca.SX | None
                ) -> tuple[ca.SX, ca.SX]:
    """``G`` (6, 6) and ``G_dot tau`` (6) of
    :func:`~controllers.solvers.computed_torque.task_in_model_twist`: the task's twist is
    ``G twist`` (``twist`` the model's, about the platform's origin at ``translation``;
    ``frame`` the task frame from the base, ``R`` row-major, ``p``: 12, or None)."""
    G = ca.SX.eye(6)
    G[0:3, 3:6] = ca.skew(translation)
    gdot = ca.vertcat(ca.cross(twist[0:3], twist[3:6]), ca.SX.zeros(3))
    if frame is not None:
        Rf = ca.reshape(frame[0:9], 3, 3).T
        Ad = ca.SX.zeros(6, 6)
        Ad[0:3, 0:3] = Rf
        Ad[0:3, 3:6] = ca.skew(frame[9:12]) @ Rf
        Ad[3:6, 3:6] = Rf
        G = Ad @ G
        gdot = Ad @ gdot
    return G, gdot


def _rigid_fit(R0: ca.SX, q: ca.SX, u: ca.SX, A: ca.SX, E: ca.SX, frame: ca.SX,
               seen: ca.SX) -> tuple[ca.SX, ca.SX]:
    """The pose (``R`` column-major, ``t``: 12, base frame) of the rigid fit
    ``min sum_i w_i |R_c E_i + t_c - B_i|^2`` of the platform points ``E`` to the joints
    ``B_i = A_i + q_i u_i`` (camera frame) of the legs seen (``w_i``: ``seen``, 1.0 or
    0.0; a hidden leg's joint is never read, a NaN there stays out), and the size of
    the last step [rad]. With every leg seen the numbers are those of the plain fit
    (a weight of 1.0 multiplies exactly, the sum of the weights is 6.0).

    With ``t_c = B_mean - R_c E_mean`` the fit maximises ``tr(R_c^T C)``,
    ``C = sum (B_i - B_mean)(E_i - E_mean)^T`` (Kabsch); a Newton step on
    ``R_c <- exp([d]_x) R_c`` solves ``(tr(S) I - sym(S)) d = vee(S - S^T)`` with
    ``S = C R_c^T`` (the quadratic model of ``-tr(R_c^T C)``), from the guess ``R0``
    (base frame). The frame is the base from the camera (``R`` row-major, ``p``).
    """
    Rbc = ca.reshape(frame[0:9], 3, 3).T
    pbc = frame[9:12]
    wt = [seen[i] for i in range(6)]
    B = [ca.if_else(wt[i], A[3 * i:3 * i + 3] + q[i] * u[3 * i:3 * i + 3], ca.SX.zeros(3))
         for i in range(6)]
    P = [E[3 * i:3 * i + 3] for i in range(6)]
    n = sum(wt, ca.SX(0.0))
    bc = sum((wt[i] * B[i] for i in range(6)), ca.SX.zeros(3)) / n
    mc = sum((wt[i] * P[i] for i in range(6)), ca.SX.zeros(3)) / n
    C = sum((wt[i] * ((B[i] - bc) @ (P[i] - mc).T) for i in range(6)), ca.SX.zeros(3, 3))
    Rc = Rbc.T @ ca.reshape(R0[0:9], 3, 3)
    size = ca.SX(0.0)
    for _ in range(FIT_ITERATIONS):
        S = C @ Rc.T
        w = ca.vertcat(S[2, 1] - S[1, 2], S[0, 2] - S[2, 0], S[1, 0] - S[0, 1])
        H = ca.trace(S) * ca.SX.eye(3) - 0.5 * (S + S.T)
        d = ca.solve(H, w)
        theta = ca.fmax(ca.sqrt(ca.dot(d, d)), 1e-12)  # as hexapod.fk: no 0/0
        K = ca.skew(d)
        a = ca.sin(theta) / theta
        b = 2 * ca.sin(theta / 2) ** 2 / theta**2
        Rc = (ca.SX.eye(3) + a * K + b * (K @ K)) @ Rc
        size = theta
    tc = bc - Rc @ mc
    return ca.vertcat(ca.reshape(Rbc @ Rc, 9, 1), Rbc @ tc + pbc), size


def _build(feature: BuiltinFeature, fk: bool, inverse_tolerance: float) -> ca.Function:
    inputs = layout(feature, fk)[0]
    x = ca.SX.sym("x", inputs.size)
    v = inputs.split(x)
    q, qd, points = v["q"], v["q_dot"], v["points"]
    if fk:
        R_t, residual = sx_encoder_pose(v["pose"], q, points, FK_CALLS)
        fk_residual = ca.mmax(ca.fabs(residual))
        problem = None
    else:
        R_t, fk_residual = _rigid_fit(v["pose"], q, v["directions"], v["base"],
                                      points[18:36], v["frame"], v["seen"])
        problem = ca.if_else(ca.sum1(v["seen"]) < 3, float(Status.TOO_FEW_LEGS), 0.0)
    K, twist, M, h, bias = sx_model_state(R_t, qd, points, v["params"])
    R, t = ca.reshape(R_t[0:9], 3, 3), R_t[9:12]
    frame = v["frame"] if feature.camera_task else None  # the task's frame
    G, gdot = model_twist(t, twist, frame)
    tau_s = G @ twist
    e, L, ldot, e_t, e_tt = feature.sx_ctc_task(v, q, R, t, tau_s)
    out = sx_task_outputs(v, R_t, fk_residual, (K, twist, M, h, bias), e, L @ G,
                          ldot + L @ gdot, e_t, e_tt, v["mask"] if feature.camera_task else None,
                          inverse_tolerance, FK_TOLERANCE if fk else FIT_TOLERANCE, problem)
    return ca.Function(_name(feature, fk), [x], [ca.cse(ca.densify(out))])


def _name(feature: BuiltinFeature, fk: bool) -> str:
    return f"hexapod_ctc_{feature.ctc_name}_{'fk' if fk else 'pose'}_step"


#: The modules that write a task step's expression (its :func:`~hexapod.compiled.code_key`).
KEY_MODULES = (*compiled_ctc.KEY_MODULES, "controllers.solvers.compiled_task_ctc",
               "controllers.tasks.base", "controllers.tasks.feature_kind",
               "controllers.tasks.leg_direction", "controllers.tasks.leg_edge",
               "controllers.tasks.leg_feature", "controllers.tasks.platform_pose")


def sx_task_outputs(v: dict[str, ca.SX], R_t: ca.SX, fk_residual: ca.SX,
                    state: tuple[ca.SX, ca.SX, ca.SX, ca.SX, ca.SX], e: ca.SX, L_model: ca.SX,
                    ldot: ca.SX, e_t: ca.SX, e_tt: ca.SX, mask: ca.SX | None,
                    inverse_tolerance: float, tolerance: float = FK_TOLERANCE,
                    problem: ca.SX | None = None) -> ca.SX:
    """The output row of a task step (:func:`task_layouts`) from its task terms: the
    desired ``e_ddot = -Kd e_dot - Kp e - integral``, ``tau_dot`` from it (a plain solve,
    or least squares over the rows whose ``mask`` is 1), the leg forces with the drives'
    terms, and the row's status (:func:`~controllers.solvers.compiled_ctc.sx_status`;
    ``TOO_FEW_ROWS`` when fewer than six rows are in the ``mask``).

    Args:
        v: The input row's blocks (``q_dot``, ``gains``, the drives', ``integral``).
        R_t: The pose (``R`` column-major, ``t``: 12).
        fk_residual: The pose's residual (1).
        state: ``K``, the model's twist, ``M``, ``h`` and ``K_dot tau``
            (:func:`~controllers.solvers.compiled_ctc.sx_model_state`).
        e: The task error (m).
        L_model: The task Jacobian for the model's twist (m, 6).
        ldot: ``L_dot tau`` for the model's twist (m).
        e_t: ``e_t`` of the reference (m).
        e_tt: ``e_tt`` of the reference (m).
        mask: The rows' mask (m; None: the square task solved as it is).
        inverse_tolerance: As :func:`task_step`'s.
        tolerance: The pose's residual below which it has converged.
        problem: The input's own status code (0: none), or None.
    """
    K, twist, M, h, bias = state
    qd = v["q_dot"]
    kp, kd, hold = v["gains"][0], v["gains"][1], v["gains"][2]
    rhs = -kd * (L_model @ twist + e_t) - kp * e - ldot - e_tt - v["integral"]
    if mask is None:
        acc = ca.solve(L_model, rhs)
        factor = L_model
    else:
        Lw = L_model * ca.repmat(mask, 1, 6)
        Q, factor = ca.qr(Lw)
        acc = ca.solve(factor, Q.T @ (mask * rhs))
    a, f, solved = sx_mechanism_forces(K, M, h, bias, acc, inverse_tolerance)
    f = f + v["rotor"] * a + v["viscous"] * qd + v["coulomb"] * ca.tanh(
        (qd + hold * a) / COULOMB_SMOOTHING)
    if mask is not None:
        few = ca.if_else(ca.sum1(mask) < 6, float(Status.TOO_FEW_ROWS), 0.0)
        problem = few if problem is None else ca.if_else(problem == 0.0, few, problem)
    normal = factor.T @ factor
    out = ca.vertcat(R_t, ca.reshape(K, 36, 1), fk_residual, f, solved, e,
                     ca.reshape(normal, 36, 1))
    return ca.vertcat(out, sx_status(fk_residual, tolerance, solved, out, problem),
                      rank_screen(normal))


@lru_cache(maxsize=8)
def task_step(feature: BuiltinFeature, fk: bool,
              inverse_tolerance: float = INVERSE_TOLERANCE) -> CompiledFunction:
    """The compiled step of a feature's task (built and compiled on first use; cached on
    disk).

    Args:
        feature: :data:`~controllers.tasks.platform_pose.PLATFORM_POSE`,
            :data:`~controllers.tasks.leg_edge.EDGE_NORMALS` or
            :data:`~controllers.tasks.leg_direction.LEG_DIRECTIONS`.
        fk: The pose from the encoder lengths by Newton steps from the input pose (else
            the rigid fit to the legs seen, from the input pose; the pose only).
        inverse_tolerance: Relative residual of the inverse solve above which ``K`` is
            taken as singular.

    Raises:
        ValueError: A feature without a compiled step, or the rigid fit asked of one
            whose pose comes from the encoders.
    """
    if feature.ctc_name is None:
        raise ValueError(f"feature {feature.kind!r}: no compiled computed-torque step")
    if not fk and not feature.visual_pose:
        raise ValueError(f"feature {feature.kind!r}: the pose comes from the encoders "
                         "(fk=True)")
    fk, tolerance = bool(fk), float(inverse_tolerance)
    inputs, outputs = layout(feature, fk)
    return CompiledFunction(partial(_build, feature, fk, tolerance), inputs=inputs,
                            outputs=outputs, key=(_name(feature, fk), code_key(
                                KEY_MODULES, feature.kind, fk, tolerance)))


__all__ = ["COMMON_INPUTS", "FIT_ITERATIONS", "FIT_TOLERANCE", "FK_CALLS", "REFERENCE", "layout",
           "model_twist", "sx_task_outputs", "task_layouts", "task_step"]
