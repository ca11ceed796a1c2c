"""The dynamic robots' control period compiled to C: every physics step fused, looped in C.

The step is :meth:`hexapod.dynamics.robots.DynamicRobots.step_reference` written once
more in CasADi SX (the mechanism's terms are those of :mod:`hexapod.dynamics.compiled`,
substituted into the step), folded over the period's steps (``Function.fold``) and
generated to C (:mod:`hexapod.compiled`); the two are tested equal. One row of the period
function carries a robot's state, its constants and its accumulators (:data:`LAYOUT`);
the output row has the same layout.
"""

from __future__ import annotations

import logging
from functools import lru_cache
from typing import Any

import casadi as ca
import numpy as np

from hexapod.compiled import CompiledFunction
from hexapod.dynamics import compiled as mech
from hexapod.dynamics.drive_model import COULOMB_SMOOTHING

log = logging.getLogger(__name__)


def _layout() -> dict[str, slice]:
    sizes = [("R", 9), ("t", 3), ("twist", 6), ("integral", 6), ("setpoint", 6), ("A", 18),
             ("E", 18), ("p", mech.N_PARAMETERS), ("kp", 6), ("ki", 6), ("limit", 6),
             ("rotor", 6), ("viscous", 6), ("coulomb", 6), ("h", 1), ("force_mode", 1),
             ("motor", 6), ("saturated_time", 1), ("track_sq", 1), ("track_max", 1),
             ("force_max", 1)]
    out, k = {}, 0
    for name, size in sizes:
        out[name] = slice(k, k + size)
        k += size
    return out


#: Where each quantity sits in a row of the period function.
LAYOUT = _layout()
#: Length of a row.
WIDTH = max(s.stop for s in LAYOUT.values())


def _clip(x: ca.SX, lim: ca.SX) -> ca.SX:
    return ca.fmin(ca.fmax(x, -lim), lim)


def _exp_so3(w: ca.SX) -> ca.SX:
    """Rodrigues' formula, with the series below 1e-6 rad (as :func:`hexapod.se3.exp_so3`)."""
    theta = ca.norm_2(w)
    small = theta < 1e-6
    th = ca.if_else(small, 1.0, theta)
    a = ca.if_else(small, 1.0 - theta**2 / 6.0, ca.sin(th) / th)
    b = ca.if_else(small, 0.5 - theta**2 / 24.0, (1.0 - ca.cos(th)) / th**2)
    K = ca.skew(w)
    return ca.SX.eye(3) + a * K + b * (K @ K)


def _step_expression() -> tuple[ca.SX, ca.SX]:
    """One physics step: the symbolic row and the next row."""
    x = ca.SX.sym("x", WIDTH)

    def get(name: str) -> ca.SX:
        return x[LAYOUT[name]]

    sym, terms = mech.expressions()
    row = ca.vertcat(get("R"), get("t"), get("twist"), ca.SX.zeros(6), get("A"), get("E"),
                     get("p"))
    M, hb, K = (ca.substitute(terms[k], sym, row) for k in ("M", "h", "K"))
    R = ca.reshape(get("R"), 3, 3)
    t, tw, h = get("t"), get("twist"), get("h")
    kp, ki, lim, integral, sp = get("kp"), get("ki"), get("limit"), get("integral"), \
        get("setpoint")
    qd = K @ tw
    # the drives (hexapod.dynamics.drive_model.DriveModel.forces)
    xs = qd / COULOMB_SMOOTHING
    small = ca.fabs(xs) < 1e-8
    secant = ca.if_else(small, 1.0, ca.tanh(xs) / ca.if_else(small, 1.0, xs))
    d_friction = get("viscous") + get("coulomb") / COULOMB_SMOOTHING * secant
    friction = get("viscous") * qd + get("coulomb") * ca.tanh(xs)
    err = sp - qd
    u = kp * err + integral
    sat_v = ca.fabs(u) >= lim
    winding = sat_v * (ca.sign(err) == ca.sign(u))
    new_integral = _clip(ca.if_else(winding, integral, integral + ki * err * h), lim)
    force = get("force_mode")[0] > 0.5
    motor = ca.if_else(force, _clip(sp, lim), _clip(u, lim))
    saturated = ca.if_else(force, ca.fabs(sp) >= lim, sat_v)
    slope = -ca.if_else(force, ca.SX.zeros(6), ca.if_else(sat_v, 0.0, kp)) - d_friction
    new_integral = ca.if_else(force, integral, new_integral)
    # the legs' bias acceleration b
    A = ca.reshape(get("A"), 3, 6)
    E = ca.reshape(get("E"), 3, 6)
    v, w = tw[0:3], tw[3:6]
    bias = []
    for i in range(6):
        r = R @ E[:, i]
        leg = t + r - A[:, i]
        q = ca.norm_2(leg)
        ui = leg / q
        wr = ca.cross(w, r)
        b_dot = v + wr
        perp = b_dot - ca.dot(ui, b_dot) * ui
        bias.append(ca.dot(ui, ca.cross(w, wr)) + ca.dot(perp, perp) / q)
    b = ca.vertcat(*bias)
    rotor = get("rotor")
    lhs = M + K.T @ ca.diag(rotor - h * slope) @ K
    rhs = K.T @ (motor - friction - rotor * b) - hb
    acc = mech.ldl_solve(lhs, rhs)
    tw_new = tw + h * acc
    t_new = t + h * tw_new[0:3]
    R_new = _exp_so3(h * tw_new[3:6]) @ R
    track = ca.fabs(err) * (1 - force)
    any_sat = ca.if_else(ca.sum1(saturated) > 0, 1.0, 0.0)
    out = ca.SX(x)
    out[LAYOUT["R"]] = ca.reshape(R_new, 9, 1)
    out[LAYOUT["t"]] = t_new
    out[LAYOUT["twist"]] = tw_new
    out[LAYOUT["integral"]] = new_integral
    out[LAYOUT["motor"]] = motor
    out[LAYOUT["saturated_time"]] = get("saturated_time") + h * any_sat
    out[LAYOUT["track_sq"]] = get("track_sq") + ca.sumsqr(track)
    out[LAYOUT["track_max"]] = ca.fmax(get("track_max"), ca.mmax(track))
    out[LAYOUT["force_max"]] = ca.fmax(get("force_max"), ca.mmax(ca.fabs(motor)))
    return x, ca.cse(out)


@lru_cache(maxsize=8)
def period_function(steps: int) -> CompiledFunction:
    """The compiled period of ``steps`` physics steps (built on first use, cached)."""
    x, y = _step_expression()
    step = ca.Function("hexapod_dyn_step", [x], [y])
    xm = ca.MX.sym("x", WIDTH)
    return CompiledFunction(ca.Function(f"hexapod_dyn_period_{steps}", [xm],
                                        [step.fold(steps)(xm)]))


def advance_compiled(robots: Any, rows: np.ndarray, setpoints: np.ndarray, h: float,
                     steps: int) -> np.ndarray:
    """:meth:`hexapod.dynamics.robots.DynamicRobots.advance` in C; returns the (n,) mask
    of rows whose state is not finite after the period (left unchanged)."""
    y = period_function(steps).batch(pack_period(robots, rows, setpoints, h))
    return unpack_period(robots, rows, y, steps)


def pack_period(robots: Any, rows: np.ndarray, setpoints: np.ndarray, h: float
                ) -> np.ndarray:
    """The input rows (n, :data:`WIDTH`) of the period function for ``rows``."""
    n = len(rows)
    d = robots.drives
    x = np.empty((n, WIDTH))
    L = LAYOUT
    x[:, L["R"]] = np.swapaxes(robots.R[rows], -1, -2).reshape(n, 9)
    x[:, L["t"]] = robots.t[rows]
    x[:, L["twist"]] = robots.twist[rows]
    x[:, L["integral"]] = d.integral[rows]
    x[:, L["setpoint"]] = setpoints
    x[:, L["A"]] = robots.A[rows].reshape(n, 18)
    x[:, L["E"]] = robots.E[rows].reshape(n, 18)
    x[:, L["p"]] = robots.parameters[rows]
    for key, arr in (("kp", d.kp), ("ki", d.ki), ("limit", d.force_limit),
                     ("rotor", robots.rotor), ("viscous", d.viscous), ("coulomb", d.coulomb)):
        x[:, L[key]] = arr[rows]
    x[:, L["h"]] = h
    x[:, L["force_mode"]] = 1.0 if d.mode == "force" else 0.0
    x[:, L["motor"]] = robots.forces[rows]
    for key, arr in (("saturated_time", robots.saturated_time), ("track_sq", robots.track_sq),
                     ("track_max", robots.track_max), ("force_max", robots.force_max)):
        x[:, L[key].start] = arr[rows]
    return x


def unpack_period(robots: Any, rows: np.ndarray, y: np.ndarray, steps: int) -> np.ndarray:
    """Store the period function's output rows ``y`` into ``robots``; returns the (n,)
    mask of rows whose state is not finite (left unchanged)."""
    L = LAYOUT
    d = robots.drives
    bad = ~np.all(np.isfinite(y[:, :L["setpoint"].start]), axis=1)
    ok, y = rows[~bad], y[~bad]
    m = len(ok)
    robots.R[ok] = np.swapaxes(y[:, L["R"]].reshape(m, 3, 3), -1, -2)
    robots.t[ok] = y[:, L["t"]]
    robots.twist[ok] = y[:, L["twist"]]
    d.integral[ok] = y[:, L["integral"]]
    robots.forces[ok] = y[:, L["motor"]]
    robots.saturated_time[ok] = y[:, L["saturated_time"].start]
    robots.track_sq[ok] = y[:, L["track_sq"].start]
    robots.track_max[ok] = y[:, L["track_max"].start]
    robots.force_max[ok] = y[:, L["force_max"].start]
    if d.mode == "velocity":
        robots.track_count[ok] += 6 * steps
    return bad  # type: ignore[no-any-return]
