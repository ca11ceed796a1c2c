"""Visual predictive controllers ``leg-edge-mpc`` and ``leg-direction-mpc``.

Each step: the tasks of the one-step QP law of the same features (:mod:`controllers.qp`,
held as the fallback), the platform pose for the global model, the problem of
:mod:`controllers.mpc.problem` solved by :func:`controllers.mpc.solver.run_sqp` from the
previous solution shifted by one period; apply the first move ``q_dot = J_inv tau_0``.

A QP that DAQP does not solve, an SQP that does not converge within ``max_iter``
iterations (``max_iter = 0`` never solves), a solve over ``time_limit``, or a non-finite
or out-of-bounds first move makes the step fall back to the QP law, saying so in
``notes`` and ``active_constraints`` (``"mpc fallback: <reason>"``; counted in
:attr:`MPCLaw.stats`). Observations with NaN are refused with the reason.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from controllers.base import Command, ControllerContext, Goal, Observation
from controllers.exceptions import ContextError, OptionError, named_as
from controllers.law_tools import check_choice, check_count, check_flag, check_number
from controllers.mpc.drive_state import DRIVE_STATES, DriveLag, drive_lag
from controllers.mpc.prediction import fit_pose
from controllers.mpc.problem import ProblemSpec, problem_kernel
from controllers.mpc.solver import (
    SCREENED_VISIBILITY_ROWS,
    PredictiveLaw,
    QPArrays,
    QPResult,
    compiled_qp,
    run_sqp,
)
from controllers.qp import LegDirectionQPController, LegEdgeQPController
from controllers.solvers.limit_qp import velocity_bounds
from controllers.tasks.feature_kind import BuiltinFeature
from controllers.tasks.leg_edge import EDGE_NORMALS
from hexapod.compiled import CompilationError, CompiledFunction

log = logging.getLogger(__name__)


class MPCLaw(PredictiveLaw):
    """Base of the predictive controllers (see the module docstring for the options).

    Args:
        horizon: Number of periods ``N`` predicted (>= 1).
        model: ``"local"`` (interaction matrix, linear propagation) or ``"global"``
            (pose reconstruction, SE(3) integration, camera model).
        gain: Gain ``lambda`` [1/s] of the reference trajectory ``(1 - lambda dt)^k e_0``.
        adaptive_gain: ``(lambda0, lambda_inf, lambda0')`` (overrides ``gain``).
        interaction: Interaction matrix of the local model: ``"current"``, ``"desired"``
            or ``"mean"``.
        reference: ``"exponential"`` or ``"zero"`` (regulate the error to zero).
        error_weight: Weight of the error of the stages 1..N-1.
        terminal_weight: Weight of the error of stage N.
        effort_weight: Weight of the leg velocities ``|J_inv tau_k|^2`` [s^2/m^2].
        stroke_margin: Distance kept from the stroke limits [m] (default: the context's).
        max_speed: Leg speed limit [m/s] (default: the geometry's).
        visibility: Keep every predicted edge inside the image (perspective camera).
        visibility_margin: Margin of the visibility constraint [px].
        max_tilt_deg: Bound on the platform tilt w.r.t. the base [deg], or None.
        max_iter: SQP iteration limit (0: never solves, every step falls back).
        accept_unconverged: Apply the last iterate when the SQP stops at ``max_iter``
            with every QP solved (real-time iteration: the iterations continue over the
            next periods from the shifted warm start); False: fall back instead.
        tolerance: SQP convergence on the first move:
            ``|delta tau_0|_inf <= tolerance * max(|tau_0|_inf, 1e-3)`` [m/s, rad/s].
        time_limit: Solve time after which the step falls back [s], or None.
        regularization: Weight of a Tikhonov term ``|tau_k|^2`` on the twists, in the cost
            and its QP (the Hessian's diagonal and the gradient).
        threshold: Singular-value threshold of the fallback law.
        compiled: Generate the QP-data kernel and DAQP to C (built once per problem
            structure, cached on disk); False: CasADi virtual machine and
            ``casadi.conic`` (same results, several times slower per step).
        drive_model: ``"ideal"`` (the predicted leg velocities are the setpoints) or
            ``"lag"``: each leg's velocity follows its setpoint as a first-order lag at
            the NOMINAL drives' ``velocity_bandwidth`` (velocity-mode drives on the
            dynamic world or a real robot; ``docs/math.md`` section 6).
        drive_state: Where the lag model starts: ``"measured"`` (the default),
            ``"encoders"`` or ``"model"`` (an ablation: :mod:`controllers.mpc.drive_state`,
            ``docs/results.md``, "Slow velocity drives").
        law_options: Further options of the fallback QP law (``edge_feature`` for the
            leg-edge law's; a plugin feature's QP law takes none).
    """

    #: The one-step QP law of the same features (fallback).
    law_class: type[Any] = LegEdgeQPController
    unit = "features"

    def __init__(self, horizon: int = 10, model: str = "local", gain: float = 1.0,
                 adaptive_gain: Sequence[float] | None = None, interaction: str = "current",
                 reference: str = "exponential", error_weight: float = 1.0,
                 terminal_weight: float = 1.0, effort_weight: float = 1e-4,
                 stroke_margin: float | None = None, max_speed: float | None = None,
                 visibility: bool = False, visibility_margin: float = 5.0,
                 max_tilt_deg: float | None = None, max_iter: int = 5,
                 tolerance: float = 1e-3, accept_unconverged: bool = True,
                 time_limit: float | None = None,
                 regularization: float = 1e-10, threshold: float = 1e-6,
                 compiled: bool = True, drive_model: str = "ideal",
                 drive_state: str = "measured", **law_options: Any) -> None:
        name = self.name
        if law_options.get("leg_rate_feedforward"):
            raise OptionError(name, "leg_rate_feedforward", "the one-step laws' option; the "
                              "predictive controllers model the drives with drive_model = "
                              "\"lag\" (from the measured leg velocities)")
        self.regularization, self.effort_weight = self._check_options(
            horizon, error_weight, terminal_weight,
            (("regularization", regularization), ("effort_weight", effort_weight)), compiled)
        self.model = check_choice(name, "model", model, ("local", "global"))
        self.reference = check_choice(name, "reference", reference, ("exponential", "zero"))
        self.drive_model = check_choice(name, "drive_model", drive_model, ("ideal", "lag"))
        self.drive_state = check_choice(name, "drive_state", drive_state, DRIVE_STATES)
        self.visibility = check_flag(name, "visibility", visibility)
        self.visibility_margin = check_number(name, "visibility_margin", visibility_margin,
                                              0.0, strict=False)
        self.max_tilt = (None if max_tilt_deg is None else math.radians(
            check_number(name, "max_tilt_deg", max_tilt_deg)))
        if self.max_tilt is not None and self.max_tilt >= math.pi / 2:
            raise OptionError(name, "max_tilt_deg", f"must be < 90, got {max_tilt_deg}")
        self.max_iter = check_count(name, "max_iter", max_iter, 0)
        self.accept_unconverged = check_flag(name, "accept_unconverged", accept_unconverged)
        self.tolerance = check_number(name, "tolerance", tolerance)
        self.time_limit = (None if time_limit is None else
                           check_number(name, "time_limit", time_limit))
        #: The one-step QP law of the same features: it builds the tasks of each period
        #: (:meth:`~controllers.laws.VisionLaw.tasks`), holds the estimate and the
        #: limits, and is the fallback.
        with named_as(name):
            self.law: Any = self.law_class(gain=gain, adaptive_gain=adaptive_gain,
                                             interaction=interaction, threshold=threshold,
                                             stroke_margin=stroke_margin,
                                             max_speed=max_speed, compiled=self.compiled,
                                             **law_options)
        self.features = self.law.features
        self._spec: ProblemSpec | None = None
        #: The drives' state of the lag model (None with the ideal prediction).
        self.drives: DriveLag | None = None

    # ----------------------------------------------------------------- reset
    def reset_trial(self, context: ControllerContext) -> None:
        """Reset the fallback law (limits, goal), build or load the compiled problem.

        Raises:
            ContextError: A field the controller needs is missing or invalid.
            OptionError: An option does not fit the context (e.g. no stroke left).
        """
        law = self.law
        with named_as(self.name):
            law.reset(context)  # (a batch of one: its step is the batch's)
        self.features = law.features
        self.context = context
        #: The feature the problem predicts: the fallback law's (a plugin feature's law
        #: reads leg directions: its local problem is the leg directions' one).
        self._feature: BuiltinFeature = law.observed_feature
        cam: Any = context.camera
        visibility = self.visibility and getattr(cam, "kind", None) == "perspective"
        if self.visibility and not visibility:
            log.info("%s: visibility constraint ignored (needs a perspective camera)", self.name)
        self._spec = ProblemSpec(self._feature, self.model, self.horizon, self.max_tilt is not None,
                                 visibility, self.drive_model == "lag")
        self._kernel: CompiledFunction = problem_kernel(self._spec, self.compiled)
        if self.compiled:  # DAQP of this size built now (and of the screened QP: solve_qp)
            if self._spec.visibility:
                compiled_qp(6 * self.horizon, self._spec.rows - self.horizon * 48
                            + SCREENED_VISIBILITY_ROWS)
            compiled_qp(6 * self.horizon, self._spec.rows)
        self._lay = self._spec.input_layout()
        self._out = self._spec.output_layout()
        self._rows = self._spec.row_names()
        self._vec = np.zeros(self._lay.size)
        sl = self._lay.slices
        geo = context.geometry
        A = law.base_points
        window = law.solver.window
        self._vec[sl["dt"]] = window.dt
        self._vec[sl["A"]] = A.reshape(-1)
        self._vec[sl["E"]] = np.asarray(geo.platform_points, dtype=float).reshape(-1)
        self._vec[sl["r"]] = geo.leg_radius
        self._vec[sl["reg"]] = self.regularization
        self._vec[sl["effort"]] = self.effort_weight
        self._vec[sl["qlo"]] = window.lower
        self._vec[sl["qhi"]] = window.upper
        self._vec[sl["vmax"]] = window.max_speed
        w = np.full(self.horizon, self.error_weight)
        w[-1] = self.terminal_weight
        self._vec[sl["w"]] = w
        if "Kit" in self._lay:
            Kit = self._feature.line_inv_t(getattr(law, "line_matrix", None))
            self._vec[sl["Kit"]] = Kit.reshape(-1)
        if self._spec.tilt:
            R_cb, _ = fit_pose(A, geo.base_points)  # base orientation seen from the estimates
            self._vec[sl["zb"]] = R_cb[:, 2]
            self._vec[sl["cosmax"]] = math.cos(float(self.max_tilt or 0.0))
        if visibility:
            K = np.asarray(cam.K, dtype=float)
            m = self.visibility_margin
            self._vec[sl["K"]] = K.reshape(-1)
            self._vec[sl["box"]] = (-0.5 + m, cam.width - 0.5 - m, -0.5 + m,
                                    cam.height - 0.5 - m)
        self.drives = None
        if self._spec.drives:
            a, c = drive_lag(context, window.dt, self.name)
            self.drives = DriveLag(a, c, window.dt, self.drive_state)
            self._vec[sl["alag"]], self._vec[sl["clag"]] = a, c
        self._offset = np.zeros(6)
        self._star = law.desired_features()
        self._restart()

    def retarget_trial(self, goal: Goal) -> None:
        """A new goal (:meth:`~controllers.laws.VisionLaw.retarget` of the fallback
        law, whose desired features the problem takes); the warm start and the drives'
        state stay.

        Raises:
            ContextError: No reset yet, or an invalid goal (the previous one kept).
        """
        if self.context is None:
            raise ContextError(self.name, "context", "retarget(goal) before reset(context)")
        with named_as(self.name):
            self.law.retarget(goal)
        self.context = self.law.context
        self._star = self.law.desired_features()

    # ----------------------------------------------------------------- step
    def step_trial(self, observation: Observation) -> Command:
        """One receding-horizon step (never raises for bad measurements)."""
        if self.context is None:
            return Command.refuse(f"{self.name}: reset(context) was not called")
        offset, self._offset = self._offset, np.zeros(6)
        cmd = self._step(observation, offset)
        if self.drives is not None:
            self.drives.sent(self._v0 + offset, observation.lengths, cmd.velocities + offset)
        return cmd

    def velocity_offset(self, q_dot: np.ndarray) -> None:
        """The leg velocities [m/s] a wrapper adds to the coming step's command (a
        trajectory task's feed-forward, :mod:`controllers.tracking`; cleared after the
        step). With ``drive_model = "lag"`` the prediction runs on the leg velocities
        RELATIVE to it (exact for a feed-forward constant over the horizon)."""
        self._offset = np.asarray(q_dot, dtype=float).reshape(6)

    def _step(self, observation: Observation, offset: np.ndarray) -> Command:
        law = self.law
        if self.drives is not None:
            self._v0 = self.drives.now(observation.lengths, observation.q_dot) - offset
        q = law.checked_lengths(observation)
        if isinstance(q, Command):
            self._U[:] = 0.0  # nothing moves: the next warm start is rest
            return q
        ts = law.tasks(observation, q)
        if isinstance(ts, Command):
            assert ts.reason is not None
            return self._fallback(observation, ts.reason)
        e, N, b, J, notes = ts.error, ts.normal, ts.gradient, ts.inverse_jacobian, ts.notes
        w, _ = np.linalg.eigh(N)
        rank = int(np.count_nonzero(w > (law.threshold ** 2) * max(w[-1], 0.0)))
        if rank < 6:  # the law refuses (it moved along the seen directions, or not at all)
            return self._fallback(observation, f"interaction matrix rank {rank} < 6")
        t_start = time.perf_counter()
        solved = self._solve(observation, q, e, N, b, J)
        if isinstance(solved, str):
            return self._fallback(observation, solved)
        tau, qdot, active, status = solved
        if self.time_limit is not None and time.perf_counter() - t_start > self.time_limit:
            return self._fallback(observation, f"time limit {self.time_limit} s exceeded "
                                               f"({status})")
        cond = math.sqrt(w[-1] / w[0]) if w[0] > 0 else math.inf
        law.estimate.commanded(tau, q)
        notes = [*notes, f"mpc {self.model} N={self.horizon}: {status}"]
        return Command(qdot, twist=tau, error=e, error_norm=float(np.sqrt(e @ e)), rank=rank,
                       condition=cond, features_used=e.shape[0], notes=notes,
                       active_constraints=active)

    def _solve(self, obs: Observation, q: np.ndarray, e: np.ndarray, N: np.ndarray,
               b: np.ndarray, J: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, list[str], str] | str:
        """Fill the kernel input, run the SQP iterations, check the first move."""
        law = self.law
        spec = self._spec
        assert spec is not None
        sl = self._lay.slices
        vec = self._vec
        window = law.solver.window
        dt = window.dt
        lam = law.gain(float(np.abs(e).max()) if e.size else 0.0)
        if self.reference == "exponential":
            ratio = max(0.0, 1.0 - lam * dt)
            vec[sl["ref"]] = ratio ** np.arange(1, self.horizon + 1)
        else:
            vec[sl["ref"]] = 0.0
        vec[sl["J0"]] = J.reshape(-1)
        vec[sl["q0"]] = q
        if spec.drives:
            try:
                J0i = np.linalg.inv(J)
            except np.linalg.LinAlgError:
                return "singular inverse Jacobian: cannot map the drives' lag to twists"
            vec[sl["J0i"]] = J0i.reshape(-1)
            vec[sl["v0"]] = self._v0
        vmax = window.max_speed
        _, _, lo1, hi1 = velocity_bounds(q, window.lower, window.upper, vmax, 1.0 / dt)
        vec[sl["lo1"]] = lo1
        vec[sl["hi1"]] = hi1
        fitted = self._fit(q)
        if isinstance(fitted, str):
            return fitted
        R0, t0 = fitted
        vec[sl["R0"]] = R0.reshape(-1)
        vec[sl["t0"]] = t0
        if spec.model == "global":
            feats, use = law.measured_features(obs)
            star = self._star
            feats = np.where(use[:, None], feats, star)
            model_f, model_q = self._model_features(R0, t0)
            vec[sl["star"]] = star.reshape(-1)
            vec[sl["offset"]] = np.where(use[:, None], feats - model_f, 0.0).reshape(-1)
            vec[sl["wf"]] = use
            vec[sl["e0"]] = np.where(use[:, None], np.cross(feats, star), 0.0).reshape(-1)
            vec[sl["qoff"]] = q - model_q
        else:
            vec[sl["N"]] = N.reshape(-1)
            vec[sl["b"]] = b
            vec[sl["e0sq"]] = float(e @ e)
        U, converged, status, last, it = run_sqp(
            self._evaluate, self._qp_data, self._U.copy(), self.max_iter, self.tolerance,
            self.compiled, spec=spec, merit_rows=self._out.slices, one_qp=spec.model == "local",
            time_limit=self.time_limit)
        self.stats.steps += 1
        self.stats.total_sqp_iterations += it
        if U is None or last is None or not (converged or self.accept_unconverged):
            return status
        tau = U[:6].copy()
        qdot = J @ tau
        tol = 1e-6 * vmax
        if not np.all(np.isfinite(qdot)):
            return "non-finite first move"
        if (qdot < lo1 - tol).any() or (qdot > hi1 + tol).any():
            return "first move outside the stroke/speed window"
        if not converged:  # (an iterate applied: a fallback is counted as one)
            self.stats.unconverged += 1
        qdot = np.minimum(np.maximum(qdot, lo1), hi1)
        self._U = self._shift(U)
        return tau, qdot, self._active(last), status

    def _evaluate(self, U: np.ndarray) -> np.ndarray | str:
        """The kernel's output at ``U`` (the rest of its input filled), or why not."""
        self._vec[self._lay.slices["U"]] = U
        try:
            return self._kernel.single(self._vec)
        except (CompilationError, RuntimeError) as exc:
            return f"QP data kernel failed: {exc}"

    def _qp_data(self, out: np.ndarray, U: np.ndarray) -> QPArrays:
        """``(H, g, C, lba, uba)`` of a kernel output (the bounds relative to ``U``)."""
        o = self._out.slices
        n, m = 6 * self.horizon, len(self._rows)
        return (out[o["H"]].reshape(n, n), out[o["g"]], out[o["C"]].reshape(m, n),
                out[o["lba"]], out[o["uba"]])

    def _active(self, res: QPResult) -> list[str]:
        """Names of the rows at a bound with a non-zero multiplier (first few)."""
        lam = res.multipliers
        if lam is None:
            return []
        idx = np.flatnonzero(np.abs(lam) > 1e-12)
        names = [self._rows[i] for i in idx[:8]]
        if len(idx) > 8:
            names.append(f"... {len(idx) - 8} more")
        return names

    def _fit(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray] | str:
        """Platform pose in the camera frame from ``B_i = A_i + q_i u_i`` (legs whose
        direction is known this step; at least three)."""
        law = self.law
        u = law.estimate.in_use
        known = np.isfinite(u[:, 0]) & law.estimate.observed
        if known.sum() < 3:
            known = np.isfinite(u[:, 0])
        if known.sum() < 3:
            return "fewer than three leg directions known: cannot reconstruct the pose"
        assert self.context is not None
        A = law.base_points
        B = np.where(known[:, None], A + q[:, None] * np.where(known[:, None], u, 0.0), 0.0)
        R, t = fit_pose(B, self.context.geometry.platform_points, known.astype(float))
        if not (np.all(np.isfinite(R)) and np.all(np.isfinite(t))):
            return "pose reconstruction failed (non-finite)"
        return R, t

    def _model_features(self, R: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Features (nf, 3) and lengths (6,) of the model at the fitted pose."""
        law = self.law
        assert self.context is not None
        geo = self.context.geometry
        A = law.base_points
        d = geo.platform_points @ R.T + t - A
        qm = np.sqrt(np.einsum("ij,ij->i", d, d))
        u = d / qm[:, None]
        return (self._feature.model_features(A, u, geo.leg_radius,
                                             getattr(law, "line_matrix", None)), qm)

    def _fallback(self, obs: Observation, reason: str) -> Command:
        """The QP law's command, carrying the reason (in its active constraints too)."""
        self._U[:] = 0.0
        cmd = super()._fallback(obs, reason)
        cmd.active_constraints = [*cmd.active_constraints, cmd.notes[-1]]
        return cmd


class LegEdgeMPCController(MPCLaw):
    """Visual predictive control on leg edges (lines or normals), local or global model.

    Takes the options of :class:`MPCLaw` and ``edge_feature`` (``"auto"``, ``"lines"``,
    ``"normals"``) of :class:`~controllers.leg_edge.LegEdgeController`.
    """

    name = "leg-edge-mpc"
    features = frozenset({"lengths", EDGE_NORMALS.field})  # the law's, at reset
    law_class = LegEdgeQPController
    unit = "edges"


class LegDirectionMPCController(MPCLaw):
    """Visual predictive control on leg directions, local or global model.

    Takes the options of :class:`MPCLaw`.
    """

    name = "leg-direction-mpc"
    features = frozenset({"lengths", "directions"})
    law_class = LegDirectionQPController
    unit = "legs"

