"""The dynamic robots' control period compiled to C: every physics step fused, looped in C.

The step (the module docstring of :mod:`hexapod.dynamics.robots`) is written in CasADi
SX (the mechanism's terms are those of :mod:`hexapod.dynamics.compiled`, substituted into
the step) and generated to C twice: by this project's lane generator
(:mod:`hexapod.compiled_lanes`: four rows per vector instruction, the period's steps
looped in C; used) and by CasADi, folded over the period's steps (``Function.fold``,
:mod:`hexapod.compiled`: the fallback, and the lane code's bitwise reference); the tests
hold the step equal to its numpy oracle (``tests/hexapod/dynamic_robots_oracle.py``). One
row carries a robot's constants, state, accumulators and leg lengths (:data:`LAYOUT`);
the robots keep their rows in a table (:func:`new_table`) whose state columns are their
attributes (views), and a period advances the table's rows in place: nothing is packed
or unpacked but the poses (the caller's arrays) and the setpoints.
"""

from __future__ import annotations

import logging
from functools import lru_cache
from typing import Any

import casadi as ca
import numpy as np

from hexapod.compiled import CompiledFunction, Layout, code_key
from hexapod.compiled_lanes import LaneFunction
from hexapod.dynamics import compiled as mech

log = logging.getLogger(__name__)


#: Where each quantity sits in a row of the period function (its input and output).
LAYOUT = Layout([("R", 9), ("t", 3), ("twist", 6), ("integral", 6), ("setpoint", 6),
                 ("A", 18), ("E", 18), ("p", mech.N_PARAMETERS), ("kp", 6), ("ki", 6),
                 ("limit", 6), ("speed_limit", 6), ("rotor", 6), ("viscous", 6),
                 ("coulomb", 6), ("h", 1),
                 ("force_mode", 1), ("motor", 6), ("saturated_time", 1), ("track_sq", 1),
                 ("track_max", 1), ("force_max", 1), ("q", 6), ("saturated_legs", 6)],
                "dynamic robot row")
#: Length of a row.
WIDTH = LAYOUT.size
_R, _T, _SETPOINT = LAYOUT["R"], LAYOUT["t"], LAYOUT["setpoint"]
_H, _FORCE_MODE = LAYOUT.index("h"), LAYOUT.index("force_mode")


def _clip(x: ca.SX, lim: ca.SX) -> ca.SX:
    return ca.fmin(ca.fmax(x, -lim), lim)


def _step_expression() -> tuple[ca.SX, ca.SX]:
    """One physics step: the symbolic row and the next row."""
    x = ca.SX.sym("x", WIDTH)

    def get(name: str) -> ca.SX:
        return x[LAYOUT[name]]

    sym, terms = mech.expressions()
    row = ca.vertcat(get("R"), get("t"), get("twist"), ca.SX.zeros(6), get("A"), get("E"),
                     get("p"))
    # q_dot = K tau and the legs' bias acceleration b = q_ddot - K tau_dot come with the
    # mechanism's terms (the same leg vectors)
    M_joint, leg_mass, hb, K, qd, b = (ca.substitute(terms[k], sym, row) for k in (
        "M_joint", "leg_mass", "h", "K", "q_dot", "leg_bias"))
    R = ca.reshape(get("R"), 3, 3)
    t, tw, h = get("t"), get("twist"), get("h")
    kp, ki, lim, integral, sp = get("kp"), get("ki"), get("limit"), get("integral"), \
        get("setpoint")
    # the drives (hexapod.dynamics.drive_model.DriveModel.forces)
    friction, d_friction = mech.sx_drive_friction(qd, get("viscous"), get("coulomb"))
    err = sp - qd
    u = kp * err + integral
    sat_v = ca.fabs(u) >= lim
    winding = sat_v * (ca.sign(err) == ca.sign(u))
    new_integral = _clip(ca.if_else(winding, integral, integral + ki * err * h), lim)
    force = get("force_mode")[0] > 0.5
    # force mode: the command, less the velocity loop's proportional term of the speed
    # beyond the limit (DriveModel.forces)
    vmax = get("speed_limit")
    held = _clip(sp, lim) - kp * (ca.fmax(qd - vmax, 0.0) + ca.fmin(qd + vmax, 0.0))
    governed = ((qd > vmax) + (qd < -vmax)) * (ca.fabs(held) < lim)
    motor = ca.if_else(force, _clip(held, lim), _clip(u, lim))
    saturated = ca.if_else(force, ca.fabs(held) >= lim, sat_v)  # (the force applied)
    slope = -ca.if_else(force, ca.if_else(governed, kp, 0.0),
                        ca.if_else(sat_v, 0.0, kp)) - d_friction
    new_integral = ca.if_else(force, integral, new_integral)
    # M + K^T diag(rotor - h slope) K: one rank-one term per leg, its mechanism's part
    # (M = M_joint + K^T diag(leg_mass) K) and the drive's added, from the upper triangle
    rotor = get("rotor")
    lhs = mech.add_leg_masses(M_joint, K, leg_mass + rotor - h * slope)
    rhs = K.T @ (motor - friction - rotor * b) - hb
    acc = mech.ldl_solve(lhs, rhs)
    tw_new = tw + h * acc
    t_new = t + h * tw_new[0:3]
    R_new = mech.sx_exp_so3(h * tw_new[3:6]) @ R
    track = ca.fabs(err) * (1 - force)
    any_sat = ca.if_else(ca.sum1(saturated) > 0, 1.0, 0.0)
    out = ca.SX(x)
    out[LAYOUT["R"]] = ca.reshape(R_new, 9, 1)
    out[LAYOUT["t"]] = t_new
    out[LAYOUT["twist"]] = tw_new
    out[LAYOUT["integral"]] = new_integral
    out[LAYOUT["motor"]] = motor
    out[LAYOUT["saturated_time"]] = get("saturated_time") + h * any_sat
    out[LAYOUT["saturated_legs"]] = get("saturated_legs") + h * saturated
    out[LAYOUT["track_sq"]] = get("track_sq") + ca.sumsqr(track)
    out[LAYOUT["track_max"]] = ca.fmax(get("track_max"), ca.mmax(track))
    out[LAYOUT["force_max"]] = ca.fmax(get("force_max"), ca.mmax(ca.fabs(motor)))
    return x, ca.cse(out)


def _finish_expression() -> tuple[ca.SX, ca.SX]:
    """The end of a period: the row with the legs' lengths ``q`` of its pose."""
    x = ca.SX.sym("x", WIDTH)
    R = ca.reshape(x[LAYOUT["R"]], 3, 3)
    A = ca.reshape(x[LAYOUT["A"]], 3, 6)
    E = ca.reshape(x[LAYOUT["E"]], 3, 6)
    out = ca.SX(x)
    out[LAYOUT["q"]] = ca.vertcat(*(ca.norm_2(x[LAYOUT["t"]] + R @ E[:, i] - A[:, i])
                                    for i in range(6)))
    return x, ca.cse(out)


@lru_cache(maxsize=1)
def period_functions() -> tuple[ca.Function, ca.Function]:
    """The physics step and the end of a period (the legs' lengths) as CasADi functions
    (built once per process, when a library is missing or the fallback is used)."""
    x, y = _step_expression()
    xf, yf = _finish_expression()
    return (ca.Function("hexapod_dyn_step", [x], [y]),
            ca.Function("hexapod_dyn_legs", [xf], [yf]))


@lru_cache(maxsize=8)
def period_function(steps: int) -> CompiledFunction:
    """The compiled period of ``steps`` physics steps, then the legs' lengths, in CasADi's
    C (built on first use, cached): the fallback of :func:`period_lanes`."""
    step, finish = period_functions()
    xm = ca.MX.sym("x", WIDTH)
    return CompiledFunction(ca.Function(f"hexapod_dyn_period_{steps}", [xm],
                                        [finish(step.fold(steps)(xm))]),
                            inputs=LAYOUT, outputs=LAYOUT)


@lru_cache(maxsize=1)
def period_lanes() -> LaneFunction | None:
    """The period as lane-parallel C (:mod:`hexapod.compiled_lanes`: several rows per
    vector instruction, the physics steps looped in C, then the legs' lengths; the same
    results as :func:`period_function` bit for bit), or None where it cannot be compiled."""
    return LaneFunction.create(lambda: period_functions()[0], "hexapod_dyn_period_lanes",
                               lambda: period_functions()[1], key=(code_key(KEY_MODULES),
                                                             (WIDTH, WIDTH)))


#: The modules that write the period's expressions (its :func:`~hexapod.compiled.code_key`).
KEY_MODULES = (*mech.KEY_MODULES, "hexapod.dynamics.robots_compiled")


def run_period(x: np.ndarray, steps: int) -> np.ndarray:
    """The rows ``x`` (n, :data:`WIDTH`) after a period of ``steps`` physics steps: the
    lane-parallel C, else CasADi's folded period."""
    lanes = period_lanes()
    if lanes is not None:
        return lanes.iterate(x, steps)
    return period_function(steps).batch(x)


def column(table: np.ndarray, name: str) -> np.ndarray:
    """The view of quantity ``name`` of :data:`LAYOUT` in ``table`` (n, :data:`WIDTH`):
    (n, size), or (n,) for a single number."""
    s = LAYOUT[name]
    return table[:, s.start] if s.stop - s.start == 1 else table[:, s]


def new_table(robots: Any) -> np.ndarray:
    """The rows (n, :data:`WIDTH`) of ``robots`` (a
    :class:`~hexapod.dynamics.robots.DynamicRobots`): their constants (geometry, inertia,
    drive parameters) and their present state, accumulators and leg lengths."""
    from hexapod.dynamics.robots import legs

    n = robots.n
    d = robots.drives
    x = np.zeros((n, WIDTH))
    L = LAYOUT
    x[:, L["R"]] = np.swapaxes(robots.R, -1, -2).reshape(n, 9)
    x[:, L["t"]] = robots.t
    x[:, L["twist"]] = robots.twist
    x[:, L["integral"]] = d.integral
    x[:, L["A"]] = robots.A.reshape(n, 18)
    x[:, L["E"]] = robots.E.reshape(n, 18)
    x[:, L["p"]] = robots.parameters
    for key, arr in (("kp", d.kp), ("ki", d.ki), ("limit", d.force_limit),
                     ("speed_limit", d.speed_limit),
                     ("rotor", robots.rotor), ("viscous", d.viscous), ("coulomb", d.coulomb),
                     ("motor", robots.forces), ("saturated_legs", robots.saturated_legs)):
        x[:, L[key]] = arr
    for key, arr in (("saturated_time", robots.saturated_time), ("track_sq", robots.track_sq),
                     ("track_max", robots.track_max), ("force_max", robots.force_max)):
        x[:, L.index(key)] = arr
    x[:, L["q"]] = legs(robots.R, robots.t, robots.A, robots.E)[0]
    return x


def row_index(rows: np.ndarray | slice) -> np.ndarray | slice:
    """``rows`` as a slice when they are consecutive (numpy copies a slice several times
    faster than it gathers rows, and a slice of a table is a view), else themselves."""
    if isinstance(rows, slice):
        return rows
    n = len(rows)
    if n:
        first = int(rows[0])
        if int(rows[-1]) - first == n - 1 and (rows[1:] - rows[:-1] == 1).all():
            return slice(first, first + n)
    return rows


def load_period(robots: Any, rows: np.ndarray | slice, setpoints: np.ndarray, h: float
                ) -> None:
    """Write the period's inputs of ``rows`` (indices or a slice) into ``robots.table``:
    the poses (from the caller's ``R`` and ``t``), the setpoints, the step and the drive
    mode."""
    table = robots.table
    rows = row_index(rows)
    if isinstance(rows, slice):  # a view of the table: the poses written in place
        table[rows, _R].reshape(-1, 3, 3)[:] = np.swapaxes(robots.R[rows], -1, -2)
    else:
        table[rows, _R] = np.swapaxes(robots.R[rows], -1, -2).reshape(-1, 9)
    table[rows, _T] = robots.t[rows]
    table[rows, _SETPOINT] = setpoints
    # the step and the drive mode: every row's, rewritten only when they change
    mode = 1.0 if robots.drives.mode == "force" else 0.0
    if robots.period_constants != (h, mode):
        table[:, _H] = h
        table[:, _FORCE_MODE] = mode
        robots.period_constants = (h, mode)


def pack_period(robots: Any, rows: np.ndarray, setpoints: np.ndarray, h: float
                ) -> np.ndarray:
    """The input rows (n, :data:`WIDTH`) of the period for ``rows`` (a copy; the table
    holds the period's inputs afterwards, as :func:`advance_compiled` leaves it)."""
    load_period(robots, rows, setpoints, h)
    return robots.table[rows]  # type: ignore[no-any-return]


def advance_compiled(robots: Any, rows: np.ndarray, setpoints: np.ndarray, h: float,
                     steps: int) -> np.ndarray:
    """:meth:`hexapod.dynamics.robots.DynamicRobots.advance` in C, in place in
    ``robots.table``; returns the (n,) mask of rows whose state is not finite after the
    period (left unchanged)."""
    index = row_index(rows)
    load_period(robots, index, setpoints, h)
    table = robots.table
    check = LAYOUT["setpoint"].start  # the state: pose, twist, integral
    lanes = period_lanes()
    if lanes is not None:
        bad = lanes.advance(table, rows, steps, check)
    else:
        y = period_function(steps).batch(table[rows])
        bad = ~np.all(np.isfinite(y[:, :check]), axis=1)
        table[rows[~bad]] = y[~bad]
    ok = row_index(rows[~bad]) if bad.any() else index
    robots.R[ok] = np.swapaxes(table[ok, _R].reshape(-1, 3, 3), -1, -2)
    robots.t[ok] = table[ok, _T]
    if robots.drives.mode == "velocity":
        robots.track_count[ok] += 6 * steps
    return bad
