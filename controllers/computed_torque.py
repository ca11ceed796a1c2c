"""Joint-space computed torque on the encoder lengths (the industrial baseline).

A force controller (:attr:`Actuation.FORCE`): it needs a dynamic world with force-mode
drives and the measured leg velocities ``q_dot`` (``Observation.q_dot``). Its model is the
controller context's NOMINAL geometry, inertia and drives, never the world's truth:

- reference ``q*(t)``, ``q_dot*(t)``, ``q_ddot*(t)``: the nominal inverse kinematics of the
  trajectory's pose (``context.reference``), ``q_dot* = K x_dot*`` and
  ``q_ddot* = K x_ddot* + K_dot x_dot*``; a fixed goal (``goal.lengths``) is reached along
  a quintic in leg space from the lengths measured at the first step, timed so that no
  leg's reference speed exceeds the nominal speed limit (a step on the full distance would
  saturate the drives and overshoot into the end stops);
- pose ``(R, t)``: the nominal forward kinematics of the encoder lengths, twist
  ``x_dot = K^-1 q_dot``;
- the joint-length task ``e = q - q*`` with ``L = K`` and ``L_dot tau = K_dot x_dot``,
  solved by :class:`~controllers.solvers.computed_torque.ComputedTorqueSolver`: desired
  leg acceleration ``a = q_ddot* + Kd (q_dot* - q_dot) + Kp (q* - q)`` with
  ``Kp = omega_n^2``, ``Kd = 2 zeta omega_n`` (the leg error obeys
  ``e_ddot + 2 zeta omega_n e_dot + omega_n^2 e = 0`` when the model is exact),
  platform acceleration ``x_ddot = K^-1 (a - K_dot x_dot)`` and the mechanism's forces
  ``DynamicModel.inverse(R, t, x_dot, x_ddot)``, plus the nominal drives' reflected rotor
  inertia ``m_r a`` and friction ``c q_dot + f_c tanh(q_dot* / v_s)``.

The force is held over the control period: the design is continuous, so ``omega_n dt``
must stay small. The default ``omega_n = 2 pi * 2 Hz`` with ``zeta = 1`` gives
``omega_n dt = 0.25`` at the 20 ms period.

Options beyond the gains: integral action ``integral_gain`` ``Ki`` [1/s] (default 0:
none), ``a = ... + Kp (e + Ki int e dt)`` with ``e = q* - q``, the integral held while a
leg's force is over the nominal drive's limit (anti-windup; with an exact model the
error obeys ``e_ddd + Kd e_dd + Kp e_d + Kp Ki e = 0``, stable for
``Ki < Kd = 2 zeta omega_n``); and what is commanded over that limit, ``saturation``
(:mod:`controllers.solvers.saturation`: ``"clip"`` per leg, the default and what the
drives do, ``"scale"`` or ``"qp"``).

One step over a batch (:meth:`ComputedTorqueController.step_arrays`): the rows through the
compiled step in one C call (:mod:`controllers.ctc_rows`).
"""

from __future__ import annotations

import math

import numpy as np

from controllers.base import (
    Command,
    CommandBatch,
    Controller,
    ControllerContext,
    Goal,
    Observation,
    ObservationBatch,
)
from controllers.ctc_rows import (
    accepted_rows,
    evaluate_rows,
    finite_readings_rows,
    over_limits,
    rank_condition,
    refusal,
)
from controllers.law_tools import goal_lengths
from controllers.solvers import compiled_ctc
from controllers.solvers.computed_torque import (
    ComputedTorqueSolver,
    SecondOrderGains,
    checked_integral_gain,
)
from controllers.solvers.saturation import (
    checked_strategy,
    over_limit,
    saturated,
    zero_acceleration_forces,
)
from controllers.task_ctc import encoder_readings, finite_readings
from hexapod.actuation import Actuation
from hexapod.compiled import BoundCall, CompilationError
from hexapod.dynamics import DynamicModel
from hexapod.dynamics.model import INVERSE_TOLERANCE
from hexapod.kinematics import inverse_kinematics
from hexapod.workspace import home_pose

#: Default natural frequency of the leg error [Hz].
NATURAL_FREQUENCY_HZ = 2.0
#: Peak of the quintic's speed over its mean speed.
QUINTIC_PEAK_SPEED = 15.0 / 8.0
#: Default damping ratio of the leg error.
DAMPING = 1.0
#: Forward-kinematics tolerance on the length residual [m] (as :func:`forward_kinematics`).
FK_TOLERANCE = compiled_ctc.FK_TOLERANCE
#: How far from ``k dt`` an observation's time may be to use the reference's grid [s].
GRID_TIME_TOLERANCE = 1e-9
#: Calls of the compiled step (``compiled_ctc.FK_CALLS`` x 3 Newton iterations each)
#: before the step is refused (as the 50 iterations of :func:`hexapod.fk.forward_kinematics`).
FK_MAX_CALLS = 16
#: Where the compiled step's blocks lie in its rows (:data:`compiled_ctc.INPUTS`,
#: :data:`compiled_ctc.OUTPUTS`), looked up once.
_DESIRED, _POSE_IN = compiled_ctc.INPUTS["desired"], compiled_ctc.INPUTS["pose"]
_POSE_OUT, _FACTOR, _FORCES = (compiled_ctc.OUTPUTS[k] for k in ("pose", "factor", "forces"))
_RESIDUAL, _STATUS = (compiled_ctc.OUTPUTS.index(k) for k in ("fk_residual", "status"))


class ComputedTorqueController(Controller):
    """Joint-space computed torque (see the module docstring).

    Args:
        natural_frequency: ``f_n`` [Hz] of the leg error's second-order response.
        damping: Its damping ratio ``zeta``.
        smooth_goal: Reach a fixed goal along the leg-space quintic (False: a step of
            ``q*`` to the goal, the error's free response).
        integral_gain: Integral action Ki [1/s] on the leg error (default 0: none).
            Stable below ``2 zeta omega_n``; the integral is held while a leg's force is
            over its limit (anti-windup).
        saturation: Forces over the drives' limit: "clip", "scale" or "qp" (default
            "clip"). Each leg clipped (as the drives do), the force vector scaled, or the
            acceleration scaled (:mod:`controllers.solvers.saturation`).
    """

    name = "computed-torque"
    features = frozenset({"lengths"})
    actuation = Actuation.FORCE
    #: Samples ``context.reference`` itself (:mod:`controllers.tracking` passes it through).
    tracks_reference = True

    def __init__(self, natural_frequency: float = NATURAL_FREQUENCY_HZ,
                 damping: float = DAMPING, smooth_goal: bool = True,
                 integral_gain: float = 0.0, saturation: str = "clip") -> None:
        gains = SecondOrderGains.checked(self.name, natural_frequency, damping)
        self.integral_gain = checked_integral_gain(self.name, integral_gain)
        self.saturation = checked_strategy(self.name, saturation)
        #: ``int (q* - q) dt`` [m s] (integral action) and the nominal force limits [N].
        self._integral = np.zeros(6)
        self._limit = np.full(6, np.inf)
        self._limit_list = self._limit.tolist()
        self.solver = ComputedTorqueSolver(gains)
        self.kp = gains.kp
        self.kd = gains.kd
        self.smooth_goal = bool(smooth_goal)
        self._ctx: ControllerContext | None = None
        self._model: DynamicModel | None = None
        #: The last pose found, as set (:attr:`_pose`) or as the compiled step's
        #: ``(R column-major, t)`` row (12,) (None: the set one is the pose).
        self._pose_set: tuple[np.ndarray, np.ndarray] | None = None
        self._pose_row: np.ndarray | None = None
        self._q_star = np.zeros(6)
        #: ``(t0 [s], duration [s], q0 [m], q* - q0 [m])`` of the quintic to a fixed goal
        #: (the legs as lists of floats).
        self._start: tuple[float, float, list[float], list[float]] | None = None
        #: The compiled step's own input and output rows (bound at the first reset): the
        #: input's constant part is filled at reset; its pose guess (block ``pose``) is
        #: :attr:`_pose` when ``_guess_in_row`` (else written from it).
        self._bound: BoundCall | None = None
        self._guess_in_row = False
        #: ``(q*, q_dot*, q_ddot*)`` of a reference on the control grid ``k dt`` (N, 18).
        self._grid = np.zeros((0, 18))
        #: The control period [s] and the time after which the reference is at rest [s].
        self._dt = 0.0
        self._t_end = math.inf
        #: Commands given by the compiled step (diagnostics).
        self.compiled_steps = 0

    @property
    def _pose(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The last pose found ``(R, t)`` (the forward kinematics' next guess), or None."""
        row = self._pose_row
        if row is None:
            return self._pose_set
        return row[0:9].reshape(3, 3).T, row[9:12]

    @_pose.setter
    def _pose(self, pose: tuple[np.ndarray, np.ndarray] | None) -> None:
        self._pose_set, self._pose_row, self._guess_in_row = pose, None, False

    def __getstate__(self) -> dict[str, object]:
        """Picklable: the compiled step's binding (ctypes) is left out, its input row
        kept and bound again on unpickling."""
        state = self.__dict__.copy()
        bound = state.pop("_bound")
        state["_bound_row"] = None if bound is None else bound.x.copy()
        return state

    def __setstate__(self, state: dict[str, object]) -> None:
        row = state.pop("_bound_row")
        self.__dict__.update(state)
        self._bound = None
        if isinstance(row, np.ndarray):
            self._bound = compiled_ctc.joint_step(INVERSE_TOLERANCE).bind()
            self._bound.x[:] = row

    @property
    def input_row(self) -> np.ndarray:
        """The compiled step's input row (n_in,) (the bound one, written in place)."""
        assert self._bound is not None
        return self._bound.x

    @property
    def force_limit(self) -> np.ndarray:
        """(6,) the nominal drives' force limits [N] (inf before a reset)."""
        return self._limit

    @property
    def _desired_row(self) -> np.ndarray:
        """The input row's ``(q*, q_dot*, q_ddot*)`` (18,) (a view)."""
        assert self._bound is not None
        return self._bound.x[_DESIRED]

    def reset_trial(self, context: ControllerContext) -> None:
        """Build the nominal model; read the reference or ``goal.lengths``.

        Raises:
            ContextError: Neither a reference nor finite goal lengths.
        """
        self._ctx = context
        self._model = DynamicModel(context.geometry)
        self._pose = None
        self._integral = np.zeros(6)
        self._limit = np.asarray(context.geometry.drives.force_limit, dtype=float)
        self._limit_list = self._limit.tolist()
        if self._bound is None:
            self._bound = compiled_ctc.joint_step(INVERSE_TOLERANCE).bind()
        row = self._bound.inputs
        g, d = context.geometry, context.geometry.drives
        row["points"][:] = (g.base_points, g.platform_points)
        row["params"][:] = self._model.parameters
        row["rotor"][:] = d.rotor_inertia
        row["viscous"][:] = d.viscous
        row["coulomb"][:] = d.coulomb
        row["gains"][:] = (self.kp, self.kd)
        self._grid = np.zeros((0, 18))
        self._dt = float(context.dt)
        if context.reference is None:
            self._t_end = math.inf
            self.retarget_trial(context.goal)
        else:  # the reference's legs on the control grid, in one batched evaluation
            dt = self._dt
            self._t_end = float(context.reference.duration) + context.dt
            steps = math.ceil(float(context.reference.duration) / dt) + 3
            self._grid = self._reference_legs(dt * np.arange(steps)).reshape(steps, 18)

    def retarget_trial(self, goal: Goal) -> None:
        """A new fixed goal (ignored when tracking a reference: it is sampled itself)."""
        if self._ctx is not None and self._ctx.reference is not None:
            return
        self._q_star = goal_lengths(self.name, goal)
        self._start = None

    def desired(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(q*, q_dot*, q_ddot*)`` at time ``t`` [s] ([m], [m/s], [m/s^2])."""
        out = np.empty(18)
        self._desired_into(t, out)
        return out[0:6], out[6:12], out[12:18]

    def _desired_into(self, t: float, out: np.ndarray) -> None:
        """:meth:`desired` written into ``out`` (18,): ``q*``, ``q_dot*``, ``q_ddot*``."""
        ctx = self._ctx
        assert ctx is not None
        if ctx.reference is None:
            self._quintic_into(t, out)
            return
        grid, dt = self._grid, self._dt
        k = round(t / dt)
        if len(grid) and t > self._t_end:  # at rest at the end, as the grid's last instant
            out[:] = grid[-1]
            return
        if 0 <= k < len(grid) and abs(t - k * dt) <= GRID_TIME_TOLERANCE:
            out[:] = grid[k]
            return
        out[:] = self._reference_legs(np.array([t]))[0].ravel()

    def _reference_legs(self, times: np.ndarray) -> np.ndarray:
        """``(q*, q_dot*, q_ddot*)`` of the reference at ``times`` (N,) [s]: (N, 3, 6)."""
        ctx, model = self._ctx, self._model
        assert ctx is not None and model is not None
        ref = ctx.reference.at(times)
        R, p, tw, acc = ref.rotation, ref.translation, ref.twist, ref.twist_rate
        out = np.empty((len(times), 3, 6))
        out[:, 0] = inverse_kinematics(ctx.geometry, R, p)  # batched: the same numbers
        K = model.jacobian_batch(R, p)
        rate, bias = model.legs_batch(R, p, tw)
        out[:, 1] = rate
        out[:, 2] = np.einsum("nij,nj->ni", K, acc) + bias
        return out

    def _quintic_into(self, t: float, out: np.ndarray) -> None:
        """The leg-space quintic from the first measured lengths to ``goal.lengths``
        (``q*``, ``q_dot*``, ``q_ddot*`` into ``out`` (18,))."""
        assert self._start is not None
        t0, T, a, b = self._start
        if T <= 0.0:
            out[0:6] = self._q_star
            out[6:18] = 0.0
            return
        x = min(max((t - t0) / T, 0.0), 1.0)
        s = x**3 * (10 - 15 * x + 6 * x**2)
        if 0.0 < x < 1.0:
            sd = 30 * x**2 * (1 - x) ** 2 / T
            sdd = 60 * x * (1 - x) * (1 - 2 * x) / T**2
        else:
            sd = sdd = 0.0
        # q0 + s d, s_dot d, s_ddot d: a multiplication and an addition per value, as
        # numpy's elementwise ones (same numbers; in Python floats, no array calls)
        out[:] = [a[0] + s * b[0], a[1] + s * b[1], a[2] + s * b[2],
                  a[3] + s * b[3], a[4] + s * b[4], a[5] + s * b[5],
                  sd * b[0], sd * b[1], sd * b[2], sd * b[3], sd * b[4], sd * b[5],
                  sdd * b[0], sdd * b[1], sdd * b[2], sdd * b[3], sdd * b[4], sdd * b[5]]

    def step_trial(self, observation: Observation) -> Command:
        """The leg forces of this period [N] (refused, zero, with a reason when the
        lengths, their rates or the time are missing or not finite, or the nominal model
        fails)."""
        if self._ctx is None or self._model is None or self._bound is None:
            return self._refuse("reset(context) was not called")
        row = self._bound.inputs
        fast_readings = finite_readings(observation, row["q"], row["q_dot"])
        if fast_readings is None:  # encoder_readings decides (its reasons), off the common case
            readings = encoder_readings(observation)
            if isinstance(readings, str):
                return self._refuse(readings)
            t, q, qd = readings
            row["q"][:] = q
            row["q_dot"][:] = qd
        else:
            t, q, qd = fast_readings
        if self._start is None:
            self._start_quintic(t, q)
        desired = self._desired_row
        try:
            self._desired_into(t, desired)
        except Exception as exc:  # the nominal model failed here: refuse with its reason
            return self._refuse(f"nominal model failed: {exc}")
        self._add_integral(desired)
        cmd = self._compiled_core(q)
        if isinstance(cmd, str):
            return self._refuse(cmd)
        self.compiled_steps += 1
        assert cmd.forces is not None and self._pose_row is not None
        cmd.forces = self._limited(cmd.forces, self._pose_row, qd, desired[6:12], cmd.error)
        return cmd

    def _start_quintic(self, t: float, q: np.ndarray) -> None:
        """Start the fixed goal's quintic at ``t`` [s] from the lengths ``q`` [m]."""
        assert self._ctx is not None
        T = QUINTIC_PEAK_SPEED * float(np.abs(self._q_star - q).max()) / \
            self._ctx.max_speed if self.smooth_goal else 0.0
        self._start = (t, T, q.tolist(), (self._q_star - q).tolist())

    def _add_integral(self, desired: np.ndarray) -> None:
        """The integral action folded into the desired leg acceleration ``q_ddot*``
        (``+ Kp Ki int (q* - q) dt``; nothing without it)."""
        if self.integral_gain:
            desired[12:18] += self.kp * self.integral_gain * self._integral

    def _limited(self, forces: np.ndarray, pose: np.ndarray, qd: np.ndarray,
                 qd_s: np.ndarray, error: np.ndarray | None, over: bool | None = None
                 ) -> np.ndarray:
        """The forces [N] of an accepted step under the saturation strategy; the
        integral of the leg error ``error`` (``q* - q`` [m]) advanced by the period
        unless a leg's force is over its limit (anti-windup; ``over`` when known)."""
        if over is None:
            over = over_limit(forces, self._limit_list)
        if self.integral_gain and not over and error is not None:
            self._integral += error * self._dt
        if not over:
            return forces
        bias = None
        if self.saturation == "qp":
            assert self._model is not None
            bias = zero_acceleration_forces(self._model, pose, qd, coulomb_velocity=qd_s)
        return saturated(self.saturation, forces, self._limit, bias)

    def step_arrays(self, observations: ObservationBatch, out: CommandBatch) -> np.ndarray:
        """The rows whose readings are finite through the compiled step in one C call
        (:func:`~controllers.ctc_rows.evaluate_rows`); returns the other rows and those
        whose result is not accepted (left to the trial's own step, which says why)."""
        obs = observations
        n = len(obs)
        readings = finite_readings_rows(obs, self.trial_instances)
        if readings is None:
            return np.arange(n)
        t, q_all, qd_all, finite = readings
        rows = [(k, inst) for k, inst in finite if isinstance(inst, ComputedTorqueController)
                and inst.prepare_row(float(t[k]), q_all[k], qd_all[k])]
        slow = np.ones(n, dtype=bool)
        if not rows:
            return np.arange(n)
        bound = self._bound
        assert bound is not None
        X = np.stack([inst.input_row for _, inst in rows])
        Y, _ = evaluate_rows(bound.function, X, _POSE_IN, _POSE_OUT, _RESIDUAL,
                             FK_TOLERANCE, FK_MAX_CALLS)
        accepted = np.flatnonzero(accepted_rows(Y, _STATUS, _FACTOR, self.solver.threshold))
        if len(accepted):
            over = over_limits(Y[accepted, _FORCES],
                               np.stack([rows[j][1].force_limit for j in accepted.tolist()]))
            for j, o in zip(accepted.tolist(), over.tolist(), strict=True):
                k, inst = rows[j]
                inst.take_row(Y[j], q_all[k], qd_all[k], out, k, o)
                slow[k] = False
        return np.flatnonzero(slow)

    def prepare_row(self, t: float, q: np.ndarray, qd: np.ndarray) -> bool:
        """Write this period's readings, reference and pose guess into the input row
        (False: the trial's own step decides, e.g. the nominal model fails)."""
        if self._ctx is None or self._model is None or self._bound is None:
            return False
        row = self._bound.inputs
        row["q"][:] = q
        row["q_dot"][:] = qd
        if self._start is None:
            self._start_quintic(t, q)
        desired = self._desired_row
        try:
            self._desired_into(t, desired)
        except Exception:  # the trial's own step refuses with the reason
            return False
        self._add_integral(desired)
        if not self._guess_in_row:
            pose = self._pose
            R0, p0 = home_pose(self._ctx.geometry) if pose is None else pose
            row["pose"][0:9] = R0.T.ravel()
            row["pose"][9:12] = p0
            self._guess_in_row = True
        return True

    def take_row(self, y: np.ndarray, q: np.ndarray, qd: np.ndarray, out: CommandBatch,
                  k: int, over: bool) -> None:
        """Take the compiled step's accepted output row ``y`` as row ``k`` of ``out``
        (``over``: a leg's force is over its limit); its pose is the next guess."""
        assert self._bound is not None
        pose = y[_POSE_OUT].copy()
        self._bound.x[_POSE_IN] = pose  # the next step's guess
        self._pose_row, self._guess_in_row = pose, True
        self.compiled_steps += 1
        desired = self._bound.x[_DESIRED]
        e = desired[0:6] - q
        assert out.forces is not None
        out.forces[k] = self._limited(y[_FORCES], pose, qd, desired[6:12], e, over)
        out.error_norm[k] = math.sqrt(e.dot(e))

    def _compiled_step(self, q: np.ndarray, qd: np.ndarray, q_s: np.ndarray,
                       qd_s: np.ndarray, qdd_s: np.ndarray) -> Command:
        """The step by :func:`compiled_ctc.joint_step` from these readings and this
        reference (a refusal with its reason off its happy path)."""
        assert self._bound is not None
        row = self._bound.inputs
        row["q"][:] = q
        row["q_dot"][:] = qd
        row["desired"][:] = (q_s, qd_s, qdd_s)
        out = self._compiled_core(q)
        return self._refuse(out) if isinstance(out, str) else out

    def _compiled_core(self, q: np.ndarray) -> Command | str:
        """:meth:`_compiled_step` with ``q``, ``q_dot`` and ``(q*, q_dot*, q_ddot*)``
        already in the input row; off the happy path (FK not converged from the previous
        pose within ``FK_MAX_CALLS`` calls, a singular inverse solve, a non-finite
        value, ``K`` rank-deficient) the reason its status gives
        (:func:`~controllers.ctc_rows.refusal`),
        the pose guess left as it was."""
        assert self._ctx is not None and self._bound is not None
        bound = self._bound
        pose_in, y, call = bound.inputs["pose"], bound.y, bound.call
        if not self._guess_in_row:
            pose = self._pose
            R0, p0 = home_pose(self._ctx.geometry) if pose is None else pose
            pose_in[0:9] = R0.T.ravel()
            pose_in[9:12] = p0
            self._guess_in_row = True
        if call():
            raise CompilationError(f"{bound.function.name}: the compiled function failed")
        calls = 1
        while not y[_RESIDUAL] < FK_TOLERANCE:  # Newton from the pose reached, as FK does
            self._guess_in_row = False
            if calls >= FK_MAX_CALLS or not math.isfinite(y[_RESIDUAL]):
                break
            pose_in[:] = y[_POSE_OUT]
            if call():
                raise CompilationError(f"{bound.function.name}: the compiled function failed")
            calls += 1
        condition = None
        if y[_STATUS] == 0.0:  # the kernel's status (controllers.ctc_status), then the rank
            condition = rank_condition(y[_FACTOR], self.solver.threshold)
        if condition is None:
            reason = refusal(y, _STATUS, _RESIDUAL, _FACTOR, self.solver.threshold)
            assert reason is not None
            return reason
        out = y.copy()
        pose_in[:] = out[_POSE_OUT]  # the next step's guess
        self._pose_row, self._guess_in_row = out[_POSE_OUT], True
        e = bound.x[_DESIRED][0:6] - q
        return Command(np.zeros(6), error=e, error_norm=math.sqrt(e.dot(e)), rank=6,
                       condition=condition, features_used=6, active_constraints=[], notes=[],
                       actuation=Actuation.FORCE, forces=out[_FORCES])

    def _refuse(self, problem: str) -> Command:
        return Command.refuse(f"{self.name}: {problem}", actuation=Actuation.FORCE)

