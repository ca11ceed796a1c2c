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
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg.lapack import dsyevd as _eigenvalues

from controllers.base import (
    Command,
    Controller,
    ControllerContext,
    Goal,
    Observation,
)
from controllers.law_tools import goal_lengths
from controllers.solvers import compiled_ctc
from controllers.solvers.computed_torque import (
    ComputedTorqueSolver,
    SecondOrderGains,
    drive_forces,
)
from controllers.task_ctc import encoder_readings
from hexapod.actuation import Actuation
from hexapod.dynamics import DynamicModel
from hexapod.dynamics.model import INVERSE_TOLERANCE
from hexapod.fk import forward_kinematics
from hexapod.kinematics import inverse_kinematics
from hexapod.workspace import home_pose

#: Default natural frequency of the leg error [Hz].
NATURAL_FREQUENCY_HZ = 2.0
#: Peak of the quintic's speed over its mean speed.
QUINTIC_PEAK_SPEED = 15.0 / 8.0
#: Default damping ratio of the leg error.
DAMPING = 1.0
#: Forward-kinematics tolerance on the length residual [m] (as :func:`forward_kinematics`).
FK_TOLERANCE = 1e-12
#: How far from ``k dt`` an observation's time may be to use the reference's grid [s].
GRID_TIME_TOLERANCE = 1e-9
#: Calls of the compiled step (``compiled_ctc.FK_CALLS`` x 3 Newton iterations each)
#: before the numpy path takes over (as its budget of 50 iterations).
FK_MAX_CALLS = 16


class ComputedTorqueController(Controller):
    """Joint-space computed torque (see the module docstring).

    Args:
        natural_frequency: ``f_n`` [Hz] of the leg error's second-order response.
        damping: Its damping ratio ``zeta``.
        smooth_goal: Reach a fixed goal along the leg-space quintic (False: a step of
            ``q*`` to the goal, the error's free response).
    """

    name = "computed-torque"
    features = frozenset({"lengths"})
    actuation = Actuation.FORCE
    #: Samples ``context.reference`` itself (:mod:`controllers.tracking` passes it through).
    tracks_reference = True

    def __init__(self, natural_frequency: float = NATURAL_FREQUENCY_HZ,
                 damping: float = DAMPING, smooth_goal: bool = True) -> None:
        gains = SecondOrderGains.checked(self.name, natural_frequency, damping)
        self.solver = ComputedTorqueSolver(gains)
        self.kp = gains.kp
        self.kd = gains.kd
        self.smooth_goal = bool(smooth_goal)
        self._ctx: ControllerContext | None = None
        self._model: DynamicModel | None = None
        self._pose: tuple[np.ndarray, np.ndarray] | None = None
        self._q_star = np.zeros(6)
        #: ``(t0 [s], q0 [m], duration [s])`` of the quintic to a fixed goal.
        self._start: tuple[float, np.ndarray, float] | None = None
        #: Input row of the compiled step, its constant part filled at reset.
        self._row = np.zeros(compiled_ctc.ROW)
        #: ``(q*, q_dot*, q_ddot*)`` of a reference on the control grid ``k dt`` (N, 3, 6).
        self._grid = np.zeros((0, 3, 6))
        #: Steps taken by the compiled path and by the numpy path (diagnostics).
        self.compiled_steps = 0
        self.numpy_steps = 0

    def reset(self, context: ControllerContext) -> None:
        """Build the nominal model; read the reference or ``goal.lengths``.

        Raises:
            ContextError: Neither a reference nor finite goal lengths.
        """
        self._ctx = context
        self._model = DynamicModel(context.geometry)
        self._pose = None
        g, d = context.geometry, context.geometry.drives
        self._row[42:60] = g.base_points.ravel()
        self._row[60:78] = g.platform_points.ravel()
        self._row[78:97] = self._model.parameters
        self._row[97:115] = np.concatenate([np.broadcast_to(np.asarray(c, dtype=float), (6,))
                                            for c in (d.rotor_inertia, d.viscous, d.coulomb)])
        self._row[115:117] = (self.kp, self.kd)
        self._grid = np.zeros((0, 3, 6))
        if context.reference is None:
            self.retarget(context.goal)
        else:  # the reference's legs on the control grid, in one batched evaluation
            dt = float(context.dt)
            steps = math.ceil(float(context.reference.duration) / dt) + 3
            self._grid = self._reference_legs(dt * np.arange(steps))

    def retarget(self, goal: Goal) -> None:
        """A new fixed goal (ignored when tracking a reference: it is sampled itself)."""
        if self._ctx is not None and self._ctx.reference is not None:
            return
        self._q_star = goal_lengths(self.name, goal)
        self._start = None

    def desired(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(q*, q_dot*, q_ddot*)`` at time ``t`` [s] ([m], [m/s], [m/s^2])."""
        ctx, model = self._ctx, self._model
        assert ctx is not None and model is not None
        if ctx.reference is None:
            return self._quintic(t)
        k = round(t / float(ctx.dt))
        if len(self._grid) and t > float(ctx.reference.duration) + ctx.dt:
            g = self._grid[-1]  # at rest at the end, as the grid's last instant
            return g[0], g[1], g[2]
        if 0 <= k < len(self._grid) and abs(t - k * float(ctx.dt)) <= GRID_TIME_TOLERANCE:
            g = self._grid[k]
            return g[0], g[1], g[2]
        g = self._reference_legs(np.array([t]))[0]
        return g[0], g[1], g[2]

    def _reference_legs(self, times: np.ndarray) -> np.ndarray:
        """``(q*, q_dot*, q_ddot*)`` of the reference at ``times`` (N,) [s]: (N, 3, 6)."""
        ctx, model = self._ctx, self._model
        assert ctx is not None and model is not None
        ref = ctx.reference.at(times)
        R, p, tw, acc = ref.rotation, ref.translation, ref.twist, ref.twist_rate
        out = np.empty((len(times), 3, 6))
        out[:, 0] = [inverse_kinematics(ctx.geometry, Ri, pi) for Ri, pi in zip(R, p, strict=True)]
        K = model.terms_batch(R, p, tw)[2]
        rate, bias = model.legs_batch(R, p, tw)
        out[:, 1] = rate
        out[:, 2] = np.einsum("nij,nj->ni", K, acc) + bias
        return out

    def _quintic(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The leg-space quintic from the first measured lengths to ``goal.lengths``."""
        assert self._start is not None
        t0, q0, T = self._start
        d = self._q_star - q0
        if T <= 0.0:
            return self._q_star, np.zeros(6), np.zeros(6)
        x = min(max((t - t0) / T, 0.0), 1.0)
        s = x**3 * (10 - 15 * x + 6 * x**2)
        sd = 30 * x**2 * (1 - x) ** 2 / T if 0.0 < x < 1.0 else 0.0
        sdd = 60 * x * (1 - x) * (1 - 2 * x) / T**2 if 0.0 < x < 1.0 else 0.0
        return q0 + s * d, sd * d, sdd * d

    def step(self, observation: Observation) -> Command:
        """The leg forces of this period [N] (refused, zero, with a reason when the
        lengths, their rates or the time are missing or not finite, or the nominal model
        fails)."""
        if self._ctx is None or self._model is None:
            return self._refuse("reset(context) was not called")
        readings = encoder_readings(observation)
        if isinstance(readings, str):
            return self._refuse(readings)
        t, q, qd = readings
        if self._start is None:  # the fixed goal's quintic starts here
            T = QUINTIC_PEAK_SPEED * float(np.abs(self._q_star - q).max()) / \
                self._ctx.max_speed if self.smooth_goal else 0.0
            self._start = (t, q.copy(), T)
        try:
            q_s, qd_s, qdd_s = self.desired(t)
        except Exception as exc:  # the nominal model failed here: refuse with its reason
            return self._refuse(f"nominal model failed: {exc}")
        fast = self._compiled_step(q, qd, q_s, qd_s, qdd_s)
        if fast is not None:
            self.compiled_steps += 1
            return fast
        self.numpy_steps += 1
        return self._numpy_step(q, qd, q_s, qd_s, qdd_s)

    def _compiled_step(self, q: np.ndarray, qd: np.ndarray, q_s: np.ndarray,
                       qd_s: np.ndarray, qdd_s: np.ndarray) -> Command | None:
        """The step by :func:`compiled_ctc.joint_step` (rounding-level equal to
        :meth:`_numpy_step`), or None off its happy path (FK not converged from the
        previous pose, ``K`` rank-deficient, a singular inverse solve, a non-finite
        value): the numpy path then decides, with its reasons."""
        assert self._ctx is not None
        row = self._row
        if self._pose is None:
            R0, p0 = home_pose(self._ctx.geometry)
        else:
            R0, p0 = self._pose
        row[0:9] = R0.T.ravel()
        row[9:12] = p0
        row[12:18] = q
        row[18:24] = qd
        row[24:30] = q_s
        row[30:36] = qd_s
        row[36:42] = qdd_s
        step = compiled_ctc.joint_step(INVERSE_TOLERANCE)
        y = step.single(row)
        calls = 1
        while not y[54] < FK_TOLERANCE:  # Newton from the pose reached, as forward_kinematics
            if calls >= FK_MAX_CALLS or not math.isfinite(float(y[54])):
                return None
            row[0:12] = y[0:12]
            y = step.single(row)
            calls += 1
        if y[55] != 1.0 or not math.isfinite(float(y @ y)):
            return None
        # the squared singular values of K: the eigenvalues of K^T K (LAPACK syevd)
        w, _, info = _eigenvalues(y[12:48].reshape(6, 6), compute_v=0)
        if info != 0 or not (w[-1] > 0 and w[0] > self.solver.threshold**2 * w[-1]):
            return None
        s_max, s_min = math.sqrt(float(w[-1])), math.sqrt(float(w[0]))
        f = y[48:54]
        self._pose = (y[0:9].reshape(3, 3).T, y[9:12])
        e = q_s - q
        return Command.of_forces(f, error=e, error_norm=math.sqrt(float(e @ e)), rank=6,
                                 condition=s_max / s_min, features_used=6)

    def _numpy_step(self, q: np.ndarray, qd: np.ndarray, q_s: np.ndarray,
                    qd_s: np.ndarray, qdd_s: np.ndarray) -> Command:
        """The step by numpy around the model's separate compiled calls (the reference
        path)."""
        assert self._ctx is not None and self._model is not None
        try:
            fk = forward_kinematics(self._ctx.geometry, q, guess=self._pose,
                                    check_stroke=False)
            R, p = fk.rotation, fk.translation
            K = self._model.terms_batch(R[None], p[None], np.zeros((1, 6)))[2][0]
            twist = np.linalg.solve(K, qd)
            bias = self._model.legs_batch(R[None], p[None], twist[None])[1][0]
            e = q_s - q
            sol = self.solver.acceleration(-e, K, bias, twist, error_t=-qd_s,
                                           error_tt=-qdd_s)
            if sol.reason is not None:
                return self._refuse(sol.reason)
            a = K @ sol.acc + bias
            f = self._model.inverse(R, p, twist, sol.acc) + drive_forces(self._model, a, qd,
                                                                         qd_s)
        except Exception as exc:  # the nominal model failed here: refuse with its reason
            return self._refuse(f"nominal model failed: {exc}")
        if not np.all(np.isfinite(f)):
            return self._refuse(f"non-finite leg forces {f}")
        self._pose = (R, p)
        return Command.of_forces(f, error=e, error_norm=float(np.linalg.norm(e)),
                                 rank=sol.rank, condition=sol.condition, features_used=6)

    def _refuse(self, problem: str) -> Command:
        return Command.refuse(f"{self.name}: {problem}", actuation=Actuation.FORCE)
