"""The compiled step of the task-space computed-torque laws.

:class:`CompiledTaskStep` holds the law's compiled step
(:func:`controllers.solvers.compiled_task_ctc.task_step`, or a plugin feature's of the
same layouts) and its input row, and fills that row: a law gives it ``compiled_kind``
and ``compiled_fk``, its constants (``compiled_constants(step)``) and, for a row its
batch does not write as arrays, its measurement and reference (``compiled_inputs(step,
observation, tr, q)``: the rows to use or None and a note, or why there is no
measurement).

The input row is a row of its batch's matrix (:mod:`controllers.task_ctc_rows`, whose
one step evaluates it); the row's ``pose`` block holds the pose guess.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from controllers.base import Observation
from controllers.ctc_rows import FK_MAX_CALLS
from controllers.solvers.compiled_task_ctc import FIT_TOLERANCE, FK_TOLERANCE, task_step
from hexapod.compiled import CompiledFunction
from hexapod.dynamics.model import INVERSE_TOLERANCE
from hexapod.layout import read_pose, write_pose
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
        """Take the input row ``row`` (n_in,) (its own, or a row of its batch's matrix,
        its values there already), with the flag whether its pose block holds a pose
        found (1,) and the count of commands (1,) (own or the batch's)."""
        #: The input row (written in place) and its views by block
        #: (:func:`~controllers.solvers.compiled_task_ctc.layout`).
        self.row = row
        self.views: dict[str, np.ndarray] = self.inputs.views(row)
        #: Whether the ``pose`` block holds a pose found (1.0) or the home pose (0.0).
        self.guessed = guessed
        #: Commands given by the step (the law's ``compiled_steps``).
        self.steps = steps
        #: The task rows the last prepared step uses (None: all).
        self.used: np.ndarray | None = None

    def __getstate__(self) -> dict[str, object]:
        """Picklable: the function (ctypes) is rebuilt on unpickling."""
        state = self.__dict__.copy()
        for key in ("function", "row", "views", "guessed", "steps"):
            del state[key]
        state["_arrays"] = (self.row.copy(), self.guessed.copy(), self.steps.copy())
        return state

    def __setstate__(self, state: dict[str, object]) -> None:
        arrays = state.pop("_arrays")
        assert isinstance(arrays, tuple)
        self.__dict__.update(state)
        self.function = self.make_function()
        self.adopt(*arrays)

    @property
    def guess(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The pose guess ``(R, t)`` of the next step (copies), or None before a pose is
        found (the home pose is in the row)."""
        if not self.guessed[0]:
            return None
        return read_pose(self.row[self.inputs["pose"]])

    @guess.setter
    def guess(self, pose: tuple[np.ndarray, np.ndarray] | None) -> None:
        """Set the next step's pose guess (None: the home pose)."""
        R0, t0 = self.home if pose is None else pose
        write_pose(self.row[self.inputs["pose"]], R0, t0)
        self.guessed[0] = 0.0 if pose is None else 1.0

    def set(self, name: str, value: ArrayLike) -> None:
        """Write an input block (:func:`~controllers.solvers.compiled_task_ctc.layout`;
        its values in row-major order, or one value for all)."""
        self.row[self.inputs[name]] = np.ravel(value)

    def prepare(self, law: TaskComputedTorque, observation: Observation, tr: float
                ) -> tuple[np.ndarray | None, str | None] | str:
        """Write the law's measurement and the reference at ``tr`` into the row (``q``,
        ``q_dot`` and the pose guess there already); the task rows to use (None: all) and
        a note, or why there is no measurement."""
        views = self.views
        prepared = law.compiled_inputs(self, observation, tr, views["q"])
        if isinstance(prepared, str):
            return prepared
        rows = prepared[0]
        if law.integral_gain:
            views["integral"][:] = law.integral_term(views["integral"].size)
        self.used = rows
        return prepared


__all__ = ["FIT_TOLERANCE", "FK_MAX_CALLS", "FK_TOLERANCE", "CompiledTaskStep"]
