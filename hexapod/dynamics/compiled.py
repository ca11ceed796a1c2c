"""Compiled dynamics of the mechanism in the platform's coordinates (CasADi -> C).

The coordinates are the platform pose ``(R, t)`` and twist ``tau = (v, w)`` of
``docs/math.md`` section 11 (``v = dt/dt``, ``w`` the angular velocity, both in the
base frame). Every rigid body ``k`` (the platform, the six leg bodies, the six rods)
has a centre-of-mass velocity and an angular velocity linear in the twist,
``(v_k, w_k) = J_k(x) tau``, with the legs' motion from the platform's as in
:mod:`hexapod.fk` (``q_dot_i = u_i . B_dot_i``, ``u_dot_i = (B_dot_i - q_dot_i u_i) / q_i``,
a leg's angular velocity ``u_i x u_dot_i``: its spin about its own axis is left at
zero, it does not move the platform, and then its axial inertia drops out of every
equation). Kane's equations (virtual power) give

    M(x) tau_dot + h(x, tau) = K(x)^T f,
    M = sum_k J_k^T diag(m_k, I_k) J_k,
    h = sum_k J_k^T [m_k (J_dot_k tau - g); I_k (J_dot_k tau)_w + w_k x I_k w_k],

with ``K`` the 6x6 matrix ``q_dot = K tau`` (rows ``[u_i^T, (R eB_i x u_i)^T]``) and
``J_dot_k tau`` the directional derivative of ``J_k(x) tau`` along the motion
(``casadi.jtimes``). One SX expression per function, generated to C by
:mod:`hexapod.compiled` and looped over a batch in C.

Row layout of every function's input (79 numbers): ``R`` (9, column-major), ``t``
(3), ``tau`` (6), ``u`` (6: leg forces [N] for ``forward``, the acceleration for
``inverse``, unused by ``terms``), ``A`` (18, base points one after the other),
``E`` (18, platform points), and the 19 inertial parameters of :func:`parameter_row`.

``forward_drives`` takes 12 more numbers per row, two leg-space masses per leg [kg],
and solves

    (M + K^T diag(a + b) K) tau_dot = K^T (f - a * K_dot tau) - h

for the drives' layer: ``a`` moves with the leg (the reflected rotor inertia: a force
``a q_ddot`` with ``q_ddot = K tau_dot + K_dot tau``), ``b = -dt d(f)/d(q_dot)`` takes
a velocity-dependent leg force implicitly over a step ``dt`` (backward Euler on the
velocity: ``f(q_dot + dt q_ddot) ~ f + (d f / d q_dot) dt K tau_dot``). It returns
``tau_dot``, ``q_dot`` and ``q_ddot`` (18).
"""

from __future__ import annotations

from functools import lru_cache, partial

import casadi as ca
import numpy as np

from hexapod.compiled import CompiledFunction, Layout, code_key
from hexapod.dynamics.drive_model import COULOMB_SMOOTHING
from hexapod.dynamics.inertia import InertiaParameters

#: The inertial parameters of an input row (:func:`parameter_row`): the platform's mass
#: [kg], centre of mass [m] and inertia ``[ixx, iyy, izz, ixy, ixz, iyz]`` [kg m^2]
#: (:class:`~hexapod.dynamics.inertia.InertiaParameters`); a leg's body and rod, each a
#: mass [kg], a centre of mass along the leg [m] and a transverse inertia [kg m^2]
#: (:func:`_leg`); gravity [m/s^2].
PARAMETERS = Layout([("platform_mass", ()), ("platform_com", 3), ("platform_inertia", 6),
                     ("leg", 6), ("gravity", 3)], "inertial parameters")
#: Number of inertial parameters in a row.
N_PARAMETERS = PARAMETERS.size
#: The input row of every function (module docstring; ``R`` column-major: the block's
#: (3, 3) view is ``R^T``).
INPUTS = Layout([("R", (3, 3)), ("t", 3), ("twist", 6), ("u", 6), ("A", (6, 3)),
                 ("E", (6, 3)), ("params", N_PARAMETERS)], "dynamics input")
#: Length of an input row.
ROW = INPUTS.size
#: The input row of ``forward_drives``: a row, then the legs' added masses ``a`` (6) and
#: implicit masses ``b`` (6) [kg].
DRIVES_INPUTS = INPUTS.extended([("a", 6), ("b", 6)], "dynamics-with-drives input")
#: Each function's output row. ``terms``: ``M`` and ``K`` (column-major: their views are
#: the transposes), ``h``, the kinetic and potential energies, the leg rates ``q_dot``
#: and the legs' acceleration bias ``K_dot tau``.
OUTPUTS = {
    "forward": Layout([("acc", 6)], "forward dynamics output"),
    "inverse": Layout([("forces", 6), ("residual", 6), ("rhs", 6)], "inverse dynamics output"),
    "terms": Layout([("M", (6, 6)), ("h", 6), ("K", (6, 6)), ("kinetic", 1),
                     ("potential", 1), ("q_dot", 6), ("leg_bias", 6)], "dynamics terms output"),
    "forward_drives": Layout([("acc", 6), ("q_dot", 6), ("q_ddot", 6)],
                             "forward dynamics with drives output"),
    "legs": Layout([("q_dot", 6), ("leg_bias", 6)], "leg rates output"),
    "jacobian": Layout([("K", (6, 6))], "inverse Jacobian output")}


def parameter_row(inertia: InertiaParameters) -> np.ndarray:
    """The inertial parameters of an input row (:data:`PARAMETERS`); a leg's are its body's
    mass, ``body_com`` and transverse inertia, then its rod's. The axial inertias do not
    enter (module docstring)."""
    row = np.empty(N_PARAMETERS)
    for block, value in (
            ("platform_mass", inertia.platform_mass), ("platform_com", inertia.platform_com),
            ("platform_inertia", inertia.platform_inertia),
            ("leg", (inertia.body_mass, inertia.body_com, inertia.body_inertia[0],
                     inertia.rod_mass, inertia.rod_com, inertia.rod_inertia[0])),
            ("gravity", inertia.gravity)):
        row[PARAMETERS[block]] = value
    return row


def _skew(w: ca.SX) -> ca.SX:
    return ca.vertcat(ca.horzcat(0, -w[2], w[1]), ca.horzcat(w[2], 0, -w[0]),
                      ca.horzcat(-w[1], w[0], 0))


def _leg(A: ca.SX, B: ca.SX, B_dot: ca.SX, c_B: ca.SX, leg: ca.SX, gravity: ca.SX
         ) -> tuple[ca.SX, ca.SX, ca.SX, ca.SX, ca.SX, ca.SX, ca.SX]:
    """One leg seen from its platform joint ``B`` (``docs/math.md`` section 11).

    The force the platform applies at ``B`` to move the leg is
    ``M_leg B_ddot + n_leg`` with ``M_leg = m_r u u^T + (J / q^2) P(u)``,
    ``J = m_b d_b^2 + m_r (q - d_r)^2 + i_b + i_r`` (Kane's equations of the body and
    the rod, spin left at zero). Returns ``(u, beta = J / q^2, m_r, y, potential, q_dot,
    bias)`` with ``y = M_leg c_B + n_leg`` for ``B_ddot = Jb tau_dot + c_B`` and
    ``bias = u . c_B + q |u_dot|^2`` the leg acceleration at zero ``tau_dot``
    (``q_ddot = u . B_ddot + q |u_dot|^2``); ``leg`` is ``(m_b, d_b, i_b, m_r, d_r, i_r)``
    (:data:`PARAMETERS`), ``gravity`` (3) [m/s^2].
    """
    m_b, d_b, i_b, m_r, d_r, i_r = (leg[k] for k in range(6))
    L = B - A
    q_sq = ca.dot(L, L)
    # the leg's one division; the others are products by 1/q (written as a square root,
    # which CasADi does not fold back into divisions as it does x * (1/q))
    inv_q = ca.sqrt(1 / q_sq)
    q = q_sq * inv_q
    inv_q2 = inv_q * inv_q
    u = L * inv_q
    q_dot = ca.dot(u, B_dot)
    u_dot = (B_dot - q_dot * u) * inv_q
    J = m_b * d_b**2 + m_r * (q - d_r) ** 2 + i_b + i_r
    beta = J * inv_q2
    g_u = ca.dot(gravity, u)
    n_leg = (m_r * d_r * ca.dot(u_dot, u_dot) * u
             + (2 * q_dot * inv_q2) * (m_r * d_r * (q - d_r) - m_b * d_b**2 - i_b - i_r) * u_dot
             - m_r * g_u * u - ((m_b * d_b + m_r * (q - d_r)) * inv_q) * (gravity - g_u * u))
    y = beta * c_B + (m_r - beta) * ca.dot(u, c_B) * u + n_leg
    potential = -m_b * ca.dot(gravity, A + d_b * u) - m_r * ca.dot(gravity, B - d_r * u)
    bias = ca.dot(u, c_B) + q * ca.dot(u_dot, u_dot)
    return u, beta, m_r, y, potential, q_dot, bias


def symmetric_outer(a: ca.SX, k: ca.SX) -> ca.SX:
    """``a k^T`` for ``a`` parallel to ``k``, from its upper triangle (21 products)."""
    n = k.shape[0]
    out = ca.SX.zeros(n, n)
    for i in range(n):
        for j in range(i, n):
            out[i, j] = a[i] * k[j]
            if j != i:
                out[j, i] = out[i, j]
    return out


def sx_exp_so3(w: ca.SX) -> ca.SX:
    """The rotation matrix (3x3) of a rotation vector ``w`` (3) [rad] by Rodrigues'
    formula, with its series below 1e-6 rad (as :func:`hexapod.se3.exp_so3`)."""
    theta = ca.norm_2(w)
    small = theta < 1e-6
    th = ca.if_else(small, 1.0, theta)
    a = ca.if_else(small, 1.0 - theta**2 / 6.0, ca.sin(th) / th)
    b = ca.if_else(small, 0.5 - theta**2 / 24.0, (1.0 - ca.cos(th)) / th**2)
    K = ca.skew(w)
    return ca.SX.eye(3) + a * K + b * (K @ K)


def sx_drive_friction(qd: ca.SX, viscous: ca.SX, coulomb: ca.SX) -> tuple[ca.SX, ca.SX]:
    """The drives' friction (:class:`hexapod.dynamics.drive_model.DriveModel`) at the leg
    rates ``qd`` (6) [m/s], viscous ``viscous`` [N s/m] and smoothed Coulomb ``coulomb``
    [N] (``tanh(qd / COULOMB_SMOOTHING)``): the force (6) [N] and its secant slope (6)
    [N s/m], ``force = slope * qd`` (finite at rest)."""
    xs = qd * (1 / COULOMB_SMOOTHING)
    small = ca.fabs(xs) < 1e-8
    secant = ca.if_else(small, 1.0, ca.tanh(xs) / ca.if_else(small, 1.0, xs))
    d_friction = viscous + coulomb * (1 / COULOMB_SMOOTHING) * secant
    friction = viscous * qd + coulomb * ca.tanh(xs)
    return friction, d_friction


def add_leg_masses(M: ca.SX, K: ca.SX, leg_mass: ca.SX) -> ca.SX:
    """``M + K^T diag(leg_mass) K``: the platform's mass matrix (6x6) [kg, kg m, kg m^2]
    with a mass (6) [kg] per leg along its row of ``K`` (``q_dot = K tau``), one rank-one
    term per leg from its upper triangle (:func:`symmetric_outer`)."""
    out = M
    for i in range(6):
        k = K[i, :].T
        out += symmetric_outer(leg_mass[i] * k, k)
    return out


def ldl_factor(M: ca.SX) -> tuple[list[list[ca.SX]], list[ca.SX]]:
    """The unrolled LDL^T factorisation ``M = L D L^T`` of a symmetric positive-definite
    ``M`` (n x n, any units): ``L`` (n x n lists, unit lower triangle: its entries below
    the diagonal) and the diagonal ``D`` (n, the units of ``M``)."""
    n = M.shape[0]
    L = [[ca.SX(0)] * n for _ in range(n)]
    D = [ca.SX(0)] * n
    for j in range(n):
        D[j] = M[j, j] - sum((L[j][k] * L[j][k] * D[k] for k in range(j)), ca.SX(0))
        for i in range(j + 1, n):
            L[i][j] = (M[i, j] - sum((L[i][k] * L[j][k] * D[k] for k in range(j)),
                                     ca.SX(0))) / D[j]
    return L, D


def ldl_substitute(L: list[list[ca.SX]], D: list[ca.SX], b: ca.SX) -> ca.SX:
    """``M^-1 b`` (n) from the factors of :func:`ldl_factor` and one right-hand side
    ``b`` (n; the result has the units of ``b`` over those of ``M``): the forward,
    diagonal and backward substitutions."""
    n = len(D)
    y = [ca.SX(0)] * n
    for i in range(n):
        y[i] = b[i] - sum((L[i][k] * y[k] for k in range(i)), ca.SX(0))
    z = [y[i] / D[i] for i in range(n)]
    out = [ca.SX(0)] * n
    for i in reversed(range(n)):
        out[i] = z[i] - sum((L[k][i] * out[k] for k in range(i + 1, n)), ca.SX(0))
    return ca.vertcat(*out)


def ldl_solve(M: ca.SX, b: ca.SX) -> ca.SX:
    """``M^-1 b`` for a symmetric positive-definite ``M`` by an unrolled LDL^T."""
    L, D = ldl_factor(M)
    return ldl_substitute(L, D, b)


def expressions() -> tuple[ca.SX, dict[str, ca.SX]]:
    """The symbolic input row and the dynamics' terms as SX expressions of it.

    Besides the terms of ``OUTPUTS["terms"]`` (``M``, ``h``, ``K``, ``kinetic``, ``potential``,
    ``q_dot``, ``leg_bias``): ``M = M_joint + K^T diag(leg_mass) K``, the legs' rank-one
    parts apart (``leg_mass_i = m_r - J_i / q_i^2``), for a caller that adds leg-space
    masses of its own (one rank-one term per leg instead of two).
    """
    x = ca.SX.sym("x", ROW)
    blocks = INPUTS.split(x)
    R = ca.reshape(blocks["R"], 3, 3)
    t = blocks["t"]
    tau = blocks["twist"]
    v, w = tau[0:3], tau[3:6]
    A = ca.reshape(blocks["A"], 3, 6)
    E = ca.reshape(blocks["E"], 3, 6)
    p = PARAMETERS.split(blocks["params"])
    m_p, c_p, gravity = p["platform_mass"], p["platform_com"], p["gravity"]
    ixx, iyy, izz, ixy, ixz, iyz = (p["platform_inertia"][k] for k in range(6))
    I_p = ca.vertcat(ca.horzcat(ixx, ixy, ixz), ca.horzcat(ixy, iyy, iyz),
                     ca.horzcat(ixz, iyz, izz))

    # The platform: CoM velocity v + w x R c_p, angular velocity w.
    rc = R @ c_p
    I_w = R @ I_p @ R.T
    Jv = ca.jacobian(v + ca.cross(w, rc), tau)
    Jw = ca.jacobian(w, tau)
    M = m_p * (Jv.T @ Jv) + Jw.T @ I_w @ Jw
    h = Jv.T @ (m_p * (ca.cross(w, ca.cross(w, rc)) - gravity)) + Jw.T @ ca.cross(w, I_w @ w)
    potential = -m_p * ca.dot(gravity, t + rc)
    # The legs, through their platform joints: B_dot = Jb tau, B_ddot = Jb tau_dot + c_B,
    # Jb = [I, -[b]x], c_B = w x (w x b); Jb^T M_leg Jb = beta Jb^T Jb + (m_r - beta) k k^T
    # with k = Jb^T u the leg's row of K, and Jb^T Jb = [[I, -[b]x], [[b]x, |b|^2 I - b b^T]]
    # summed over the legs as sum(beta), sum(beta b) and sum(beta (|b|^2 I - b b^T)).
    M_joint = M  # M without the legs' rank-one terms (m_r - beta) k k^T
    k_rows, q_dots, biases, leg_coefficients = [], [], [], []
    s0, s1, s2 = ca.SX(0), ca.SX.zeros(3), ca.SX.zeros(3, 3)
    for i in range(6):
        b = R @ E[:, i]
        c_B = ca.cross(w, ca.cross(w, b))
        u, beta, m_r, y, v_leg, q_dot, bias = _leg(A[:, i], b + t, v + ca.cross(w, b), c_B,
                                                   p["leg"], gravity)
        q_dots.append(q_dot)
        biases.append(bias)
        k = ca.vertcat(u, ca.cross(b, u))
        s0 += beta
        s1 += beta * b
        s2 += beta * (ca.dot(b, b) * ca.SX.eye(3) - b @ b.T)
        M += symmetric_outer((m_r - beta) * k, k)
        leg_coefficients.append(m_r - beta)
        h += ca.vertcat(y, ca.cross(b, y))
        potential += v_leg
        k_rows.append(k.T)
    legs_joint = ca.vertcat(ca.horzcat(s0 * ca.SX.eye(3), -_skew(s1)),
                            ca.horzcat(_skew(s1), s2))
    M += legs_joint
    K = ca.vertcat(*k_rows)
    kinetic = 0.5 * ca.dot(tau, M @ tau)
    return x, {"M": M, "h": h, "K": K, "kinetic": kinetic, "potential": potential,
               "q_dot": ca.vertcat(*q_dots), "leg_bias": ca.vertcat(*biases),
               "M_joint": M_joint + legs_joint, "leg_mass": ca.vertcat(*leg_coefficients)}


@lru_cache(maxsize=1)
def cached_expressions() -> tuple[ca.SX, dict[str, ca.SX]]:
    """:func:`expressions`, built once per process (the kernels and the identification
    regressor differentiate the same graph)."""
    return expressions()


def _build(name: str) -> ca.Function:
    """The CasADi function ``name``: ``forward`` (acceleration, 6), ``inverse`` (leg
    forces, their residual ``K^T f - (M acc + h)`` and ``M acc + h``: 18), ``terms`` or
    ``forward_drives`` (:data:`DRIVES_INPUTS`; the outputs: :data:`OUTPUTS`)."""
    x, e = cached_expressions()
    M, h, K = e["M"], e["h"], e["K"]
    u = x[INPUTS["u"]]
    if name == "forward":
        return ca.Function("hexapod_dyn_forward", [x], [ca.cse(ldl_solve(M, K.T @ u - h))])
    if name == "inverse":
        rhs = M @ u + h
        f = ca.solve(K.T, rhs)
        # the residual exposes a singular K (the solve returns finite garbage there)
        return ca.Function("hexapod_dyn_inverse", [x],
                           [ca.cse(ca.vertcat(f, K.T @ f - rhs, rhs))])
    if name == "terms":
        return ca.Function("hexapod_dyn_terms", [x], [ca.cse(ca.vertcat(
            ca.reshape(M, 36, 1), h, ca.reshape(K, 36, 1), e["kinetic"], e["potential"],
            e["q_dot"], e["leg_bias"]))])
    if name == "legs":  # the leg rates of "terms" alone: its nodes, the same numbers
        return ca.Function("hexapod_dyn_legs", [x], [ca.cse(ca.vertcat(e["q_dot"],
                                                                       e["leg_bias"]))])
    if name == "jacobian":  # K of "terms" alone (column-major): its nodes, the same numbers
        return ca.Function("hexapod_dyn_jacobian", [x], [ca.cse(ca.reshape(K, 36, 1))])
    if name == "forward_drives":
        # Leg-space masses: a (moves with the leg, e.g. reflected rotor inertia) and b
        # (an implicit velocity-dependent force, -dt d(force)/d(q_dot), without the bias).
        extra = ca.SX.sym("legs", 12)
        a, b = extra[0:6], extra[6:12]
        leg_bias = e["leg_bias"]
        M_eff = M + K.T @ ca.diag(a + b) @ K
        acc = ldl_solve(M_eff, K.T @ (u - a * leg_bias) - h)
        return ca.Function("hexapod_dyn_forward_drives", [ca.vertcat(x, extra)],
                           [ca.cse(ca.vertcat(acc, e["q_dot"], K @ acc + leg_bias))])
    raise ValueError(f"unknown compiled dynamics function {name!r}; expected one of "
                     "forward, inverse, terms, legs, jacobian, forward_drives")


#: The modules that write the functions' expressions (their
#: :func:`~hexapod.compiled.code_key`).
KEY_MODULES = ("hexapod.layout", "hexapod.dynamics.compiled", "hexapod.dynamics.drive_model")


@lru_cache(maxsize=8)
def compiled(name: str) -> CompiledFunction:
    """One of the compiled functions (``"forward"``, ``"inverse"``, ``"terms"``, ``"legs"``,
    ``"jacobian"``, ``"forward_drives"``), built and compiled on first use (the C library is cached
    on disk by :mod:`hexapod.compiled`)."""
    inputs = DRIVES_INPUTS if name == "forward_drives" else INPUTS
    if name not in OUTPUTS:
        _build(name)  # raises: an unknown name
    return CompiledFunction(partial(_build, name), inputs=inputs, outputs=OUTPUTS[name],
                            key=(f"hexapod_dyn_{name}", code_key(KEY_MODULES, name)))


def pack(R: np.ndarray, t: np.ndarray, twist: np.ndarray, u: np.ndarray,
         base_points: np.ndarray, platform_points: np.ndarray, parameters: np.ndarray
         ) -> np.ndarray:
    """Input rows (N, 79) of a batch.

    Args:
        R: (N, 3, 3) platform orientations.
        t: (N, 3) platform positions [m].
        twist: (N, 6) twists ``(v, w)`` [m/s, rad/s].
        u: (N, 6) leg forces [N] or platform accelerations [m/s^2, rad/s^2].
        base_points: (6, 3) or (N, 6, 3) ``A_i`` [m].
        platform_points: (6, 3) or (N, 6, 3) ``eB_i`` [m].
        parameters: (19,) or (N, 19) rows of :func:`parameter_row`.
    """
    n = t.shape[0]
    rows = np.empty((n, ROW))
    s = _PACK_SLICES  # the blocks' slices (INPUTS), looked up once: a call per period
    rows[:, s[0]].reshape(n, 3, 3)[:] = np.swapaxes(R, -1, -2)
    rows[:, s[1]] = t
    rows[:, s[2]] = twist
    rows[:, s[3]] = u
    rows[:, s[4]].reshape(n, 6, 3)[:] = base_points
    rows[:, s[5]].reshape(n, 6, 3)[:] = platform_points
    rows[:, s[6]] = parameters
    return rows


#: The slices of :func:`pack`'s blocks in an input row.
_PACK_SLICES = tuple(INPUTS[b] for b in ("R", "t", "twist", "u", "A", "E", "params"))
