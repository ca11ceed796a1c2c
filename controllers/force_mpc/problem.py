"""The force-level predictive problem, a condensed Gauss-Newton QP compiled to C (the
prediction, cost and solver in full: ``docs/dynamic-world.md``, "The force-level
predictive controllers").

Decision: the leg forces ``U = (f_0, ..., f_{N-1})`` [N] held over one period each,
single shooting, the drives' force limits as simple bounds. The NOMINAL robot's state
``x = (R, t, tau)`` (:data:`STATE`, base frame) moves by ``substeps`` steps of the
dynamic world's own integration (:func:`_step_function`); the sensitivities ``S_{k+1}
= A_k S_k + [0 .. B_k .. 0]`` come from each period's linear model frozen at its start
(:func:`_linear_function`); ``H`` and ``g`` are one CasADi function generated to C
(:func:`force_kernel`).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import casadi as ca
import numpy as np

from controllers.tasks.feature_kind import BuiltinFeature
from controllers.tasks.leg_edge import EDGE_NORMALS, sx_edge_normals
from hexapod.compiled import CompiledFunction, Layout, Shape
from hexapod.dynamics import compiled as mech

#: The state: rotation (column-major), position [m], twist [m/s, rad/s].
STATE = Layout([("R", 9), ("t", 3), ("twist", 6)], "force-MPC state")
#: The features: twelve edge normals (six legs, two edges, three components).
NS = 36
#: The nominal model's constants of a step: base and platform points [m] (base frame),
#: the 19 inertial parameters, the drives' rotor inertia [kg], viscous [N s/m] and
#: Coulomb [N] friction, and the step ``h`` [s].
MODEL = Layout([("A", (6, 3)), ("E", (6, 3)), ("params", mech.N_PARAMETERS),
                ("rotor", 6), ("viscous", 6), ("coulomb", 6), ("h", 1), ("smoothing", 1)],
               "force-MPC model constants")
#: The features' constants: the camera's rotation from the base (column-major), the
#: estimated base points in the camera frame [m] and the legs' radius [m].
CAMERA = Layout([("R", 9), ("A", (6, 3)), ("radius", 1)], "force-MPC camera constants")


@dataclass(frozen=True)
class ForceProblemSpec:
    """The structure of one problem (what the compiled kernel depends on).

    Attributes:
        horizon: ``N`` periods.
        substeps: Integration steps per period.
        feature: The features: :data:`~controllers.tasks.leg_edge.EDGE_NORMALS` (the
            edge normals, camera frame) or :data:`~controllers.tasks.platform_pose.
            PLATFORM_POSE` (``(t [m], R column-major)``, base frame).
    """

    horizon: int
    substeps: int
    feature: BuiltinFeature = EDGE_NORMALS

    def input_layout(self) -> Layout:
        """The kernel's input row."""
        N, m = self.horizon, self.feature.stage_features
        blocks: list[tuple[str, Shape]] = [
            ("state", STATE.size), ("U", 6 * N), ("f_prev", 6), ("reference", (N, m)),
            ("observed", m), ("mask", m), ("weights", 4)]
        blocks += [(f"model_{b}", MODEL.shapes[b]) for b in MODEL]
        blocks += [(f"camera_{b}", CAMERA.shapes[b]) for b in CAMERA]
        return Layout(blocks, "force-MPC kernel input")

    def output_layout(self) -> Layout:
        """The kernel's output row: the QP data, the cost, the predicted states,
        features (with the observed offset) and leg lengths [m] of stages ``1..N``."""
        N, n, m = self.horizon, 6 * self.horizon, self.feature.stage_features
        return Layout([("H", (n, n)), ("g", n), ("cost", 1), ("states", (N, STATE.size)),
                       ("features", (N, m)), ("lengths", (N, 6)), ("rates", (N, 6))],
                      "force-MPC kernel output")


def _mechanism(s: dict[str, ca.SX], m: dict[str, ca.SX], *names: str) -> tuple[ca.SX, ...]:
    """The closed-chain terms ``names`` of :func:`hexapod.dynamics.compiled.
    cached_expressions` at the state ``s`` (:data:`STATE`, split) of the nominal model
    ``m`` (:data:`MODEL`, split)."""
    sym, terms = mech.cached_expressions()
    row = ca.vertcat(s["R"], s["t"], s["twist"], ca.SX.zeros(6), m["A"], m["E"], m["params"])
    return tuple(ca.substitute(terms[k], sym, row) for k in names)


def _step_function() -> ca.Function:
    """``(x, f, c) -> x``: one integration step ``h`` of the nominal robot with force-mode
    drives, ``f`` (6) [N] inside its limits, ``c`` the model constants (:data:`MODEL`),
    written as the dynamic world's step (:mod:`hexapod.dynamics.robots_compiled`):
    ``(M + K^T diag(m_leg + m_r + h d_f) K) tau_dot = K^T (f - friction - m_r K_dot tau)
    - h_mech`` (linearly implicit in the friction's secant ``d_f``), then ``tau += h
    tau_dot``, ``t += h v``, ``R <- exp(h [w]x) R``."""
    x = ca.SX.sym("x", STATE.size)
    f = ca.SX.sym("f", 6)
    c = ca.SX.sym("c", MODEL.size)
    s = STATE.split(x)
    m = MODEL.split(c)
    M_joint, leg_mass, hb, K, qd, b = _mechanism(s, m, "M_joint", "leg_mass", "h", "K",
                                                 "q_dot", "leg_bias")
    h = m["h"]
    friction, d_friction = mech.sx_drive_friction(qd, m["viscous"], m["coulomb"])
    rotor = m["rotor"]
    lhs = mech.add_leg_masses(M_joint, K, leg_mass + rotor + h * d_friction)
    rhs = K.T @ (f - friction - rotor * b) - hb
    acc = mech.ldl_solve(lhs, rhs)
    tw_new = s["twist"] + h * acc
    t_new = s["t"] + h * tw_new[0:3]
    R_new = mech.sx_exp_so3(h * tw_new[3:6]) @ ca.reshape(s["R"], 3, 3)
    return ca.Function("force_mpc_step", [x, f, c],
                       [ca.vertcat(ca.reshape(R_new, 9, 1), t_new, tw_new)])


def _linear_function(substeps: int) -> ca.Function:
    """``(x, c) -> (A (12 x 12), B (12 x 6))``: the period's linear model in the
    perturbation ``(xi, delta tau)`` (``xi = (delta t, delta phi)``, ``R -> exp([delta
    phi]x) R``), frozen at the period's start, the friction's slope with the Coulomb
    force smoothed at ``smoothing`` [m/s] (``docs/dynamic-world.md``, "Solver")."""
    x = ca.SX.sym("x", STATE.size)
    c = ca.SX.sym("c", MODEL.size)
    s = STATE.split(x)
    m = MODEL.split(c)
    M_joint, leg_mass, K, qd = _mechanism(s, m, "M_joint", "leg_mass", "K", "q_dot")
    h = m["h"]
    # the friction's slope: viscous, and the Coulomb force smoothed at ``smoothing``
    slope = m["viscous"] + m["coulomb"] / m["smoothing"] * (
        1 - ca.tanh(qd / m["smoothing"]) ** 2)
    Mb = M_joint
    L = M_joint
    for i in range(6):
        k = K[i, :].T
        Mb += mech.symmetric_outer((leg_mass[i] + m["rotor"][i]) * k, k)
        L += mech.symmetric_outer((leg_mass[i] + m["rotor"][i] + h * slope[i]) * k, k)
    Lf, D = mech.ldl_factor(L)  # one unrolled LDL^T factorisation for the 12 columns
    rhs = ca.horzcat(Mb, h * K.T)
    PQ = ca.horzcat(*(mech.ldl_substitute(Lf, D, rhs[:, j]) for j in range(12)))
    P, Q = PQ[:, :6], PQ[:, 6:]  # tau' = P tau + Q f
    Att, Axt = ca.SX.eye(6), ca.SX(6, 6)
    Bt, Bx = ca.SX(6, 6), ca.SX(6, 6)
    for _ in range(substeps):
        Bt = P @ Bt + Q
        Att = P @ Att
        Axt = Axt + h * Att
        Bx = Bx + h * Bt
    A = ca.vertcat(ca.horzcat(ca.SX.eye(6), Axt), ca.horzcat(ca.SX(6, 6), Att))
    return ca.Function("force_mpc_linear", [x, c], [A, ca.vertcat(Bx, Bt)])


def _period_function(substeps: int) -> ca.Function:
    """``(x, f, c) -> (x_next, A, B, q_dot)``: the state after one period of ``substeps``
    steps, the linear model of :func:`_linear_function` at ``x``, and the leg rates
    ``q_dot = K tau`` [m/s] at ``x_next``."""
    step = _step_function()
    lin = _linear_function(substeps)
    xs, fs, cs = ca.SX.sym("x", STATE.size), ca.SX.sym("f", 6), ca.SX.sym("c", MODEL.size)
    xk = xs
    for _ in range(substeps):
        xk = step(xk, fs, cs)
    Ak, Bk = lin(xs, cs)
    (qd,) = _mechanism(STATE.split(xk), MODEL.split(cs), "q_dot")
    return ca.Function("force_mpc_period", [xs, fs, cs], [xk, Ak, Bk, qd])


def _features_function(feature: BuiltinFeature) -> ca.Function:
    """``(x, c, cam) -> (s, ds/dxi, lengths)``: the features of the nominal robot at a
    state (the edge normals, camera frame, or the pose ``(t, R column-major)``, base
    frame: :meth:`~controllers.tasks.feature_kind.BuiltinFeature.sx_stage_features`),
    their Jacobian (m x 6) in the pose's left perturbation ``xi = (delta t, delta phi)``
    and the leg lengths [m]."""
    x = ca.SX.sym("x", STATE.size)
    c = ca.SX.sym("c", MODEL.size)
    cam = ca.SX.sym("cam", CAMERA.size)
    st = STATE.split(x)
    m = MODEL.split(c)
    k = CAMERA.split(cam)
    R = ca.reshape(st["R"], 3, 3)
    Rc = ca.reshape(k["R"], 3, 3)
    A = ca.reshape(m["A"], 3, 6)
    E = ca.reshape(m["E"], 3, 6)
    Ac = ca.reshape(k["A"], 3, 6)
    normals, lengths = [], []
    for i in range(6):
        d = st["t"] + R @ E[:, i] - A[:, i]
        q = ca.sqrt(ca.dot(d, d))
        lengths.append(q)
        n1, n2 = sx_edge_normals(Ac[:, i], Rc @ (d / q), k["radius"])
        normals += [n1, n2]
    s = feature.sx_stage_features(st["t"], st["R"], normals)
    xi = ca.SX.sym("xi", 6)
    moved = ca.vertcat(ca.reshape((ca.SX.eye(3) + ca.skew(xi[3:6])) @ R, 9, 1),
                       st["t"] + xi[0:3], st["twist"])
    s_moved = ca.substitute(s, x, moved)
    C = ca.substitute(ca.jacobian(s_moved, xi), xi, ca.SX.zeros(6))
    return ca.Function("force_mpc_features", [x, c, cam], [s, C, ca.vertcat(*lengths)])


def kernel_function(spec: ForceProblemSpec) -> ca.Function:
    """The QP data of one Gauss-Newton iteration (module docstring) as one function of
    the input row (:meth:`ForceProblemSpec.input_layout`): an MX graph calling the
    period's and the features' SX functions (each generated to C once) and condensing
    with dense matrix products."""
    N, n, ns = spec.horizon, 6 * spec.horizon, spec.feature.stage_features
    lay = spec.input_layout()
    period = _period_function(spec.substeps)
    feats = _features_function(spec.feature)
    v = ca.MX.sym("v", lay.size)
    P = lay.split(v)
    c = ca.vertcat(*(P[f"model_{b}"] for b in MODEL))
    cam = ca.vertcat(*(P[f"camera_{b}"] for b in CAMERA))
    U = P["U"]
    w_err, w_term, w_rate, w_effort = (P["weights"][i] for i in range(4))
    mask = P["mask"]
    s0 = feats(P["state"], c, cam)[0]
    offset = P["observed"] - s0
    x = P["state"]
    S: ca.MX | None = None  # d(xi, tau)_k / d(f_0 .. f_{k-1}) (12 x 6 k)
    H = ca.MX(n, n)
    g = ca.MX(n, 1)
    cost = ca.MX(0)
    states, features, lengths, rates = [], [], [], []
    for k in range(N):
        f = U[6 * k:6 * k + 6]
        x, A, B, qd = period(x, f, c)
        S = B if S is None else ca.horzcat(A @ S, B)
        s, C, q = feats(x, c, cam)
        ref = P["reference"][k * ns:(k + 1) * ns]
        weight = w_term if k == N - 1 else w_err
        wm = weight * mask
        r = s + offset - ref
        Wr = wm * r
        Q = C.T @ (ca.repmat(wm, 1, 6) * C)  # (6 x 6) on the pose perturbation
        Sx = S[0:6, :]
        m = 6 * k + 6
        block = Sx.T @ (Q @ Sx)
        grad = Sx.T @ (C.T @ Wr)
        if m < n:
            block = ca.diagcat(block, ca.MX(n - m, n - m))
            grad = ca.vertcat(grad, ca.MX(n - m, 1))
        H = H + block
        g = g + grad
        cost = cost + 0.5 * ca.dot(r, Wr)
        states.append(x)
        features.append(s + offset)
        lengths.append(q)
        rates.append(qd)
    # force rate: sum |f_k - f_{k-1}|^2 (f_{-1} = f_prev), and effort sum |f_k|^2
    D = np.eye(n) - np.eye(n, k=-6)
    shift = ca.vertcat(P["f_prev"], ca.MX(n - 6, 1))
    dr = ca.mtimes(ca.DM(D), U) - shift
    H = H + w_rate * ca.DM(D.T @ D) + w_effort * ca.DM(np.eye(n))
    g = g + w_rate * ca.mtimes(ca.DM(D.T), dr) + w_effort * U
    cost = cost + 0.5 * w_rate * ca.dot(dr, dr) + 0.5 * w_effort * ca.dot(U, U)
    out = ca.vertcat(ca.reshape(ca.densify(H), n * n, 1), g, cost, *states, *features,
                     *lengths, *rates)
    name = spec.feature.force_mpc_name
    return ca.Function(f"{name}_{N}_{spec.substeps}", [v], [out])


@lru_cache(maxsize=8)
def force_kernel(spec: ForceProblemSpec, compile: bool = True) -> CompiledFunction:
    """The compiled kernel of ``spec`` (built on first use, the C library cached on
    disk by :mod:`hexapod.compiled`)."""
    return CompiledFunction(kernel_function(spec), compile=compile,
                            inputs=spec.input_layout(), outputs=spec.output_layout())
