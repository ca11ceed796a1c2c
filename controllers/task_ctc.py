"""Computed torque on a task: the shared loop of ``cartesian-ctc``, ``vision-ctc``,
``leg-edge-ctc`` and ``leg-direction-ctc``.

Each period a :class:`TaskComputedTorque` subclass writes its measurement and the
reference (with its rate and acceleration) into the input row of its compiled step
(:meth:`TaskComputedTorque.compiled_inputs`, :mod:`controllers.task_ctc_compiled`), and
one C call gives the pose, the task's error and Jacobian for the NOMINAL model and the
leg forces held over the period. Off its happy path the law refuses with the reason of
the row's status (:mod:`controllers.ctc_status`).

The reference is ``context.reference`` (base frame) or, for a fixed goal, a quintic
line from the pose measured at the first step to the goal pose, slow enough that no
leg's nominal speed exceeds the limit (``smooth_goal``; off: a step). The checked
readings, goal pose, camera and that line are :mod:`controllers.task_ctc_inputs`'.
"""

from __future__ import annotations

from abc import abstractmethod
from dataclasses import replace
from typing import Any

import numpy as np

from controllers.base import (
    Command,
    ControllerContext,
    Goal,
    Observation,
    ObservationBatch,
)
from controllers.control_grid import grid_step, grid_times
from controllers.ctc_law import DAMPING as DAMPING
from controllers.ctc_law import NATURAL_FREQUENCY_HZ as NATURAL_FREQUENCY_HZ
from controllers.ctc_law import ComputedTorqueLaw
from controllers.solvers.saturation import over_limit, zero_acceleration_forces
from controllers.task_ctc_compiled import CompiledTaskStep
from controllers.task_ctc_inputs import encoder_readings as encoder_readings
from controllers.task_ctc_rows import START, STARTED, VERSION, TaskRows
from controllers.tasks.feature_kind import BuiltinFeature
from hexapod.actuation import Actuation
from hexapod.dynamics import DynamicModel


class TaskComputedTorque(ComputedTorqueLaw):
    """Computed torque on a task (see the module docstring; the options are
    :class:`~controllers.ctc_law.ComputedTorqueLaw`'s). Subclasses set ``name``,
    ``features``, ``compiled_kind`` and implement :meth:`goal_pose` and
    :meth:`compiled_inputs`."""

    #: The feature object of the compiled step (:mod:`controllers.solvers.compiled_task_ctc`;
    #: None: the subclass makes its own step at reset).
    compiled_kind: BuiltinFeature | None = None
    #: The compiled step finds the pose from the encoders (else it is given).
    compiled_fk = True
    #: The measurement a step writes itself where all of it is seen and finite, as
    #: :meth:`compiled_inputs` would: ``(observation field, its visibility field, the
    #: input block it goes to, an input block set to ones or None)``; ``()``: nothing
    #: measured (the pose from the encoders); None: every row by :meth:`compiled_inputs`.
    batch_measurement: tuple[str, str, str, str | None] | tuple[()] | None = None

    def init_state(self) -> None:
        """The trial's state before its first reset."""
        #: ``int e dt`` of each task row (integral action; sized at the first step).
        self.integral = np.zeros(0)
        #: The nominal drives' force limits [N].
        self.force_limit = np.full(6, np.inf)
        self.force_limit_list = self.force_limit.tolist()
        self.context: ControllerContext | None = None
        self.model: DynamicModel | None = None
        #: (3,) the reference clock (:mod:`controllers.task_ctc_rows`: started, the time
        #: at which the reference's clock is 0 [s], the reference's version), its own or
        #: a view of its batch's.
        self.clock = np.zeros(3)
        self._reference: Any = None  # anything with at(times) and duration, base frame
        self._pose_grid: tuple[Any, np.ndarray] | None = None
        #: The compiled step (None: not reset).
        self.compiled: CompiledTaskStep | None = None
        #: The batch's arrays (:class:`~controllers.task_ctc_rows.TaskRows`), built at
        #: the first batched step after a reset (trial 0 holds them).
        self._rows: TaskRows | None = None

    def reset_trial(self, context: ControllerContext) -> None:
        """Build the nominal model; take the reference or the goal.

        Raises:
            ContextError: What the law needs is missing from the context.
        """
        self.context = context
        self.model = DynamicModel(context.geometry)
        self._rows = None
        self.clock = np.zeros(3)
        self.compiled = None
        self.integral = np.zeros(0)
        self.force_limit = np.asarray(context.geometry.drives.force_limit, dtype=float)
        self.force_limit_list = self.force_limit.tolist()
        self._pose_grid = None
        self.prepare(context)
        self.retarget_trial(context.goal)
        self.compiled = None if self.compiled_kind is None else CompiledTaskStep(self)

    def __getstate__(self) -> dict[str, object]:
        """Picklable: the batch's arrays are left out (its own clock kept)."""
        state = self.__dict__.copy()
        state["_rows"] = None
        state["clock"] = np.array(self.clock)
        return state

    @property
    def reference(self) -> Any:
        """The reference followed (base frame; anything with ``at(times)`` and
        ``duration``), or None (a fixed goal at rest)."""
        return self._reference

    @reference.setter
    def reference(self, reference: Any) -> None:
        self._reference = reference
        self.reference_changed()

    def reference_changed(self) -> None:
        """Count a change of what the reference grid is built from (a batch builds its
        grid again)."""
        self.clock[VERSION] += 1.0

    @property
    def guess(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The pose guess ``(R, t)`` of the next step (None: none found yet)."""
        return None if self.compiled is None else self.compiled.guess

    @property
    def compiled_steps(self) -> int:
        """Commands of the compiled step (diagnostics)."""
        return 0 if self.compiled is None else int(self.compiled.steps[0])

    @property
    def started(self) -> bool:
        """Whether the law follows its reference (a fixed goal's line starts at the
        first step)."""
        return bool(self.clock[STARTED])

    @property
    def reference_start(self) -> float:
        """The observation time [s] at which the reference's clock is 0."""
        return float(self.clock[START])

    def prepare(self, context: ControllerContext) -> None:
        """Per-trial checks and constants of a subclass (nothing by default)."""

    def compiled_constants(self, step: CompiledTaskStep) -> None:
        """Write the law's constant inputs of the compiled step (nothing by default)."""

    @abstractmethod
    def compiled_inputs(self, step: CompiledTaskStep, observation: Observation, tr: float,
                        q: np.ndarray) -> tuple[np.ndarray | None, str | None] | str:
        """Write this period's measurement and reference (``tr`` [s] on the reference's
        clock; without a reference the fixed goal at rest) into the compiled step's row;
        the task rows to use (None: all) and a note, or why there is no measurement."""

    def batch_partly_seen(self, rows_batch: TaskRows, step: CompiledTaskStep,
                          X: np.ndarray, observations: ObservationBatch,
                          candidates: np.ndarray
                          ) -> dict[int, tuple[np.ndarray | None, str | None]]:
        """Write the measurement of the ``candidates`` (n,) rows that :meth:`compiled_inputs`
        takes with some feature hidden, as it writes them, where the law can do it as
        arrays; those rows with their task rows used (None: all) and the note
        :meth:`compiled_inputs` gives. None by default."""
        return {}

    def batch_grid(self) -> tuple[np.ndarray, np.ndarray | None] | None:
        """The reference rows on the control grid (S, w) as :meth:`compiled_inputs`
        writes them, and the grid steps whose task rows are all known (S,) (None: all),
        for :class:`~controllers.task_ctc_rows.TaskRows`; None without a reference."""
        return None

    def build_grids(self, laws: list[TaskComputedTorque]) -> None:
        """Build the reference grids of ``laws`` (trials of this law's batch, with new
        references) together before their :meth:`batch_grid` (nothing by default: each
        builds its own)."""

    def retarget_trial(self, goal: Goal) -> None:
        """A new fixed goal (ignored when tracking ``context.reference``)."""
        ctx = self.context
        if ctx is None:
            return
        if ctx.reference is not None:
            self.reference = ctx.reference
            self.clock[STARTED], self.clock[START] = 1.0, 0.0
            return
        self.context = ctx = ctx if ctx.goal is goal else replace(ctx, goal=goal)
        self.take_goal(goal)
        self.reference = None
        self.clock[STARTED] = 0.0

    def take_goal(self, goal: Goal) -> None:
        """Read what the law regulates to from a fixed goal (raises ContextError)."""

    @abstractmethod
    def goal_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """The fixed goal's pose (base frame), the end of the smooth line."""

    def pose_reference(self, tr: float) -> np.ndarray:
        """(24,) the reference at ``tr`` [s]: ``R*`` (row-major), ``t*``, twist, twist rate
        (base frame, :meth:`anchor`). The control grid ``k dt`` is sampled once per
        reference (one batched call); other instants on demand."""
        assert self.context is not None
        k = grid_step(tr, float(self.context.dt))
        if k >= 0:
            grid = self.pose_grid()
            return grid[min(k, len(grid) - 1)]  # type: ignore[no-any-return]
        return self.pose_rows(np.array([tr]))[0]

    def pose_grid(self) -> np.ndarray:
        """(n, 24) :meth:`pose_reference` on the control grid ``k dt`` up to the
        reference's end (and a step past it), built on first use for each reference."""
        ctx, ref = self.context, self.reference
        assert ctx is not None and ref is not None
        if self._pose_grid is None or self._pose_grid[0] is not ref:
            self._pose_grid = (ref, self.pose_rows(grid_times(ref.duration, float(ctx.dt))))
        return self._pose_grid[1]

    def pose_rows(self, times: np.ndarray) -> np.ndarray:
        """(m, 24) rows of :meth:`pose_reference` at ``times`` (m,) [s]."""
        sample = self.reference.at(times)
        R, t, tw, twr = self.anchor(sample.rotation, sample.translation, sample.twist,
                                    sample.twist_rate)
        return np.concatenate([R.reshape(len(t), 9), t, tw, twr], axis=1)

    def anchor(self, R: np.ndarray, t: np.ndarray, twist: np.ndarray, twist_rate: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The reference's poses (m, 3, 3), (m, 3), twists and rates (m, 6) as the law
        tracks them (unchanged by default)."""
        return R, t, twist, twist_rate

    def batch_rows(self) -> TaskRows:
        """The batch's arrays and its one step (:meth:`~controllers.task_ctc_rows.
        TaskRows.step`)."""
        return TaskRows(self.trial_instances)

    def integral_term(self, m: int) -> np.ndarray:
        """(m,) ``Kp Ki int e dt`` of the task rows (the integral action's share of the
        desired ``e_ddot``, subtracted from it)."""
        if len(self.integral) != m:
            self.integral = np.zeros(m)
        return self.gains.kp * self.integral_gain * self.integral  # type: ignore[no-any-return]

    def limited(self, forces: np.ndarray, pose: np.ndarray, qd: np.ndarray,
                error: np.ndarray, used: np.ndarray | None, over: bool | None = None
                ) -> np.ndarray:
        """The forces [N] of an accepted step under the saturation strategy; the
        integral of the task error advanced unless a leg's force is over its limit.

        Args:
            forces: (6,) the control law's forces [N].
            pose: (12,) the pose of the step (``R`` column-major, ``t`` [m]).
            qd: (6,) measured leg velocities [m/s].
            error: (m,) the task error of every row.
            used: (m,) the rows used, or None.
            over: Whether a leg's force is over its limit (None: found here).
        """
        if over is None:
            over = over_limit(forces, self.force_limit_list)
        if self.integral_gain and not over:
            assert self.context is not None
            if len(self.integral) != len(error):
                self.integral = np.zeros(len(error))
            step = np.where(np.isfinite(error), error, 0.0) * float(self.context.dt)
            self.integral += step if used is None else np.where(used, step, 0.0)
        if not over:
            return forces
        model, ctx = self.model, self.context
        assert model is not None and ctx is not None
        return self.ctc_options.saturated(forces, self.force_limit, lambda: (
            zero_acceleration_forces(model, pose, qd, hold=float(ctx.dt))))

    def refuse(self, problem: str, error: np.ndarray | None = None) -> Command:
        """A zero force command with the reason."""
        return Command.refuse(f"{self.name}: {problem}", error=error,
                              actuation=Actuation.FORCE)
