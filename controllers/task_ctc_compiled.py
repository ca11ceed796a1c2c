"""The compiled step of the task-space computed-torque laws.

:class:`CompiledTaskStep` fills the input row of the law's compiled step
(:func:`controllers.solvers.compiled_task_ctc.task_step`, or a plugin feature's of the
same layouts), calls it and reads the command; off the happy path it answers why not:
the law's measurement has none, or the row's ``status`` (:mod:`controllers.ctc_status`)
or the rank test says so (worded by :func:`controllers.ctc_rows.refusal`). A law gives
it ``compiled_kind`` and ``compiled_fk``, its constants (``compiled_constants(step)``)
and each period its measurement and reference (``compiled_inputs(step, observation,
tr, q)``: the rows to use or None and a note, or why there is no measurement).

The C function runs on the step's own bound rows (:meth:`hexapod.compiled.
CompiledFunction.bind`; the input row may be a row of its batch's matrix,
:mod:`controllers.task_ctc_rows`); the row's ``pose`` block holds the pose guess.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike
from scipy.linalg.lapack import dsyevd as _eigenvalues

from controllers.base import Command, Observation
from controllers.ctc_rows import FK_MAX_CALLS, newton_calls, refusal
from controllers.solvers.compiled_task_ctc import FIT_TOLERANCE, FK_TOLERANCE, task_step
from hexapod.actuation import Actuation
from hexapod.compiled import BoundCall, CompiledFunction
from hexapod.dynamics.model import INVERSE_TOLERANCE
from hexapod.workspace import home_pose

if TYPE_CHECKING:
    from controllers.task_ctc import TaskComputedTorque


class CompiledTaskStep:
    """The compiled step of one law (see the module docstring). A subclass may step
    another function of the built-in steps' layouts (:meth:`make_function`, as
    :class:`controllers.features.ctc_step.FeatureTaskStep` does).

    Args:
        law: The law, reset (its context and nominal model built).
        kind: The step's feature object (default: the law's ``compiled_kind``; a
            subclass's own step may name it by a string).
        fk: The pose from the encoders by Newton steps (default: the law's
            ``compiled_fk``); else by the rigid fit (its tolerance).
    """

    #: The input row, its guess flag (1,) and its command count (1,) (:meth:`adopt`).
    row: np.ndarray
    guessed: np.ndarray
    steps: np.ndarray

    def __init__(self, law: TaskComputedTorque, kind: Any = None,
                 fk: bool | None = None) -> None:
        assert law.context is not None and law.model is not None
        kind = law.compiled_kind if kind is None else kind
        assert kind is not None
        self.kind: Any = kind
        self.fk: bool = law.compiled_fk if fk is None else bool(fk)
        self.function = self.make_function()
        self.inputs, self.outputs = self.function.inputs, self.function.outputs
        self.adopt(np.zeros(self.function.n_in), np.zeros(1), np.zeros(1, dtype=np.int64))
        g = law.context.geometry
        d = g.drives
        self.set("points", (g.base_points, g.platform_points))
        self.set("params", law.model.parameters)
        self.set("rotor", d.rotor_inertia)
        self.set("viscous", d.viscous)
        self.set("coulomb", d.coulomb)
        self.set("gains", (law.gains.kp, law.gains.kd, float(law.context.dt)))
        self.home = home_pose(g)
        self.guess = None
        out = self.outputs
        self._residual = out.index("fk_residual")
        self._status = out.index("status")
        self._factor = out["factor"]
        self._forces = out["forces"]
        #: The output blocks of the pose and of the task error.
        self.pose_block, self.error_block = out["pose"], out["error"]
        #: Pose residual below which the pose has converged.
        self.tolerance = FK_TOLERANCE if self.fk else FIT_TOLERANCE
        #: What finds the pose (a refusal names it).
        self.pose_name = "forward kinematics of the lengths" if self.fk else \
            "the rigid fit of the legs seen"
        law.compiled_constants(self)

    def make_function(self) -> CompiledFunction:
        """The compiled step of :attr:`kind` and :attr:`fk` (a subclass's hook: another
        function of the same blocks; called again on unpickling)."""
        return task_step(self.kind, self.fk, INVERSE_TOLERANCE)

    def adopt(self, row: np.ndarray, guessed: np.ndarray, steps: np.ndarray) -> None:
        """Bind the compiled function to the input row ``row`` (n_in,) (used in place:
        its own, or a row of its batch's matrix, its values there already), with the
        flag whether its pose block holds a pose found (1,) and the count of commands
        (1,) (own or the batch's)."""
        #: The input row (written in place, evaluated without a copy).
        self.row = row
        #: The function bound to the row and its views by block
        #: (:func:`~controllers.solvers.compiled_task_ctc.layout`), made at the first
        #: per-trial use (:meth:`bind`; a batch's rows stepped as arrays never bind one):
        #: None and empty before.
        self.bound: BoundCall | None = None
        self.views: dict[str, np.ndarray] = {}
        #: Whether the ``pose`` block holds a pose found (1.0) or the home pose (0.0).
        self.guessed = guessed
        #: Commands given by the step (the law's ``compiled_steps``).
        self.steps = steps
        #: The task rows the last prepared step uses (None: all).
        self.used: np.ndarray | None = None

    def bind(self) -> dict[str, np.ndarray]:
        """Bind the compiled function to :attr:`row` (its first per-trial use); returns
        :attr:`views`."""
        self.bound = self.function.bind(self.row)
        self.views = self.bound.inputs
        return self.views

    def __getstate__(self) -> dict[str, object]:
        """Picklable: the function and its binding (ctypes) are rebuilt on unpickling."""
        state = self.__dict__.copy()
        for key in ("function", "bound", "row", "views", "guessed", "steps"):
            del state[key]
        state["_arrays"] = (self.row.copy(), self.guessed.copy(), self.steps.copy())
        return state

    def __setstate__(self, state: dict[str, object]) -> None:
        arrays = state.pop("_arrays")
        assert isinstance(arrays, tuple)
        self.__dict__.update(state)
        self.function = self.make_function()
        self.adopt(*arrays)
        self.bind()

    @property
    def guess(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The pose guess ``(R, t)`` of the next step (copies), or None before a pose is
        found (the home pose is in the row)."""
        if not self.guessed[0]:
            return None
        pose = self.row[self.inputs["pose"]]
        return pose[0:9].reshape(3, 3).T.copy(), pose[9:12].copy()

    @guess.setter
    def guess(self, pose: tuple[np.ndarray, np.ndarray] | None) -> None:
        """Set the next step's pose guess (None: the home pose)."""
        R0, t0 = self.home if pose is None else pose
        pose_in = self.row[self.inputs["pose"]]
        pose_in[0:9] = np.asarray(R0).T.ravel()
        pose_in[9:12] = t0
        self.guessed[0] = 0.0 if pose is None else 1.0

    def set(self, name: str, value: ArrayLike) -> None:
        """Write an input block (:func:`~controllers.solvers.compiled_task_ctc.layout`;
        its values in row-major order, or one value for all)."""
        self.row[self.inputs[name]] = np.ravel(value)

    def step_written(self, law: TaskComputedTorque, observation: Observation, tr: float
                     ) -> Command | str:
        """The command of this period at ``tr`` [s] of the reference's clock, or why there
        is none (``q`` and ``q_dot`` already in the row)."""
        prepared = self.prepare(law, observation, tr)
        if isinstance(prepared, str):
            return prepared
        rows, note = prepared
        bound = self.bound
        assert bound is not None  # (prepare binds it)
        pose_in, y = self.views["pose"], bound.y
        guess = newton_calls(bound, pose_in, self.pose_block, self._residual,
                             self.tolerance, FK_MAX_CALLS)
        # a command: status 0 and full rank (the squared singular values of the masked
        # Jacobian by LAPACK syevd of L^T L; the test of controllers.ctc_rows.rank_condition,
        # the condition as sqrt(max / min)); its pose then the next guess
        w_min = w_max = 0.0
        info = 1
        if y[self._status] == 0.0:
            w, _, info = _eigenvalues(y[self._factor].reshape(6, 6), 0)  # (compute_v=0)
            w_min, w_max = float(w[0]), float(w[-1])
        if info != 0 or not (w_max > 0 and w_min > law.solver.threshold**2 * w_max):
            if guess is not None:  # the guess stays the last pose found
                pose_in[:] = guess
            reason = refusal(y, self._status, self._residual, self._factor,
                             law.solver.threshold,
                             self.pose_name, self.views)
            assert reason is not None
            return reason
        pose_in[:] = y[self.pose_block]
        self.guessed[0] = 1.0
        e = y[self.error_block]
        e = e.copy() if rows is None else e[rows]
        return Command(np.zeros(6), error=e, error_norm=math.sqrt(e.dot(e)), rank=6,
                       condition=math.sqrt(w_max / w_min), features_used=len(e),
                       active_constraints=[],
                       notes=[] if note is None else [note], actuation=Actuation.FORCE,
                       forces=y[self._forces].copy())

    def prepare(self, law: TaskComputedTorque, observation: Observation, tr: float
                ) -> tuple[np.ndarray | None, str | None] | str:
        """Write the law's measurement and the reference at ``tr`` into the row (``q``,
        ``q_dot`` and the pose guess there already); the task rows to use (None: all) and
        a note, or why there is no measurement."""
        views = self.views or self.bind()
        prepared = law.compiled_inputs(self, observation, tr, views["q"])
        if isinstance(prepared, str):
            return prepared
        rows = prepared[0]
        if law.integral_gain:
            views["integral"][:] = law.integral_term(views["integral"].size)
        self.used = rows
        return prepared


__all__ = ["FIT_TOLERANCE", "FK_MAX_CALLS", "FK_TOLERANCE", "CompiledTaskStep"]
