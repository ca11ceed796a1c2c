"""Joint-space computed torque on the encoder lengths (the industrial baseline).

A force controller (:attr:`Actuation.FORCE`) for the dynamic world (it needs the measured
leg velocities ``Observation.q_dot``). Its model is the context's NOMINAL geometry,
inertia and drives, never the world's truth:

- reference ``q*``, ``q_dot* = K x_dot*``, ``q_ddot* = K x_ddot* + K_dot x_dot*``: the
  nominal inverse kinematics of ``context.reference``; a fixed goal (``goal.lengths``) is
  reached along a leg-space quintic from the lengths measured at the first step, timed so
  that no leg's reference speed exceeds the nominal speed limit;
- pose: the nominal forward kinematics of the encoder lengths, twist ``x_dot = K^-1 q_dot``;
- desired leg acceleration ``a = q_ddot* + Kd (q_dot* - q_dot) + Kp (q* - q)`` with
  ``Kp = omega_n^2``, ``Kd = 2 zeta omega_n`` (the leg error obeys ``e_ddot + 2 zeta
  omega_n e_dot + omega_n^2 e = 0`` when the model is exact), ``x_ddot = K^-1 (a - K_dot
  x_dot)`` and the forces ``DynamicModel.inverse(R, t, x_dot, x_ddot)`` plus the drives'
  ``m_r a + c q_dot + f_c tanh(q_dot* / v_s)``.

The force is held over the control period, so ``omega_n dt`` must stay small (the
default ``omega_n = 2 pi * 2 Hz``, ``zeta = 1``: 0.25 at 20 ms). Options: integral action
``integral_gain`` ``Ki`` [1/s] (``a = ... + Kp (e + Ki int e dt)``, held while a leg's
force is over its limit; stable for ``Ki < 2 zeta omega_n``) and ``saturation`` over the
limit (:mod:`controllers.solvers.saturation`: ``"clip"``, ``"scale"`` or ``"qp"``).

The step is one compiled function (:mod:`controllers.solvers.compiled_ctc`) and C around
it over the rows of a batch (:mod:`controllers.joint_ctc_rows`); the per-trial ``step``
is a batch of one.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from controllers.control_grid import chunks, grid_times
from controllers.ctc_law import DAMPING, NATURAL_FREQUENCY_HZ, ComputedTorqueLaw
from controllers.ctc_rows import FK_MAX_CALLS
from controllers.exceptions import ContextError
from controllers.joint_ctc_rows import (
    POSE_IN,
    QUINTIC_SIZE,
    JointRows,
    JointState,
)
from controllers.law_tools import goal_lengths
from controllers.solvers import compiled_ctc
from controllers.solvers.saturation import zero_acceleration_forces
from controllers.task_ctc_inputs import QUINTIC_PEAK_SPEED
from hexapod.dynamics import DynamicModel
from hexapod.dynamics.model import INVERSE_TOLERANCE
from hexapod.kinematics import inverse_kinematics
from hexapod.layout import read_pose, write_pose
from hexapod.workspace import home_pose

if TYPE_CHECKING:
    from collections.abc import Sequence

    from controllers.data import ControllerContext, Goal
    from hexapod.geometry import HexapodGeometry

#: Forward-kinematics tolerance on the length residual [m] (as :func:`forward_kinematics`).
FK_TOLERANCE = compiled_ctc.FK_TOLERANCE
__all__ = ["DAMPING", "FK_MAX_CALLS", "FK_TOLERANCE", "NATURAL_FREQUENCY_HZ",
           "QUINTIC_PEAK_SPEED", "ComputedTorqueController", "legs_of_poses", "sample_grids"]


class ComputedTorqueController(ComputedTorqueLaw):
    """Joint-space computed torque (see the module docstring).

    Args:
        natural_frequency: ``f_n`` [Hz] of the leg error's second-order response.
        smooth_goal: Reach a fixed goal along the leg-space quintic (False: a step of
            ``q*`` to the goal, the error's free response).
        integral_gain: Integral action Ki [1/s] on the leg error (default 0: none).
            Held while a leg's force is over its limit.

    The other options (``damping``, ``saturation``) are
    :class:`~controllers.ctc_law.ComputedTorqueLaw`'s.
    """

    name = "computed-torque"
    features = frozenset({"lengths"})

    def init_state(self) -> None:
        """The trial's state before its first reset."""
        self.kp = self.gains.kp
        self.kd = self.gains.kd
        self._ctx: ControllerContext | None = None
        self._model: DynamicModel | None = None
        #: The trial's state, own or views of its batch's (:meth:`adopt`): ``int (q* -
        #: q) dt`` [m s], the fixed goal's quintic and the compiled step's commands.
        self._integral = np.zeros(6)
        self._quintic = np.zeros(QUINTIC_SIZE)
        self._steps = np.zeros(1, dtype=np.int64)
        #: The nominal force limits [N] (inf before a reset).
        self._limit = np.full(6, np.inf)
        self._q_star = np.zeros(6)
        #: The compiled step's input row (own or a view of its batch's; None before a
        #: reset); its pose block holds the pose guess (the last pose found, the home pose
        #: before one).
        self._row: np.ndarray | None = None
        #: The batch whose arrays hold this trial's state, and its row there.
        self._batch: JointRows | None = None
        self._index = 0
        #: ``(q*, q_dot*, q_ddot*)`` of a reference on the control grid ``k dt`` (N, 18)
        #: (None: not sampled yet, :attr:`grid`).
        self._grid: np.ndarray | None = np.zeros((0, 18))
        #: The control period [s] and the time after which the reference is at rest [s].
        self._dt = 0.0
        self._t_end = math.inf
        #: The batch's arrays (:class:`~controllers.joint_ctc_rows.JointRows`; trial 0's).
        self._rows: JointRows | None = None

    @property
    def compiled_steps(self) -> int:
        """Commands given by the compiled step (diagnostics)."""
        return int(self._steps[0])

    @property
    def _pose(self) -> tuple[np.ndarray, np.ndarray]:
        """The pose guess ``(R, t)`` of the next step (copies of the input row's)."""
        assert self._row is not None
        return read_pose(self._row[POSE_IN])

    @_pose.setter
    def _pose(self, pose: tuple[np.ndarray, np.ndarray] | None) -> None:
        """Set the next step's pose guess (None: the nominal home pose)."""
        assert self._row is not None and self._ctx is not None
        R0, p0 = home_pose(self._ctx.geometry) if pose is None else pose
        write_pose(self._row[POSE_IN], R0, p0)

    def __getstate__(self) -> dict[str, object]:
        """Picklable: the batch (C context) left out, rebuilt at the next step from
        copies of this trial's arrays."""
        state = self.__dict__.copy()
        state["_rows"] = state["_batch"] = None
        state["_row"] = None if self._row is None else self._row.copy()
        for key in ("_integral", "_quintic", "_steps"):  # own arrays, not views
            state[key] = np.array(state[key])
        return state

    def adopt(self, batch: JointRows, index: int) -> None:
        """Take views of row ``index`` of a batch's arrays (their values there already)
        as this trial's input row, integral (6,), quintic (21,) and command count (1,)."""
        self._batch, self._index = batch, index
        self._row, self._integral = batch.X[index], batch.integral[index]
        self._quintic, self._steps = batch.quintic[index], batch.steps[index:index + 1]

    def batch_state(self) -> JointState:
        """This trial's state for its batch (:class:`~controllers.joint_ctc_rows.JointRows`)."""
        assert self._row is not None and self._ctx is not None
        grid = None if self._ctx.reference is None else self.grid
        speed = float(self._ctx.max_speed) if self.smooth_goal else math.nan
        return JointState(self._row, self._integral, self._quintic, self._steps,
                          self._limit, self._dt, self._t_end, grid, speed,
                          compiled_ctc.joint_step(INVERSE_TOLERANCE))

    def reset_trial(self, context: ControllerContext) -> None:
        """Build the nominal model; read the reference or ``goal.lengths``.

        Raises:
            ContextError: Neither a reference nor finite goal lengths.
        """
        self._ctx = context
        self._model = DynamicModel(context.geometry)
        self._rows = None
        self._integral = np.zeros(6)
        self._quintic = np.zeros(QUINTIC_SIZE)
        self._steps = np.zeros(1, dtype=np.int64)
        self._limit = np.asarray(context.geometry.drives.force_limit, dtype=float)
        # its own row (not a view of a former batch's)
        self._row, self._batch = np.zeros(compiled_ctc.INPUTS.size), None
        row = self._row
        g, d, at = context.geometry, context.geometry.drives, compiled_ctc.INPUTS
        row[at["points"]] = np.ravel((g.base_points, g.platform_points))
        row[at["params"]] = np.ravel(self._model.parameters)
        row[at["rotor"]] = d.rotor_inertia
        row[at["viscous"]] = d.viscous
        row[at["coulomb"]] = d.coulomb
        row[at["gains"]] = (self.kp, self.kd)
        self._pose = None
        self._grid = np.zeros((0, 18))
        self._dt = float(context.dt)
        if context.reference is None:
            self._t_end = math.inf
            self.retarget_trial(context.goal)
        else:  # the reference's legs on the control grid: sampled by reset_batch
            self._t_end = float(context.reference.duration) + context.dt
            self._grid = None

    def reset_batch(self, contexts: Sequence[ControllerContext]) -> None:
        """Every trial reset, the references' legs on the control grids sampled
        together (:func:`sample_grids`), then the batch's arrays (:class:`JointRows`).

        Raises:
            ContextError: A context the controller cannot use.
            DynamicsError: The nominal model cannot evaluate a reference.
        """
        super().reset_batch(contexts)
        sample_grids([inst for inst in self.trial_instances
                      if isinstance(inst, ComputedTorqueController) and inst.grid_pending])
        self._rows = self.batch_rows()

    def grid_times(self) -> np.ndarray:
        """The control grid [s] on which the reference is sampled
        (:func:`controllers.control_grid.grid_times`)."""
        assert self._ctx is not None and self._ctx.reference is not None
        return grid_times(self._ctx.reference.duration, self._dt)

    @property
    def grid_pending(self) -> bool:
        """True after a reset to a reference, until its grid is sampled."""
        return self._grid is None

    def grid_source(self) -> tuple[ControllerContext, DynamicModel]:
        """The context (with its reference) and the nominal model the grid is sampled
        from (after a reset)."""
        assert self._ctx is not None and self._model is not None
        return self._ctx, self._model

    def take_grid(self, grid: np.ndarray) -> None:
        """Take the reference's grid (N, 18) sampled for this trial (:func:`sample_grids`)."""
        self._grid = grid

    @property
    def grid(self) -> np.ndarray:
        """``(q*, q_dot*, q_ddot*)`` (N, 18) of the reference on the control grid
        (:meth:`grid_times`; sampled here when :meth:`reset_batch` has not), (0, 18)
        for a fixed goal."""
        if self._grid is None:
            self._grid = self.reference_legs(self.grid_times()).reshape(-1, 18)
        return self._grid

    def retarget_trial(self, goal: Goal) -> None:
        """A new fixed goal (ignored when tracking a reference: it is sampled itself)."""
        if self._ctx is not None and self._ctx.reference is not None:
            return
        self._q_star = goal_lengths(self.name, goal, None if self._ctx is None
                                    else self._ctx.geometry.stroke)
        self._quintic[0] = 0.0  # started again at the next step
        self._quintic[15:21] = self._q_star

    def desired(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(q*, q_dot*, q_ddot*)`` at time ``t`` [s] ([m], [m/s], [m/s^2]) as the next
        step reads them (a fixed goal's quintic as it is: ``q*`` before its first step)."""
        if self._row is None:
            raise ContextError(self.name, "context", "desired(t) before reset(context)")
        if self._batch is None:  # (a copy, before its first step): a batch of its own
            JointRows([self])
        assert self._batch is not None
        out = self._batch.desired(self._index, t)
        return out[0:6], out[6:12], out[12:18]

    def reference_legs(self, times: np.ndarray) -> np.ndarray:
        """``(q*, q_dot*, q_ddot*)`` of the reference at ``times`` (N,) [s]: (N, 3, 6)."""
        ctx, model = self._ctx, self._model
        assert ctx is not None and model is not None
        ref = ctx.reference.at(times)
        return legs_of_poses(ctx.geometry, model, ref.rotation, ref.translation, ref.twist,
                             ref.twist_rate)

    def saturated_forces(self, forces: np.ndarray, pose: np.ndarray, qd: np.ndarray,
                         qd_s: np.ndarray) -> np.ndarray:
        """The forces [N] of an accepted step (6,) under the saturation strategy (as
        they are under the limits), with its pose (12,) (``R`` column-major, ``t`` [m]),
        the leg velocities ``qd`` [m/s] and their reference ``qd_s`` [m/s]."""
        model = self._model
        assert model is not None
        return self.ctc_options.saturated(forces, self._limit, lambda: zero_acceleration_forces(
            model, pose, qd, coulomb_velocity=qd_s))

    @property
    def context(self) -> ControllerContext | None:
        """The trial's context (None before :meth:`reset_trial`)."""
        return self._ctx

    def batch_rows(self) -> JointRows:
        """The batch's arrays and its one step (:meth:`JointRows.step`: refused, zero,
        with a reason where the lengths, their rates or the time are missing or not
        finite, or the nominal model fails)."""
        return JointRows(self.trial_instances)


def legs_of_poses(geometry: HexapodGeometry, model: DynamicModel, R: np.ndarray, p: np.ndarray,
                  twist: np.ndarray, acc: np.ndarray) -> np.ndarray:
    """``(q, q_dot, q_ddot)`` (N, 3, 6) [m, m/s, m/s^2] of platform poses ``(R, p)``
    (N, 3, 3), (N, 3) [m] moving at ``twist`` (N, 6) with ``acc`` (N, 6) (its rate),
    by the nominal ``model``: every row on its own (the same numbers in any batch)."""
    out = np.empty((len(p), 3, 6))
    out[:, 0] = inverse_kinematics(geometry, R, p)
    K, rate, bias = model.legs_jacobian_batch(R, p, twist)
    out[:, 1] = rate
    out[:, 2] = np.einsum("nij,nj->ni", K, acc) + bias
    return out


def sample_grids(laws: list[ComputedTorqueController]) -> None:
    """Sample the references of the (reset) trials ``laws`` on their control grids
    (:attr:`ComputedTorqueController.grid`): the legs of the trials that share their
    nominal geometry in one evaluation per chunk (:func:`controllers.control_grid.chunks`:
    rows are independent, each grid holds the numbers of its own evaluation)."""
    for members in chunks([id(law.grid_source()[0].geometry) for law in laws]):
        group = [laws[k] for k in members]
        ctx, model = group[0].grid_source()
        refs = [law.grid_source()[0].reference.at(law.grid_times())  # type: ignore[union-attr]
                for law in group]
        legs = legs_of_poses(
            ctx.geometry, model,
            *(np.concatenate([getattr(r, f) for r in refs])
              for f in ("rotation", "translation", "twist", "twist_rate")))
        start = 0
        for law, ref in zip(group, refs, strict=True):
            size = len(ref.translation)
            law.take_grid(legs[start:start + size].reshape(size, 18))
            start += size
