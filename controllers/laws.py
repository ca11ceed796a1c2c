"""The image-based laws' per-trial side (``docs/math.md`` section 6): a feature gives an
error and an interaction matrix; :class:`VisionLaw` combines them for every feature
(gain, solver, hidden features, diagnostics): ``tau = -lambda L^+ e``, ``q_dot = J_inv
tau``. The law's one step is its batch's (:class:`~controllers.law_steps.
VisionLawBatch`, C around the compiled core :mod:`controllers.law_kernel` in
:mod:`controllers.law_rows`); an instance steps the rows that C leaves to Python
(:meth:`VisionLaw.rare_step`: after :meth:`VisionLaw._select` when a feature is hidden
now or in the goal, or a refusal; :meth:`VisionLaw.rejected_step`). The tests' numpy
oracle is ``tests/controllers/numpy_law.py``.
"""

from __future__ import annotations

import math
from abc import abstractmethod
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from controllers.base import Command, ControllerContext, Goal, Observation
from controllers.estimators import LegDirectionEstimate, PoseEstimate
from controllers.exceptions import ContextError, OptionError
from controllers.law_kernel import Feature, LawKernel, LawResult, feature_law_kernel
from controllers.law_steps import ObservedFeature, VisionLawBatch
from controllers.law_tools import (
    INTERACTIONS,
    Gain,
    Selection,
    TaskStep,
    base_points_of,
    check_choice,
    check_flag,
    check_number,
    check_observation,
    goal_lengths,
)
from controllers.model_directions import ModelDirections
from controllers.plausible import implausible_lengths, stroke_of
from controllers.solvers.base import Solver
from controllers.solvers.pseudo_inverse import DampedPseudoInverse
from controllers.tasks.feature_kind import BuiltinFeature


class VisionLaw(VisionLawBatch):
    """Base of the image-based laws: ``tau = -lambda L^+ e``, ``q_dot = J_inv tau``.

    Subclasses set :attr:`observed_feature` and implement :meth:`_reset_features` (read
    the goal, then :meth:`_install_kernel`) and :meth:`_select` (the used features and the
    leg directions when a feature is hidden). The solver (:attr:`solver`, the damped
    pseudo-inverse by default) turns the tasks into a twist: the QP laws set the limit QP.

    Args:
        gain: Constant gain ``lambda`` [1/s].
        adaptive_gain: ``(lambda0, lambda_inf, lambda0')`` (overrides ``gain``).
        interaction: ``"current"``, ``"desired"`` or ``"mean"``.
        threshold: Relative singular-value threshold: below ``threshold * s_max`` a
            singular value counts as zero, and a stacked interaction matrix of rank
            < 6 makes the law refuse to move.
        damping: Damping ``mu`` of the pseudo-inverse ``(L^T L + mu^2 I)^-1 L^T``.
        compiled: Evaluate the core (:mod:`controllers.law_kernel`) compiled to C (False:
            the CasADi virtual machine evaluates the same expression, slower).
        leg_rate_feedforward: Feed the measured leg velocities forward through the nominal
            drives' lag (:mod:`controllers.leg_rate`): the setpoint ``u = q_dot +
            kappa (q_dot - v)`` that moves each leg by ``dt q_dot`` over the period
            (velocity-mode drives; default off: the law's command as it is).
    """

    #: What a feature block is called in the notes ("legs", "edges").
    unit = "features"
    #: What the law reads from an observation (its field, visibility mask and shape).
    observed_feature: ObservedFeature
    #: The features visible in the goal (set by :meth:`_reset_features`).
    _goal_visible: np.ndarray

    def __init__(self, gain: float = 1.0, adaptive_gain: Sequence[float] | None = None,
                 interaction: str = "current", threshold: float = 1e-6,
                 damping: float = 0.0, compiled: bool = True,
                 leg_rate_feedforward: bool = False) -> None:
        self.gain = Gain.from_options(self.name, gain, adaptive_gain)
        self.init_leg_rate(leg_rate_feedforward)
        self.interaction = check_choice(self.name, "interaction", interaction, INTERACTIONS)
        self.threshold = check_number(self.name, "threshold", threshold, 0.0, strict=False)
        if self.threshold >= 1.0:
            raise OptionError(self.name, "threshold", f"must be < 1, got {self.threshold}")
        self.damping = check_number(self.name, "damping", damping, 0.0, strict=False)
        self.compiled = check_flag(self.name, "compiled", compiled)
        #: What turns the tasks into a twist (the QP laws put the limit QP here).
        self.solver: Solver = DampedPseudoInverse(self.threshold, self.damping)
        self.context: ControllerContext | None = None
        #: (6, 3) the estimated base points ``A_i`` in the camera frame [m] (after reset).
        self.base_points = np.zeros((6, 3))
        #: Control period [s] (after reset).
        self.dt = 0.0
        #: The leg directions known between periods (a row of the batch's estimate when
        #: stepped in a batch).
        self.estimate = LegDirectionEstimate.fresh()
        #: Last nominal-model pose (warm start of the forward kinematics that predicts
        #: the directions of never-seen legs), None before the first.
        self.model_pose: PoseEstimate | None = None
        #: This period's row of a batch's :class:`ModelDirections` (set by the batch step
        #: for the rows it leaves to this law, taken by :meth:`_model_directions`).
        self.model_ahead: tuple[ModelDirections, int] | None = None
        #: The compiled core (:mod:`controllers.law_kernel`), set by :meth:`_install_kernel`.
        self.kernel: LawKernel | None = None
        self._spare_kernel: LawKernel | None = None
        #: The kernel's weights and ``measured`` inputs were set by :meth:`_select`
        #: (restored to ones by :meth:`_load_kernel`).
        self._kernel_selected = False
        #: Views of the compiled core's inputs (:meth:`_configure_kernel`).
        self._k_lengths: np.ndarray
        self._k_desired_lengths: np.ndarray | None

    def __getstate__(self) -> dict[str, object]:
        """A copy's state (:meth:`VisionLawBatch.__getstate__`), without the views of
        the compiled core's inputs, taken again of the copy's core (:meth:`__setstate__`).
        """
        state = super().__getstate__()
        for key in ("_k_features", "_k_lengths", "_k_desired_lengths"):
            state.pop(key, None)
        state["model_ahead"] = None
        return state

    def __setstate__(self, state: dict[str, object]) -> None:
        self.__dict__.update(state)
        kernel = self.kernel
        if kernel is not None:  # (the views _configure_kernel takes)
            self._k_features = kernel.inputs["features"].reshape(self.observed_feature.shape)
            self._k_lengths = kernel.inputs["lengths"]
            self._k_desired_lengths = (kernel.inputs["desired_lengths"]
                                       if self.desired_lengths_measured else None)

    # ----------------------------------------------------------------- reset
    def reset_trial(self, context: ControllerContext) -> None:
        """Read the estimated base points, the period and the goal.

        Raises:
            ContextError: A field the law needs is missing or invalid.
        """
        A = base_points_of(self.name, context)
        dt = float(context.dt)
        if not (math.isfinite(dt) and dt > 0):
            raise ContextError(self.name, "dt", f"must be positive and finite, got {dt}")
        self.context = context
        self.base_points = A.copy()
        self.dt = dt
        self.estimate = LegDirectionEstimate.fresh()
        self.model_pose = None
        self._q_star: np.ndarray | None = (None if context.goal.lengths is None
                                           else goal_lengths(self.name, context.goal,
                                                        context.geometry.stroke))
        self.kernel = None
        self._spare_kernel = None
        self._kernel_selected = False
        self._reset_features(context)
        self.solver.reset(context, self.name, dt)
        self._configure_kernel()
        self.reset_leg_rate(context, dt)

    def retarget_trial(self, goal: Goal) -> None:
        """A new goal (a trajectory task's, :mod:`controllers.tracking`): the desired
        features and lengths as :meth:`reset_trial` sets them; the estimate, the forward
        kinematics' warm start, the solver's state and the compiled core stay.

        Raises:
            ContextError: :meth:`reset_trial` was not called, or the goal is invalid (as in
                :meth:`reset_trial`; the law then keeps its previous goal).
        """
        if self.context is None:
            raise ContextError(self.name, "context", "retarget(goal) before reset(context)")
        context = replace(self.context, goal=goal)
        q_star = None if goal.lengths is None else goal_lengths(
            self.name, goal, None if self.context is None else self.context.geometry.stroke)
        state = dict(vars(self))  # what _retarget_features may change
        self._q_star = q_star
        self._unselect_kernel()  # a reused core starts from the common case's inputs
        self._spare_kernel, self.kernel = self.kernel, None
        try:
            self._retarget_features(context)
        except ContextError:
            vars(self).clear()
            vars(self).update(state)
            raise
        finally:
            self._spare_kernel = None
        self.context = context
        self._configure_kernel()

    def _configure_kernel(self) -> None:
        """Write the goal lengths (DESIRED/MEAN cores), the gain, threshold and damping into
        the compiled core, and keep views of its lengths inputs."""
        kernel = self.kernel
        if kernel is None:
            raise TypeError(f"{self.name}: _reset_features must set the compiled core "
                            "(self._install_kernel)")
        g = self.gain
        self._k_lengths = kernel.inputs["lengths"]
        self._k_desired_lengths = None
        if "desired_lengths" in kernel.inputs:
            if self._q_star is not None:
                kernel.set("desired_lengths", self._q_star)
            else:
                self._k_desired_lengths = kernel.inputs["desired_lengths"]
        kernel.set("gain", (g.at_zero, g.at_infinity, g.slope_at_zero))
        kernel.set("threshold2", self.threshold * self.threshold)
        kernel.set("damping2", self.solver.damping2)

    def _install_kernel(self, feature: Feature, **goal: Any) -> None:
        """Set the compiled core of ``feature`` (the one kept by :meth:`retarget_trial`, else
        a new one) with the goal's inputs: ``goal`` (those the core has), the base points
        and the weights ``self._goal_visible`` (the goal's visible features)."""
        kernel, self._spare_kernel = self._spare_kernel, None
        if kernel is None:
            kernel = feature_law_kernel(feature, self.interaction, self.compiled)
        for name, value in goal.items():
            if name in kernel.inputs:
                kernel.set(name, value)
        kernel.set("base_points", self.base_points)
        kernel.set("weights", self._goal_visible)
        self.kernel = kernel
        #: Task rows of one feature block (a built-in's unit vector, a plugin leg's rows).
        self.unit_rows = (feature.task_rows // feature.units
                          if isinstance(feature, BuiltinFeature) else feature.rows)
        self._k_features = kernel.inputs["features"].reshape(self.observed_feature.shape)
        #: Every feature is visible in the goal (the batch's C may step the trial).
        self.goal_all_visible = bool(self._goal_visible.all())

    def _retarget_features(self, context: ControllerContext) -> None:
        """Read the desired features of a new goal (:meth:`retarget_trial`); subclasses skip
        what does not depend on the goal."""
        self._reset_features(context)

    def desired_features(self) -> np.ndarray:
        """(nf, 3) the desired features, one row per feature (zeros where unknown)."""
        raise NotImplementedError

    def measured_features(self, obs: Observation) -> tuple[np.ndarray, np.ndarray]:
        """(nf, 3) the measured features of an observation and (nf,) which are usable
        (observed now and in the goal)."""
        seen = self.observed_feature
        vis = np.asarray(getattr(obs, seen.visibility), dtype=bool) & self._goal_visible
        return (np.asarray(getattr(obs, seen.field), dtype=float).reshape(seen.units, 3),
                vis.reshape(seen.units))

    @abstractmethod
    def _reset_features(self, context: ControllerContext) -> None:
        """Read and validate the desired features, then :meth:`_install_kernel`."""

    def _select(self, obs: Observation, q: np.ndarray) -> Selection:
        """The used features and the leg directions when a feature is hidden (the
        compiled core computes the rest).

        Must also update ``self.estimate``: dead-reckon the hidden legs with the last
        twist, write the legs observed this step and the directions ``J_inv`` uses
        (``in_use``: dead-reckoned, approximated from the goal for legs never seen, NaN
        when unknown), except those of the legs it marks ``measured`` (the core's).
        """
        raise NotImplementedError

    # ----------------------------------------------------------------- step
    def checked_lengths(self, observation: Observation) -> np.ndarray | Command:
        """The measured lengths (6,) [m], or the refusal of an unusable observation (then
        nothing is commanded this period: the estimate's twist is zeroed)."""
        problem = check_observation(observation, self.features)
        if problem is not None:
            self.estimate.halted()  # no motion commanded
            return Command.refuse(problem)
        q = np.asarray(observation.lengths, dtype=float)
        if q.min() <= 0:
            self.estimate.halted()
            leg = int(np.argmin(q))
            return Command.refuse(f"lengths: leg {leg} at {float(q[leg]):.6g} m, not a "
                                  "positive length")
        stroke = stroke_of(self.context)
        if stroke is not None and (wrong := implausible_lengths(q, stroke)) is not None:
            self.estimate.halted()
            return Command.refuse(f"lengths: {wrong}")
        return q

    def tasks(self, observation: Observation, q: np.ndarray) -> TaskStep | Command:
        """This period's tasks for a solver (the part of a step every solver shares), or
        the refusal of why none can be built: the compiled core after :meth:`_select`
        (the rows the batch's C leaves to Python with a hidden feature), or directly when
        every feature is visible now and in the goal (:meth:`_load_kernel`: the
        predictive controllers' tasks, and a trial whose core is not its batch's); the
        estimate updated (nothing commanded yet); the nominal model's directions for legs
        never seen (:meth:`_model_directions`).

        Args:
            observation: The observation.
            q: Its lengths from :meth:`checked_lengths` [m].
        """
        est = self.estimate
        kernel = self.kernel
        assert kernel is not None, "reset() sets the compiled core"
        common = self._load_kernel(observation, q)
        if common:
            r = kernel.evaluate()
            est.halted()  # until a command is actually sent
            est.measured_all(r.directions)
            e, notes = r.error, []
        else:
            sel = self._select(observation, q)  # dead-reckons hidden legs with the last twist
            est.halted()  # until a command is actually sent
            inputs = kernel.inputs
            inputs["features"][:] = sel.features.reshape(-1)
            inputs["lengths"][:] = q
            inputs["weights"][:] = sel.used
            inputs["measured"][:] = sel.measured
            # legs never seen: the nominal model's directions, before the core (which
            # uses a leg's given direction only in the inverse Jacobian)
            legs = sel.leg_directions
            never = ~np.isfinite(legs[:, 0]) & ~sel.measured
            model = self._model_directions(q) if never.any() else None
            if model is not None:
                legs = np.where(never[:, None], model, legs)
                est.in_use[never] = model[never]
            inputs["leg_directions"][:] = legs.reshape(-1)
            if "desired_lengths" in inputs:
                inputs["desired_lengths"][:] = self._desired_lengths(q)
            self._kernel_selected = True
            r = kernel.evaluate()
            m = sel.measured
            est.directions[m] = r.directions[m]
            est.in_use[m] = r.directions[m]
            e, notes = r.error.reshape(len(sel.used), -1)[sel.used].reshape(-1), sel.notes
        if not (math.isfinite(r.error_norm) and math.isfinite(r.n_sum)):
            return Command.refuse("non-finite error or interaction matrix (degenerate features)",
                                  e)
        if common:
            return TaskStep(e, r.error_norm, r.N, r.b, r.gain, r.J, notes, r)
        if len(unknown := np.flatnonzero(~np.isfinite(est.in_use[:, 0]))):
            # no model directions, or a leg measured without a direction: the core again
            model = self._model_directions(q) if model is None else model
            if model is None:
                return Command.refuse(
                    f"direction of leg {int(unknown[0])} unknown (hidden since reset, no "
                    "desired direction, no nominal model prediction): cannot build the "
                    "inverse Jacobian", e)
            est.in_use[unknown] = model[unknown]
            kernel.inputs["leg_directions"][:] = est.in_use.reshape(-1)
            r = kernel.evaluate()
        if model is not None:
            never[unknown] = True
            notes.append("nominal-model directions (forward kinematics of the measured "
                         "lengths) for never-seen legs " + _legs(never))
        return TaskStep(e, r.error_norm, r.N, r.b, r.gain, r.J, notes, r)

    def rare_step(self, observation: Observation) -> Command:
        """One period of a row the batch's C left to Python as not its common case (a
        hidden feature, an unusable observation; :mod:`controllers.law_rows`), with the
        measured leg rates fed forward when ``leg_rate_feedforward``
        (:mod:`controllers.leg_rate`); never raises for bad measurements."""
        return self.fed_forward(self._law_step(observation), observation)

    def rejected_step(self, observation: Observation, r: LawResult) -> Command:
        """One period of a row whose compiled core's result ``r`` (the full core's) the
        batch's C did not accept as the command (having written the estimate's measured
        directions and a zero twist): the refusal of a degenerate core, or the solver's
        answer (OSQP where the optimum touches a bound), fed forward as :meth:`rare_step`.
        """
        q = np.asarray(observation.lengths, dtype=float)
        e = r.error
        if not (math.isfinite(r.error_norm) and math.isfinite(r.n_sum)):
            cmd = Command.refuse("non-finite error or interaction matrix (degenerate "
                                 "features)", e)
        else:
            cmd = self._command(self.solver.solve(r.N, r.b, r.gain, q, r.J, r), r.J, e,
                                r.error_norm, e.shape[0], q, [])
        return self.fed_forward(cmd, observation)

    def _law_step(self, observation: Observation) -> Command:
        """The law's command of one period (before the leg-rate feed-forward)."""
        if self.context is None:
            return Command.refuse(f"{self.name}: reset(context) was not called")
        q = self.checked_lengths(observation)
        if isinstance(q, Command):
            return q
        ts = self.tasks(observation, q)
        if isinstance(ts, Command):
            return ts
        J, e = ts.inverse_jacobian, ts.error
        return self._command(self.solver.solve(ts.normal, ts.gradient, ts.gain, q, J,
                                               ts.compiled),
                             J, e, ts.error_norm, e.shape[0], q, ts.notes)

    def _command(self, solved: tuple[np.ndarray, int, float, list[str], str | None,
                                     np.ndarray | None],
                 J: np.ndarray, e: np.ndarray, error_norm: float, rows: int, q: np.ndarray,
                 notes: list[str]) -> Command:
        """The command (or the refusal) from the solver's output."""
        tau, rank, cond, active, reason, qdot = solved
        if reason is not None or rank < 6:
            if reason is None:
                reason = (f"interaction matrix rank {rank} < 6 with {rows // self.unit_rows} "
                          f"{self.unit} (condition {cond:.3g})")
            return Command(np.zeros(6), error=e, error_norm=error_norm, rank=rank,
                           condition=cond, features_used=rows, reason=reason,
                           notes=notes, active_constraints=active)
        if qdot is None:
            qdot = self.solver.finish(J @ tau)
            if not np.all(np.isfinite(qdot)):
                return Command.refuse("non-finite command (numerical failure)", e)
        self.estimate.commanded(tau, q)
        return Command(qdot, twist=tau, error=e, error_norm=error_norm, rank=rank,
                       condition=cond, features_used=rows, notes=notes,
                       active_constraints=active)

    def _load_kernel(self, obs: Observation, q: np.ndarray) -> bool:
        """Write the measured features and lengths into ``self.kernel`` when every
        feature is visible, now and in the goal (the common case: every weight one,
        every leg direction measured); False to take :meth:`_select`."""
        seen = self.observed_feature
        vis = getattr(obs, seen.visibility)
        if not (self.goal_all_visible and (vis.all() if type(vis) is np.ndarray
                                            else np.all(np.asarray(vis, dtype=bool)))):
            return False
        self._k_features[...] = getattr(obs, seen.field)
        self._unselect_kernel()
        self._k_lengths[...] = q
        if self._k_desired_lengths is not None:  # q* unknown: the measured lengths
            self._k_desired_lengths[...] = q
        return True

    def _unselect_kernel(self) -> None:
        """Give the core back the common case's weights and ``measured`` inputs (ones)
        after :meth:`_select` changed them."""
        if self._kernel_selected:
            kernel = self.kernel
            assert kernel is not None
            kernel.inputs["weights"][:] = 1.0
            kernel.inputs["measured"][:] = 1.0
            self._kernel_selected = False

    @property
    def desired_lengths_measured(self) -> bool:
        """Whether the core's ``desired_lengths`` (DESIRED / MEAN interaction) are the
        measured lengths (the goal gives none)."""
        k = self.kernel
        return k is not None and self._q_star is None and "desired_lengths" in k.inputs

    def _model_directions(self, q: np.ndarray) -> np.ndarray | None:
        """Leg directions (6, 3) (camera frame) of the nominal forward kinematics of ``q``
        [m] (warm-started at :attr:`model_pose`) seen through the estimated
        ``camera_from_base``, or None (no camera pose, no solution): ``J_inv`` of legs
        never observed (an approximate direction only slows the convergence). The rows a
        batch step leaves to the trials are solved together (:attr:`model_ahead`,
        :mod:`controllers.model_directions`)."""
        ahead, self.model_ahead = self.model_ahead, None  # (this period's row only)
        if ahead is None or not ahead[0].holds(ahead[1], self, q):
            ahead = (ModelDirections([self], q[None]), 0)  # this row alone
        return ahead[0].take(ahead[1])

    # ----------------------------------------------------------------- helpers
    def _desired_lengths(self, q: np.ndarray) -> np.ndarray:
        """``q*`` for the DESIRED/MEAN interaction: the goal lengths, else the measured ones."""
        return q if self._q_star is None else self._q_star

    def _notes(self, used: np.ndarray, predicted: np.ndarray, approximated: np.ndarray,
               hidden: str = "hidden") -> list[str]:
        """The notes of a step with hidden features: how many are used, and the legs
        (boolean masks) whose direction is predicted or the desired one."""
        notes = [f"using {int(np.count_nonzero(used))} of {used.size} {self.unit}"]
        if predicted.any():
            notes.append(f"predicted directions of {hidden} legs " + _legs(predicted))
        if approximated.any():
            notes.append("desired direction used for never-seen legs " + _legs(approximated))
        return notes


def _legs(legs: np.ndarray) -> str:
    """The legs of a mask or of indices, as ``"1, 4"``."""
    index = np.flatnonzero(legs) if legs.dtype == bool else legs
    return ", ".join(str(int(i)) for i in index)
