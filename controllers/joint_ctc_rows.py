"""The batch of the joint-space computed torque (``computed-torque``) as arrays.

:class:`JointRows` (built at the first batched step after a reset) owns its trials'
state: the input matrix ``X`` (n, n_in) with each row's constants and pose guess, the
leg integrals, the fixed goals' quintics, the command counts, the force limits and the
reference's legs on the control grid (one grid when they are equal). Each instance's
state is views of these arrays, so its per-trial step (which refuses with the reason)
and the batch share it.

One batched step (:meth:`JointRows.step`): readings and desired legs written by fancy
indexing, one C call, the rows screened at once, the results written as slices; Python
per row only for a fixed goal's first step, an instant off the grid, or forces over a
limit with a saturation other than clipping.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from controllers.ctc_rows import FK_MAX_CALLS, accepted_rows, evaluate_rows, norms, over_limits
from controllers.data import CommandBatch, ObservationBatch
from controllers.solvers import compiled_ctc
from hexapod.compiled import CompiledFunction

if TYPE_CHECKING:
    from controllers.computed_torque import ComputedTorqueController

#: How far from ``k dt`` an observation's time may be to use the reference's grid [s].
GRID_TIME_TOLERANCE = 1e-9
#: Where the compiled step's blocks lie in its rows (:data:`compiled_ctc.INPUTS`,
#: :data:`compiled_ctc.OUTPUTS`), looked up once.
DESIRED, POSE_IN = compiled_ctc.INPUTS["desired"], compiled_ctc.INPUTS["pose"]
Q_IN, QD_IN = compiled_ctc.INPUTS["q"], compiled_ctc.INPUTS["q_dot"]
POSE_OUT, FACTOR, FORCES, SCREEN = (compiled_ctc.OUTPUTS[k]
                                     for k in ("pose", "factor", "forces", "screen"))
RESIDUAL, STATUS = (compiled_ctc.OUTPUTS.index(k) for k in ("fk_residual", "status"))
#: The columns of a quintic's row (21,): started (1.0 or 0.0), ``t0`` [s], duration
#: ``T`` [s], ``q0`` (6) [m], ``q* - q0`` (6) [m], ``q*`` (6) [m].
QUINTIC_SIZE = 21


def quintic_timing(t: float, t0: float, T: float) -> tuple[float, float, float] | None:
    """The quintic timing ``(s, s_dot, s_ddot)`` at ``t`` [s] of a motion started at
    ``t0`` [s] lasting ``T`` [s] (``s`` from 0 to 1; rates [1/s], [1/s^2]), None for a
    zero duration (at ``q*`` at once)."""
    if T <= 0.0:
        return None
    x = min(max((t - t0) / T, 0.0), 1.0)
    s = x**3 * (10 - 15 * x + 6 * x**2)
    if 0.0 < x < 1.0:
        return s, 30 * x**2 * (1 - x) ** 2 / T, 60 * x * (1 - x) * (1 - 2 * x) / T**2
    return s, 0.0, 0.0


def quintic_row_into(t: float, row: np.ndarray, out: np.ndarray) -> None:
    """:func:`quintic_rows` of one quintic ``row`` (21,) at ``t`` [s], written into
    ``out`` (18,) (the same operations on the same numbers, in Python floats: one
    array read and one write)."""
    r = row.tolist()
    timing = quintic_timing(t, r[1], r[2])
    if timing is None:
        out[0:6] = r[15:21]
        out[6:18] = 0.0
        return
    s, sd, sdd = timing
    _, _, _, a0, a1, a2, a3, a4, a5, d0, d1, d2, d3, d4, d5, *_ = r
    out[:] = [a0 + s * d0, a1 + s * d1, a2 + s * d2, a3 + s * d3, a4 + s * d4, a5 + s * d5,
              sd * d0, sd * d1, sd * d2, sd * d3, sd * d4, sd * d5,
              sdd * d0, sdd * d1, sdd * d2, sdd * d3, sdd * d4, sdd * d5]


def quintic_rows(t: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """``(q*, q_dot*, q_ddot*)`` (m, 18) of the leg-space quintics ``rows`` (m, 21)
    (:data:`QUINTIC_SIZE`) at the times ``t`` (m,) [s]: ``q0 + s d``, ``s_dot d``,
    ``s_ddot d`` with ``d = q* - q0`` (``q*`` at rest for a zero duration). The timing
    (:func:`quintic_timing`) is computed in Python floats, row by row."""
    m = len(t)
    timing = np.zeros((m, 3))
    step = np.zeros(m, dtype=bool)
    for j, (tj, t0, T) in enumerate(zip(t.tolist(), rows[:, 1].tolist(), rows[:, 2].tolist(),
                                         strict=True)):
        tm = quintic_timing(tj, t0, T)
        if tm is None:
            step[j] = True
        else:
            timing[j] = tm
    d = rows[:, 9:15]
    out = np.empty((m, 18))
    out[:, 0:6] = rows[:, 3:9] + timing[:, 0:1] * d
    out[:, 6:12] = timing[:, 1:2] * d
    out[:, 12:18] = timing[:, 2:3] * d
    if step.any():
        out[step, 0:6] = rows[step, 15:21]
        out[step, 6:18] = 0.0
    return out


class JointState(NamedTuple):
    """One trial's state as its batch takes it (its own arrays, copied into the batch's).

    Attributes:
        row: (n_in,) the compiled step's input row.
        integral: (6,) ``int (q* - q) dt`` [m s].
        quintic: (21,) the fixed goal's quintic (:data:`QUINTIC_SIZE`).
        steps: (1,) the commands of the compiled step.
        limit: (6,) the nominal force limits [N].
        dt: The control period [s].
        t_end: The time after which the reference is at rest [s] (inf: none).
        grid: (N, 18) the reference's legs on the control grid, None for a fixed goal.
        function: The compiled step.
    """

    row: np.ndarray
    integral: np.ndarray
    quintic: np.ndarray
    steps: np.ndarray
    limit: np.ndarray
    dt: float
    t_end: float
    grid: np.ndarray | None
    function: CompiledFunction


class JointRows:
    """The arrays of a batch of computed-torque trials (see the module docstring); each
    instance's state becomes views of them.

    Args:
        laws: The trials' instances (reset), in trial order.
    """

    def __init__(self, laws: list[ComputedTorqueController]) -> None:
        self.laws = laws
        states = [law.batch_state() for law in laws]
        self.function = states[0].function
        n = len(laws)
        self.X = np.stack([st.row for st in states])
        self.integral = np.stack([st.integral for st in states])
        self.quintic = np.stack([st.quintic for st in states])
        self.steps = np.concatenate([st.steps for st in states])
        self.limit = np.stack([st.limit for st in states])
        for k, law in enumerate(laws):
            law.adopt(self.X[k], self.integral[k], self.quintic[k], self.steps[k:k + 1])
        self.dt = np.array([st.dt for st in states])
        self.t_end = np.array([st.t_end for st in states])
        #: (n,) each trial's index (its row of the arrays).
        self.index = np.arange(n)
        self.tracking = np.array([st.grid is not None for st in states])
        grids = [st.grid for st in states if st.grid is not None]
        self.grid_len = np.array([0 if st.grid is None else len(st.grid) for st in states],
                                 dtype=int)
        #: (1 or n, S, 18) the grids, one shared when they are equal (index 0).
        self.shared = bool(grids) and all(g is grids[0] or np.array_equal(g, grids[0])
                                          for g in grids)
        if self.shared:
            self.grids = grids[0][None]
        else:
            size = max((len(g) for g in grids), default=1)
            self.grids = np.zeros((n, max(size, 1), 18))
            for k, st in enumerate(states):
                g = st.grid
                if g is not None and len(g):
                    self.grids[k, :len(g)] = g
                    self.grids[k, len(g):] = g[-1]

    def desired(self, trials: np.ndarray, t: np.ndarray, q: np.ndarray,
                at: np.ndarray | slice | None = None) -> tuple[np.ndarray, np.ndarray]:
        """``(q*, q_dot*, q_ddot*)`` (m, 18) of the trials ``trials`` (m,) at ``t`` (m,)
        [s] (a fixed goal's quintic started from the lengths ``q`` (m, 6) [m]) and the
        (m,) mask of the rows that have them; ``at``: ``trials`` or the slice they make."""
        m = len(trials)
        sel = trials if at is None else at
        out = np.zeros((m, 18))
        ok = np.ones(m, dtype=bool)
        tracking = self.tracking[sel]
        every = bool(tracking.all())
        if every or tracking.any():
            j = slice(None) if every else np.flatnonzero(tracking)
            jt = sel if every else trials[j]
            tk, dt, length = t[j], self.dt[jt], self.grid_len[jt]
            k = np.rint(tk / dt)
            end = (length > 0) & (tk > self.t_end[jt])
            on = ~end & (k >= 0) & (k < length) & (np.abs(tk - k * dt) <= GRID_TIME_TOLERANCE)
            index = np.where(end, length - 1, np.where(on, k, 0)).astype(int)
            if not self.shared:  # the trials' own grids, one after the other
                index += self.grids.shape[1] * self.index[jt]
            out[j] = self.grids.reshape(-1, 18).take(index, axis=0)
            for i in np.flatnonzero(~end & ~on).tolist():  # off the grid: on demand
                r = i if every else int(j[i])  # type: ignore[index]
                try:
                    out[r] = self.laws[int(trials[r])].reference_legs(
                        np.array([tk[i]]))[0].ravel()
                except Exception:  # the trial's own step refuses with the reason
                    ok[r] = False
        if not every:
            jq = np.flatnonzero(~tracking)
            for i in jq[self.quintic[trials[jq], 0] == 0.0].tolist():  # a first step
                self.laws[int(trials[i])].start_quintic(float(t[i]), q[i])
            out[jq] = quintic_rows(t[jq], self.quintic[trials[jq]])
        return out, ok

    def step(self, observations: ObservationBatch, out: CommandBatch, kp_ki: float,
             threshold: float, saturation: str) -> np.ndarray:
        """Step every row with finite readings into ``out`` (consecutive trials through
        one slice of the arrays, the same values); returns the rows left to the trials'
        own steps (readings not finite, no desired row, a result not accepted).

        Args:
            observations: The batch (row ``k`` of trial ``observations.trials[k]``).
            out: The commands, written in place.
            kp_ki: ``Kp Ki`` of the integral action (0: none).
            threshold: The rank test's relative singular-value threshold.
            saturation: The strategy over a force limit.
        """
        n = len(observations)
        if observations.q_dot is None:
            return np.arange(n)
        t = np.asarray(observations.t, dtype=float)
        q_all = np.asarray(observations.lengths, dtype=float)
        qd_all = np.asarray(observations.q_dot, dtype=float)
        trials = np.asarray(observations.trials, dtype=int)
        at: np.ndarray | slice
        if np.isfinite(t).all() and np.isfinite(q_all).all() and np.isfinite(qd_all).all():
            rows = np.arange(n)
            q, qd = q_all, qd_all
            first = int(trials[0]) if n else 0
            at = (slice(first, first + n) if n and int(trials[-1]) == first + n - 1
                  and bool((np.diff(trials) == 1).all()) else trials)
        else:
            finite = (np.isfinite(t) & np.isfinite(q_all).all(axis=1)
                      & np.isfinite(qd_all).all(axis=1))
            rows = np.flatnonzero(finite)
            trials = trials[rows]
            t, q, qd = t[rows], q_all[rows], qd_all[rows]
            at = trials
        X = self.X
        X[at, Q_IN] = q
        X[at, QD_IN] = qd
        desired, ok = self.desired(trials, t, q, at)
        if kp_ki:
            desired[:, 12:18] += kp_ki * self.integral[at]
        X[at, DESIRED] = desired
        if not ok.all():
            rows, trials, t, q, qd, desired = (a[ok] for a in (rows, trials, t, q, qd,
                                                               desired))
            at = trials
        if not len(rows):
            return np.arange(n)
        rows_in = X[at].copy() if isinstance(at, slice) else X[at]  # Newton moves its guesses
        Y, _ = evaluate_rows(self.function, rows_in, POSE_IN, POSE_OUT, RESIDUAL,
                             compiled_ctc.FK_TOLERANCE, FK_MAX_CALLS)
        accepted = accepted_rows(Y, STATUS, SCREEN, FACTOR, threshold)
        if accepted.all():  # every row: the slices of the batch's arrays
            ka, ta, Ya, e_rows, qd_a, desired_a = rows, at, Y, q, qd, desired
        else:
            a = np.flatnonzero(accepted)
            if not len(a):
                return np.arange(n)
            ka, ta, Ya = rows[a], trials[a], Y[a]
            e_rows, qd_a, desired_a = q[a], qd[a], desired[a]
        X[ta, POSE_IN] = Ya[:, POSE_OUT]  # the next steps' guesses
        self.steps[ta] += 1
        e = desired_a[:, 0:6] - e_rows
        forces = Ya[:, FORCES]
        over = over_limits(forces, self.limit[ta])
        if kp_ki:  # anti-windup: held while a leg's force is over its limit
            held = ~over
            tt = (self.index[ta] if isinstance(ta, slice) else ta)[held]
            self.integral[tt] += e[held] * self.dt[tt][:, None]
        assert out.forces is not None
        out.forces[ka] = forces
        out.error_norm[ka] = np.sqrt(norms(e))
        if over.any():
            tl = self.index[ta] if isinstance(ta, slice) else ta
            for i in np.flatnonzero(over).tolist():  # over a limit: the saturation strategy
                law = self.laws[int(tl[i])]
                out.forces[ka[i]] = law.saturated_forces(forces[i], Ya[i, POSE_OUT], qd_a[i],
                                                          desired_a[i, 6:12])
        slow = np.ones(n, dtype=bool)
        slow[ka] = False
        return np.flatnonzero(slow)


__all__ = ["GRID_TIME_TOLERANCE", "QUINTIC_SIZE", "JointRows", "JointState", "quintic_row_into",
           "quintic_rows", "quintic_timing"]
