"""The force-level predictive controllers' receding horizon (:class:`ForceMPCLaw`),
here for ``leg-edge-force-mpc`` (its pose variant ``pose-force-mpc``:
:mod:`controllers.force_mpc.variants`; both in full: ``docs/dynamic-world.md``).

Each period: the encoders and the features (refused, zero forces, with the reason when
one is missing or not finite); the state from the NOMINAL forward kinematics and ``K^-1
q_dot``; the held computed-torque law's reference at ``t + k dt``, ``k = 1..N``; up to
``max_iter`` Gauss-Newton QPs (:func:`controllers.mpc.solver.run_sqp`) from the
previous plan shifted by one period; apply ``f_0``. A failed solve falls back to the
held law for that period (said in ``notes``, counted in :attr:`ForceMPCLaw.stats`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from controllers.base import Command, ControllerContext, Goal, Observation
from controllers.exceptions import ContextError, named_as
from controllers.feature_ctc import LegEdgeCTC
from controllers.force_mpc.problem import STATE, ForceProblemSpec, force_kernel
from controllers.law_tools import check_count, check_number
from controllers.mpc.solver import PredictiveLaw, QPArrays, compiled_qp, run_sqp
from controllers.task_ctc import (
    DAMPING,
    NATURAL_FREQUENCY_HZ,
    TaskComputedTorque,
    encoder_readings,
)
from controllers.tasks.feature_kind import BuiltinFeature
from controllers.tasks.leg_edge import EDGE_NORMALS
from hexapod.actuation import Actuation
from hexapod.compiled import BoundCall
from hexapod.dynamics.compiled import parameter_row
from hexapod.exceptions import HexapodError
from hexapod.fk import forward_kinematics

#: Largest planned force beyond its bound accepted from the QP, relative to the bound
#: (DAQP's solutions were seen up to 4e-5 beyond it in the perf runs: 0.008 N at
#: 200 N); the plan is then clipped onto the bounds.
BOUND_TOLERANCE = 1e-4
#: Default cap of the Gauss-Newton QPs per period (one let the plans' end stages
#: oscillate; ``docs/dynamic-world.md``, "Why three Gauss-Newton QPs").
MAX_ITER = 3


class ForceMPCLaw(PredictiveLaw):
    """Base of the force-level predictive controllers (see the module docstring): the
    subclasses say which features (:attr:`feature`), which law they hold
    (:attr:`law_class`), and read the features and the reference.

    Args:
        horizon: Number of periods ``N`` predicted (1 to 50).
        substeps: Integration steps per period of the prediction (``h = dt / substeps``;
            at the world's own step, the world's integration of the nominal robot).
        error_weight: Weight of the feature error of the stages ``1..N-1``.
        terminal_weight: Weight of the feature error of stage ``N``.
        rate_weight: Weight of the force rate ``sum_k |f_k - f_{k-1}|^2`` [1/N^2].
        effort_weight: Weight of the forces ``sum_k |f_k|^2`` [1/N^2].
        max_iter: Most Gauss-Newton QPs per period (stopping once the first force has
            converged; 1: the real-time iteration).
        natural_frequency: ``f_n`` [Hz] of the fallback computed-torque law
            (``leg-edge-ctc``; ``cartesian-ctc`` for ``pose-force-mpc``).
        damping: Damping ratio of the fallback law.
        smooth_goal: Reach a fixed goal along a quintic line (False: the goal as a step),
            as the fallback law does.
        friction_smoothing: Speed ``v_g`` [m/s] at which the QP's sensitivities smooth
            the drives' Coulomb friction (the prediction itself keeps the drives' model).
        compiled: Generate the kernel and DAQP to C (False: the CasADi virtual machine
            and ``casadi.conic``; the same results, much slower).
    """

    #: The features of the predictive problem (a feature object with a force-MPC
    #: problem: :data:`~controllers.tasks.leg_edge.EDGE_NORMALS`,
    #: :data:`~controllers.tasks.platform_pose.PLATFORM_POSE`).
    feature: BuiltinFeature = EDGE_NORMALS
    #: The computed-torque law of the same features: reference, goal and fallback.
    law_class: type[TaskComputedTorque] = LegEdgeCTC
    actuation = Actuation.FORCE
    fallback_note = "force-mpc fallback"
    #: Samples ``context.reference`` itself (:mod:`controllers.tracking` passes it through).
    tracks_reference = True

    def __init__(self, horizon: int = 10, substeps: int = 4, error_weight: float = 1.0,
                 terminal_weight: float = 1.0, rate_weight: float = 1e-8,
                 effort_weight: float = 0.0, max_iter: int = MAX_ITER,
                 natural_frequency: float = NATURAL_FREQUENCY_HZ, damping: float = DAMPING,
                 smooth_goal: bool = True, friction_smoothing: float = 3e-3,
                 compiled: bool = True) -> None:
        name = self.name
        self.rate_weight, self.effort_weight = self._check_options(
            horizon, error_weight, terminal_weight,
            (("rate_weight", rate_weight), ("effort_weight", effort_weight)), compiled)
        self.substeps = check_count(name, "substeps", substeps, 1, 100)
        self.max_iter = check_count(name, "max_iter", max_iter, 1, 20)
        self.friction_smoothing = check_number(name, "friction_smoothing",
                                               friction_smoothing)
        #: The fallback law, whose reference and goal this controller tracks.
        with named_as(name):
            self.law: Any = self.law_class(natural_frequency=natural_frequency,
                                           damping=damping, smooth_goal=smooth_goal)
        self.spec = ForceProblemSpec(horizon, substeps, self.feature)
        self._bound: BoundCall | None = None
        #: The plan of the last step (6 N,) [N] (before the shift).
        self.plan: np.ndarray | None = None

    def __getstate__(self) -> dict[str, object]:
        """A deep copy's state: the views of the state block left out, taken again of the
        copy's own binding (:meth:`__setstate__`; copied, they would be arrays of their
        own, written by the step but never read by its C)."""
        state = self.__dict__.copy()
        state.pop("_state", None)
        return state

    def __setstate__(self, state: dict[str, object]) -> None:
        self.__dict__.update(state)
        if self._bound is not None:
            self._state = STATE.views(self._bound.inputs["state"])

    # ----------------------------------------------------------------- reset
    def reset_trial(self, context: ControllerContext) -> None:
        """Reset the held law (reference, goal), build or load the compiled kernel and
        write the nominal model's constants.

        Raises:
            ContextError: A field the controller needs is missing or invalid.
        """
        with named_as(self.name):
            self.law.reset(context)  # (a batch of one: its step is the batch's)
        self.context = context
        g = context.geometry
        dt = float(context.dt)
        if not (math.isfinite(dt) and dt > 0):
            raise ContextError(self.name, "dt", f"expected a positive period [s], got {dt}")
        self._kernel = force_kernel(self.spec, self.compiled)
        self._bound = self._kernel.bind()
        v = self._bound.inputs
        #: The state's blocks in the kernel input (written each step).
        self._state = STATE.views(v["state"])
        d = g.drives
        v["model_A"][:] = g.base_points
        v["model_E"][:] = g.platform_points
        v["model_params"][:] = parameter_row(g.inertia)
        v["model_rotor"][:] = d.rotor_inertia
        v["model_viscous"][:] = d.viscous
        v["model_coulomb"][:] = d.coulomb
        v["model_h"][:] = dt / self.substeps
        v["model_smoothing"][:] = self.friction_smoothing
        self.camera_constants(context, v)
        v["weights"][:] = (self.error_weight, self.terminal_weight, self.rate_weight,
                           self.effort_weight)
        self._limit = np.tile(np.asarray(d.force_limit, dtype=float), self.horizon)
        n = 6 * self.horizon
        if self.compiled:  # DAQP of this size built now
            compiled_qp(n, n)
        self._eye = np.eye(n)
        self._dt = dt
        self._restart()
        self.plan = None
        self._f_prev = np.zeros(6)
        self._started = False
        self._t0 = 0.0
        self._guess: tuple[np.ndarray, np.ndarray] | None = None

    def retarget_trial(self, goal: Goal) -> None:
        """A new fixed goal (ignored when tracking ``context.reference``)."""
        with named_as(self.name):
            self.law.retarget(goal)
        if self.context is not None and self.context.reference is None:
            self._started = False

    # ----------------------------------------------------------------- step
    def step_trial(self, observation: Observation) -> Command:
        """The leg forces of this period [N], or a refusal (zeros) with its reason."""
        if self.context is None or self._bound is None:
            return self._refuse("reset(context) was not called")
        readings = encoder_readings(observation, self.context.geometry.stroke)
        if isinstance(readings, str):
            return self._refuse(readings)
        t, q, qd = readings
        seen = self._features(observation)
        if isinstance(seen, str):
            return self._refuse(seen)
        observed, mask = seen
        if not self._started:  # the held law starts its reference (line to the goal) here
            first = self.law_step(observation)
            if first.reason is not None:
                return self._refuse(first.reason.removeprefix(f"{self.law.name}: "))
            self._started = True
            # the law's clock: the reference's own, or the line's from this step
            self._t0 = t if self.context.reference is None else 0.0
            self._U = np.tile(np.asarray(first.forces, dtype=float), self.horizon)
            self._f_prev = np.asarray(first.forces, dtype=float).copy()
        try:
            R, p = self._pose(q)
            # K^-1 q_dot of the nominal model at the pose (K rows [u_i, (R eB_i) x u_i])
            g = self.context.geometry
            r = g.platform_points @ R.T
            legs = p + r - g.base_points
            u = legs / np.linalg.norm(legs, axis=1)[:, None]
            twist = np.linalg.solve(np.hstack([u, np.cross(r, u)]), qd)
            reference, known = self._reference(t - self._t0)
        except (HexapodError, np.linalg.LinAlgError, ValueError) as exc:
            return self._fallback(observation, f"nominal model failed: {exc}")
        mask = np.where(known, mask, 0.0)  # the rows' weights (0: unused)
        if observed is None:  # the features are the pose itself
            observed = np.concatenate([p, R.T.ravel()])
        used = self.used(mask)
        if isinstance(used, str):
            return self._refuse(used)
        v = self._bound.inputs
        state = self._state
        state["R"][:] = R.T.ravel()
        state["t"][:] = p
        state["twist"][:] = twist
        v["f_prev"][:] = self._f_prev
        v["reference"][:] = reference
        v["observed"][:] = np.where(mask, observed, 0.0)
        v["mask"][:] = mask
        return self._solve(observation, observed, reference[0], mask, used)

    def _solve(self, observation: Observation, normals: np.ndarray, ref_now: np.ndarray,
               mask: np.ndarray, used: int) -> Command:
        """The Gauss-Newton QPs from the warm start (full steps), and the command."""
        self.stats.steps += 1
        U, converged, status, last, it = run_sqp(self._evaluate, self._qp_data, self._U.copy(),
                                                 self.max_iter, 1e-3, self.compiled, floor=1.0)
        if U is None or last is None:
            return self._fallback(observation, status)
        self.stats.total_sqp_iterations += it
        if not converged and self.max_iter > 1:
            self.stats.unconverged += 1
        lim = self._limit
        if not (math.isfinite(float(U.sum()))
                and np.all(np.abs(U) <= lim * (1.0 + BOUND_TOLERANCE))):
            worst = int(np.argmax(np.abs(U) - lim))
            return self._fallback(observation, f"planned force out of its bounds: leg "
                                  f"{worst % 6} at stage {worst // 6}: {U[worst]} N, limit "
                                  f"{lim[worst]} N")
        U = np.clip(U, -lim, lim)  # within DAQP's tolerance of the bounds: onto them
        f = U[:6]
        self.plan = U.copy()
        self._U = self._shift(U)
        self._f_prev = f.copy()
        e = np.where(mask, normals - ref_now, 0.0)
        return Command.of_forces(f, error=e, error_norm=float(np.linalg.norm(e)),
                                 features_used=used,
                                 notes=[f"force-mpc: {status}; last QP: {last.status}"])

    def _evaluate(self, U: np.ndarray) -> np.ndarray | str:
        """The kernel's ``H`` and ``g`` at ``U`` (its output's first blocks, a view), or
        why not."""
        assert self._bound is not None
        self._bound.inputs["U"][:] = U
        if self._bound.call():
            return "the compiled kernel failed"
        return self._bound.y[:self._kernel.outputs["g"].stop]

    def _qp_data(self, out: np.ndarray, U: np.ndarray) -> QPArrays:
        """``(H, g, C, lba, uba)``: the force limits as bounds on the step from ``U``."""
        n = U.size
        return out[:n * n].reshape(n, n), out[n * n:], self._eye, -self._limit - U, \
            self._limit - U

    # ----------------------------------------------------------------- pieces
    def camera_constants(self, context: ControllerContext, v: dict[str, np.ndarray]) -> None:
        """Write the camera's constants of the kernel (none by default).

        Raises:
            ContextError: A field the features need is missing or invalid.
        """

    def _features(self, observation: Observation
                  ) -> tuple[np.ndarray | None, np.ndarray] | str:
        """The observed features (m,) (None: the pose of the encoders) and the rows'
        weights (m,) (0: not seen), or why not."""
        raise NotImplementedError

    def used(self, mask: np.ndarray) -> int | str:
        """The features the rows ``mask`` use, as the command reports them, or why they
        are too few to control the six legs."""
        return int(mask.sum())

    def _pose(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The nominal forward kinematics of the lengths [m] (warm-started)."""
        assert self.context is not None
        fk = forward_kinematics(self.context.geometry, q, guess=self._guess,
                                check_stroke=False)
        self._guess = (fk.rotation, fk.translation)
        return fk.rotation, fk.translation

    def _reference(self, tr: float) -> tuple[np.ndarray, np.ndarray]:
        """The reference features (N, m) of the stages at ``tr + k dt``, ``k = 1..N``,
        [s] on the reference's clock, and the rows known at every stage (m,) bool."""
        raise NotImplementedError

    def _fallback(self, observation: Observation, reason: str) -> Command:
        """The held law's command this period, noting why; the plan restarts from it."""
        cmd = super()._fallback(observation, reason)
        if cmd.reason is None and cmd.forces is not None:
            self._f_prev = np.asarray(cmd.forces, dtype=float).copy()
            self._U = np.tile(self._f_prev, self.horizon)
        return cmd

    def _refuse(self, problem: str) -> Command:
        return Command.refuse(f"{self.name}: {problem}", actuation=Actuation.FORCE)

    # ----------------------------------------------------------------- diagnostics
    def prediction(self, plan: np.ndarray | None = None) -> dict[str, Any]:
        """The kernel's prediction from the last step's state along ``plan`` (6 N,) [N]
        (default: the plan applied at the last step): the states (N, 18), the features
        with the observed offset (N, m), leg lengths (N, 6) [m] and leg rates (N, 6)
        [m/s] at the ends of the periods ``1..N`` (the kernel output's blocks), and the
        cost.

        Raises:
            ContextError: No step solved yet.
        """
        if self._bound is None or self.plan is None:
            raise ContextError(self.name, "prediction", "no step solved yet")
        bound = self._bound
        saved = bound.x.copy()
        bound.inputs["U"][:] = self.plan if plan is None else plan
        if bound.call():
            raise ContextError(self.name, "prediction", "the compiled kernel failed")
        y = self._kernel.outputs.views(bound.y.copy())
        bound.x[:] = saved
        return {**{key: y[key] for key in ("states", "features", "lengths", "rates")},
                "cost": float(y["cost"][0])}

