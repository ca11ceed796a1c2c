"""The predictive problem (``docs/math.md`` section 6, "Predictive variant" and
"Drive-aware prediction"): a condensed Gauss-Newton QP per SQP iteration, compiled to C.

Decision: the camera-frame twists ``U = (tau_0, ..., tau_{N-1})``, single shooting (the
predicted states are functions of ``U`` only: ``6 N`` variables, no equality, a dense
active-set QP). Every stage bound is relaxed to the current value when the robot is
already beyond it (``U = 0`` stays feasible); the first speed row is merged with the
first-period stroke window, as in :mod:`controllers.qp`.

Each SQP iteration linearises the stage values ``v_k(x_k)`` w.r.t. a left pose
perturbation ``xi = (v, w)`` and carries it to ``U`` with ``D_{k+1} = Ad(E_k) D_k +
[0 .. B_k ..]``, ``E_k = exp(dt tau_k)``, ``B_k`` the left Jacobian of the step: the
Gauss-Newton Hessian ``sum_k D_k^T (G_k^T W G_k) D_k`` costs ``O(N^2)`` 6 x 6 products.
The local model is the same with ``Ad = I``, ``B_k = dt I`` and ``G_k`` frozen (one QP
solves it). One CasADi function generated to C (:func:`problem_kernel`);
:mod:`controllers.mpc.solver` solves the QPs.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import casadi as ca

from controllers.mpc.prediction import sx_exp_se3, sx_legs, sx_pixel
from controllers.tasks.feature_kind import BuiltinFeature
from controllers.tasks.leg_edge import sx_edge_normals
from hexapod.compiled import CompiledFunction, Layout

#: Upper bound used for one-sided rows (the tilt cosine never exceeds 1).
_BIG = 1e20


@dataclass(frozen=True)
class ProblemSpec:
    """The structure of one problem (what the compiled kernel depends on): the predicted
    feature (of :data:`~controllers.mpc.prediction.FEATURE_KINDS`), the ``"local"`` or
    ``"global"`` model, the horizon ``N``, whether the tilt rows, the image-bound rows
    (perspective camera) and the drives' lag (:func:`_drive_blocks`) are in it."""

    feature: BuiltinFeature
    model: str
    horizon: int
    tilt: bool
    visibility: bool
    drives: bool = False

    @property
    def stage_rows(self) -> int:
        """Constraint rows of one stage: strokes, tilt, visibility (both ends of 12 edges)."""
        return 6 + (1 if self.tilt else 0) + (48 if self.visibility else 0)

    @property
    def rows(self) -> int:
        """All constraint rows: stages, then the speed rows of every move."""
        return self.horizon * (self.stage_rows + 6)

    def input_layout(self) -> Layout:
        """Layout of the kernel input (see :func:`_kernel_function`)."""
        nf = self.feature.units
        N = self.horizon
        fields: list[tuple[str, int]] = [
            ("U", 6 * N), ("dt", 1), ("ref", N), ("w", N), ("effort", 1), ("reg", 1),
            ("J0", 36), ("q0", 6), ("qlo", 1), ("qhi", 1), ("vmax", 1), ("lo1", 6),
            ("hi1", 6), ("R0", 9), ("t0", 3), ("A", 18), ("E", 18), ("r", 1)]
        if self.model == "global":
            fields += [("Kit", 9), ("star", 3 * nf), ("offset", 3 * nf), ("wf", nf),
                       ("e0", 3 * nf), ("qoff", 6)]
        else:
            fields += [("N", 36), ("b", 6), ("e0sq", 1)]
        if self.tilt:
            fields += [("zb", 3), ("cosmax", 1)]
        if self.visibility:
            fields += [("K", 9), ("box", 4)]
        if self.drives:
            fields += [("J0i", 36), ("alag", 6), ("clag", 6), ("v0", 6)]
        return Layout(fields, f"MPC {self.feature.kind} {self.model} input")

    def output_layout(self) -> Layout:
        """Layout of the kernel output: cost, ``H`` (row-major), ``g``, ``C`` (row-major),
        the row bounds of ``delta U`` and the constraint values."""
        n = 6 * self.horizon
        m = self.rows
        return Layout([("cost", 1), ("H", n * n), ("g", n), ("C", m * n), ("lba", m),
                       ("uba", m), ("values", m)], f"MPC {self.feature.kind} {self.model} output")

    def row_names(self) -> list[str]:
        """A name per constraint row (for ``Command.active_constraints``)."""
        names: list[str] = []
        for k in range(1, self.horizon + 1):
            names += [f"stroke leg {i} (stage {k})" for i in range(6)]
            if self.tilt:
                names.append(f"tilt (stage {k})")
            if self.visibility:
                names += [f"visibility leg {i} edge {j} {end} {ax} (stage {k})"
                          for i in range(6) for j in range(2) for end in ("base", "platform")
                          for ax in ("u", "v")]
        for k in range(self.horizon):
            names += [f"speed leg {i} (move {k})" for i in range(6)]
        return names


def _mat(v: Any, rows: int, cols: int) -> Any:
    """Row-major reshape."""
    return ca.reshape(v, cols, rows).T


def _pose_function(spec: ProblemSpec) -> ca.Function:
    """``(R, t, p) ->`` the residual (3 nf, global model; else empty), the stage rows'
    values, their Jacobians w.r.t. a left pose perturbation ``xi``, and ``J_inv`` (6, 6)
    at the pose (unused, kept: the compiled kernels without it ran about 5 % slower)."""
    lay = spec.input_layout()
    p = ca.SX.sym("p", lay.size)
    P = lay.split(p)
    R = ca.SX.sym("R", 3, 3)
    t = ca.SX.sym("t", 3)
    xi = ca.SX.sym("xi", 6)
    w = xi[3:]
    Rp = (ca.SX.eye(3) + ca.skew(w)) @ R
    tp = t + xi[:3] + ca.cross(w, t)
    A = [P["A"][3 * i:3 * i + 3] for i in range(6)]
    E = [P["E"][3 * i:3 * i + 3] for i in range(6)]
    r = P["r"]
    q, u, B = sx_legs(Rp, tp, A, E)
    values = []
    if spec.model == "global":
        values += [qi + P["qoff"][i] for i, qi in enumerate(q)]
    else:
        values += q  # replaced by the measured lengths and J_0 in the local model
    if spec.tilt:
        values.append(ca.dot(P["zb"], Rp[:, 2]))
    if spec.visibility:
        K = _mat(P["K"], 3, 3)
        for i in range(6):
            for n in sx_edge_normals(A[i], u[i], r):
                for X in (A[i] + r * n, B[i] + r * n):  # the segment's ends
                    values.append(sx_pixel(X, K))
    vals = ca.vertcat(*values)
    if spec.model == "global":
        Kit = _mat(P["Kit"], 3, 3)
        feats = spec.feature.sx_of_legs(u, A, r, Kit)
        star = P["star"]
        off = P["offset"]
        res = ca.vertcat(*[ca.cross(f + off[3 * j:3 * j + 3], star[3 * j:3 * j + 3])
                           for j, f in enumerate(feats)])
        outs_res: list[ca.SX] = [res, ca.jacobian(res, xi)]
    else:
        outs_res = [ca.SX(0, 1), ca.SX(0, 6)]
    Jv = ca.jacobian(vals, xi)
    Jinv = ca.vertcat(*[ca.horzcat(u[i].T, ca.cross(A[i], u[i]).T) for i in range(6)])
    outs = [*outs_res, vals, Jv, Jinv]
    zero = ca.DM.zeros(6)
    outs = [ca.substitute(o, xi, zero) for o in outs]
    return ca.Function("mpc_pose", [R, t, p], outs)


def _step_jacobian() -> ca.Function:
    """``(dR, dp)`` of one step, ``B = d xi / d tau`` (6, 6) (the left perturbation of
    ``exp(dt tau)`` caused by a change of ``tau``, in twist coordinates) and the adjoint
    ``Ad(E) = [[dR, [dp]_x dR], [0, dR]]`` of the step for twists ``(v, w)``."""
    tau = ca.SX.sym("tau", 6)
    dt = ca.SX.sym("dt")
    dR, dp = sx_exp_se3(dt * tau[:3], dt * tau[3:])
    JR = ca.jacobian(ca.vec(dR), tau)
    Jp = ca.jacobian(dp, tau)
    cols = []
    for j in range(6):
        Om = ca.reshape(JR[:, j], 3, 3) @ dR.T
        wj = ca.vertcat(Om[2, 1] - Om[1, 2], Om[0, 2] - Om[2, 0], Om[1, 0] - Om[0, 1]) / 2
        vj = Jp[:, j] - ca.cross(wj, dp)
        cols.append(ca.vertcat(vj, wj))
    Ad = ca.vertcat(ca.horzcat(dR, ca.skew(dp) @ dR), ca.horzcat(ca.SX.zeros(3, 3), dR))
    return ca.Function("mpc_step", [tau, dt], [dR, dp, ca.horzcat(*cols), Ad])


def _drive_blocks(P: dict[str, Any], N: int, dt: Any) -> tuple[list[Any], list[Any]]:
    """The blocks ``[P_0, ..., P_{N-1}]`` (6, 6) and offsets ``[p_0, ..., p_{N-1}]``
    (6, 1) of the twist displacements ``ds_k = sum_{j <= k} P_{k-j} tau_j + p_k`` under
    lagging drives (``docs/math.md`` section 6, "Drive-aware prediction")."""
    J0 = _mat(P["J0"], 6, 6)
    J0i = _mat(P["J0i"], 6, 6)
    a, c, v0 = P["alag"], P["clag"], P["v0"]

    def legmap(d: Any) -> Any:
        return J0i @ (ca.repmat(d, 1, 6) * J0)

    blocks = [legmap(dt - c)]
    offsets = []
    power: Any = ca.MX.ones(6, 1)  # a^k
    for k in range(N):
        offsets.append(J0i @ (c * power * v0))
        if k < N - 1:
            blocks.append(legmap(c * (1 - a) * power))
        power = power * a
    return blocks, offsets


def _displacement(blocks: list[Any], offsets: list[Any], U: list[Any], k: int) -> Any:
    """``ds_k = sum_{j <= k} P_{k-j} tau_j + p_k`` (see :func:`_drive_blocks`)."""
    ds = offsets[k]
    for j in range(k + 1):
        ds = ds + blocks[k - j] @ U[j]
    return ds


def _add_stage(Hb: list[list[Any]], gb: list[Any], D: list[Any], MD: list[Any], m: Any
               ) -> None:
    """A stage's Gauss-Newton terms: ``g_i += D_i^T m``, ``H_ij += D_i^T MD_j`` (``i <= j``)."""
    for i, Di in enumerate(D):
        gb[i] += Di.T @ m
        for j in range(i, len(D)):
            Hb[i][j] += Di.T @ MD[j]


def _kernel_function(spec: ProblemSpec) -> ca.Function:
    """The QP data ``min 1/2 d^T H d + g^T d`` s.t. ``lba <= C d <= uba`` in ``d =
    delta U`` of one SQP iteration (the spec's layouts), one MX function."""
    lay = spec.input_layout()
    v: Any = ca.MX.sym("v", lay.size)
    P = lay.split(v)
    N = spec.horizon
    dt = P["dt"]
    U = [P["U"][6 * k:6 * k + 6] for k in range(N)]
    J0 = _mat(P["J0"], 6, 6)
    pose_f: Any = _pose_function(spec)
    step_f: Any = _step_jacobian()
    R0 = _mat(P["R0"], 3, 3)
    t0 = P["t0"]
    # Current values (stage 0) for the relaxation of the bounds.
    _, _, vals0, G0, _ = pose_f(R0, t0, v)
    if spec.model == "local":
        vals0 = ca.vertcat(P["q0"], vals0[6:])
        G0 = ca.vertcat(J0, G0[6:, :])
    Hb: list[list[Any]] = [[ca.MX.zeros(6, 6) for _ in range(N)] for _ in range(N)]
    gb: list[Any] = [ca.MX.zeros(6, 1) for _ in range(N)]
    cost: Any = ca.MX(0)
    rows_c: list[Any] = []
    vals_c: list[Any] = []
    sr = spec.stage_rows
    lo_stage: list[Any] = [ca.repmat(P["qlo"], 6, 1)]  # strokes
    hi_stage: list[Any] = [ca.repmat(P["qhi"], 6, 1)]
    if spec.tilt:
        lo_stage.append(P["cosmax"])
        hi_stage.append(ca.MX(_BIG))
    if spec.visibility:
        box = P["box"]
        lo_stage.append(ca.repmat(ca.vertcat(box[0], box[2]), 24, 1))
        hi_stage.append(ca.repmat(ca.vertcat(box[1], box[3]), 24, 1))
    lo_s = ca.fmin(ca.vertcat(*lo_stage), vals0)
    hi_s = ca.fmax(ca.vertcat(*hi_stage), vals0)
    lag = _drive_blocks(P, N, dt) if spec.drives else None
    if spec.model == "global":
        e0 = P["e0"]
        wrow = ca.vertcat(*[ca.repmat(P["wf"][j], 3, 1) for j in range(spec.feature.units)])
        R, t = R0, t0
        D: list[Any] = []
        for k in range(1, N + 1):
            if lag is None:
                dR, dp, Bk, Ad = step_f(U[k - 1], dt)
                D = [Ad @ Dj for Dj in D] + [Bk]
            else:  # the displacement of the lagging drives, one unit of time
                blocks, offsets = lag
                dR, dp, Bk, Ad = step_f(_displacement(blocks, offsets, U, k - 1), 1.0)
                D = [Ad @ Dj + Bk @ blocks[k - 1 - j] for j, Dj in enumerate(D)] \
                    + [Bk @ blocks[0]]
            R, t = dR @ R, dR @ t + dp
            res, Gr, vals, Gv, _ = pose_f(R, t, v)
            wk = P["w"][k - 1]
            rk = res - P["ref"][k - 1] * e0
            Wr = wrow * rk
            cost += wk * ca.dot(rk, Wr)
            M = wk * (Gr.T @ (Gr * ca.repmat(wrow, 1, 6)))
            m = wk * (Gr.T @ Wr)
            _add_stage(Hb, gb, D, [M @ Dj for Dj in D], m)
            rows_c.append(ca.horzcat(*[Gv @ Dj for Dj in D], ca.MX.zeros(sr, 6 * (N - k))))
            vals_c.append(vals)
    else:
        Nm = _mat(P["N"], 6, 6)
        b = P["b"]
        s: Any = ca.MX.zeros(6, 1)
        if lag is not None:  # d s_k / d tau_j = S_{k-1-j}, S_l = P_0 + ... + P_l
            blocks, offsets = lag
            S = [blocks[0]]
            for blk in blocks[1:]:
                S.append(S[-1] + blk)
        for k in range(1, N + 1):
            s = s + (dt * U[k - 1] if lag is None else _displacement(blocks, offsets, U, k - 1))
            wk = P["w"][k - 1]
            one_r = 1 - P["ref"][k - 1]
            Ns = Nm @ s
            cost += wk * (P["e0sq"] * one_r * one_r + 2 * one_r * ca.dot(b, s) + ca.dot(s, Ns))
            m = wk * (Ns + one_r * b)
            if lag is None:
                for i in range(k):
                    gb[i] += dt * m
                    for j in range(i, k):
                        Hb[i][j] += (dt * dt * wk) * Nm
                rows_c.append(ca.horzcat(*([dt * G0] * k), ca.MX.zeros(sr, 6 * (N - k))))
            else:
                Dk = [S[k - 1 - j] for j in range(k)]  # d s_k / d tau_j
                _add_stage(Hb, gb, Dk, [wk * (Nm @ Dj) for Dj in Dk], m)
                rows_c.append(ca.horzcat(*[G0 @ Dj for Dj in Dk], ca.MX.zeros(sr, 6 * (N - k))))
            vals_c.append(vals0 + G0 @ s)
    lo_c: list[Any] = [lo_s] * N  # the stage rows' bounds
    hi_c: list[Any] = [hi_s] * N
    # Speed rows: J_inv,0 tau_k, the first one with the first-period stroke window.
    vmax = P["vmax"]
    for k in range(N):
        vals_c.append(J0 @ U[k])
        rows_c.append(ca.horzcat(ca.MX.zeros(6, 6 * k), J0, ca.MX.zeros(6, 6 * (N - k - 1))))
        if k == 0:
            lo_c.append(P["lo1"])
            hi_c.append(P["hi1"])
        else:
            lo_c.append(-ca.repmat(vmax, 6, 1))
            hi_c.append(ca.repmat(vmax, 6, 1))
    # Effort on the leg velocities of the current inverse Jacobian, and a Tikhonov term on
    # the twists: both in the cost too, so that the merit's slope is the QP's g^T d.
    JtJ = P["effort"] * (J0.T @ J0) + P["reg"] * ca.MX.eye(6)
    for k in range(N):
        Hb[k][k] += JtJ
        gb[k] += JtJ @ U[k]
        cost += P["effort"] * ca.sumsqr(J0 @ U[k]) + P["reg"] * ca.sumsqr(U[k])
    H = ca.blockcat([[Hb[i][j] if j >= i else Hb[j][i].T for j in range(N)]
                     for i in range(N)])
    C = ca.vertcat(*rows_c)
    vals_all = ca.vertcat(*vals_c)
    lba = ca.vertcat(*lo_c) - vals_all
    uba = ca.vertcat(*hi_c) - vals_all
    out = ca.densify(ca.vertcat(cost, ca.vec(H.T), ca.vertcat(*gb), ca.vec(C.T), lba, uba,
                                   vals_all))
    name = f"hexapod_mpc_{spec.feature.kind}_{spec.model}_{N}{'_t' if spec.tilt else ''}" \
           f"{'_v' if spec.visibility else ''}{'_d' if spec.drives else ''}"
    return ca.Function(name, [v], [out])


@lru_cache(maxsize=32)
def problem_kernel(spec: ProblemSpec, compile: bool = True) -> CompiledFunction:
    """The QP-data kernel of a problem structure, compiled to C (cached per process and on
    disk); ``compile=False``: evaluated by the CasADi virtual machine (no C compilation:
    slower per call, nothing to build; option ``compiled = False``)."""
    return CompiledFunction(_kernel_function(spec), compile=compile,
                            inputs=spec.input_layout(), outputs=spec.output_layout())
