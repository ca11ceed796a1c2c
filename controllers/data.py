"""What a controller reads and writes: observations, goals, context, commands, one trial
and a batch of trials (:class:`Observation` / :class:`ObservationBatch`, :class:`Goal` /
:class:`GoalBatch`, :class:`Command` / :class:`CommandBatch`). All re-exported by
:mod:`controllers.base`.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from controllers.plausible import implausible_lengths
from hexapod.actuation import Actuation
from hexapod.geometry import HexapodGeometry

#: The observed unit-vector feature fields: name, shape of one trial's, visibility mask
#: (the ``field``, ``shape`` and ``visibility`` of the built-in feature objects,
#: :mod:`controllers.tasks.feature_kind`).
FEATURE_FIELDS = (("normals", (6, 2, 3), "edge_visible"), ("lines", (6, 2, 3), "edge_visible"),
                  ("directions", (6, 3), "direction_visible"))


@dataclass
class Observation:
    """What the robot and the camera measured at one instant.

    All vectors are in the camera frame. Hidden features are NaN and flagged
    False in the masks.

    Attributes:
        t: Time [s].
        lengths: (6,) measured leg lengths (encoders, offsets included) [m].
        normals: (6, 2, 3) unit edge normals (interpretation planes), computed with
            the estimated intrinsics; None when the sensor gives none.
        lines: (6, 2, 3) unit image lines in normalised pixel coordinates
            (perspective camera only), else None.
        directions: (6, 3) unit leg directions, else None.
        edge_visible: (6, 2) bool, which edges were observed.
        direction_visible: (6,) bool, which directions were observed.
        quality: Optional per-edge quality (e.g. fit residual), (6, 2).
        image_t: Capture time of the image the features come from [s] (None: taken at
            ``t``); older than ``t`` by the camera's latency and frame period
            (:mod:`benchmarks.sim.clock`).
        q_dot: (6,) measured leg velocities [m/s], or None when the robot gives none
            (a kinematic world does not; force laws need them).
    """

    t: float
    lengths: np.ndarray
    normals: np.ndarray | None = None
    lines: np.ndarray | None = None
    directions: np.ndarray | None = None
    edge_visible: np.ndarray = field(default_factory=lambda: np.ones((6, 2), dtype=bool))
    direction_visible: np.ndarray = field(default_factory=lambda: np.ones(6, dtype=bool))
    quality: np.ndarray | None = None
    image_t: float | None = None
    q_dot: np.ndarray | None = None


@dataclass
class _GoalFields:
    """The fields of :class:`Goal`, which :class:`GoalBatch` has with a row axis."""

    normals: np.ndarray | None = None
    lines: np.ndarray | None = None
    directions: np.ndarray | None = None
    lengths: np.ndarray | None = None
    rotation: np.ndarray | None = None
    translation: np.ndarray | None = None
    edge_visible: np.ndarray | None = None


@dataclass
class Goal(_GoalFields):
    """The desired configuration, as features and (for the baselines) as a pose.

    Attributes:
        normals: (6, 2, 3) desired edge normals (from the image at the goal).
        lines: (6, 2, 3) desired image lines (perspective camera).
        directions: (6, 3) desired leg directions.
        lengths: (6,) desired leg lengths in the nominal model [m].
        rotation: (3, 3) desired platform orientation in the nominal base frame.
        translation: (3,) desired platform position in the nominal base frame [m].
        edge_visible: (6, 2) which desired edges were observed.
    """


@dataclass
class ControllerContext:
    """What the user knows or calibrated (estimates, never the truth).

    Attributes:
        base_points: (6, 3) estimated base points ``A_i`` in the camera frame [m].
        geometry: Nominal geometry (base frame), with strokes and speed limit.
        camera: The estimated camera (intrinsics and ``camera_from_base``), or None.
        dt: Control period [s].
        goal: The desired features / pose.
        stroke_margin: Distance kept from the stroke limits by limit-aware laws [m].
        reference: A trajectory task's reference (a
            :class:`hexapod.trajectory.PoseTrajectory` in the base frame: pose, twist and
            acceleration at any time), or None for a fixed goal
            (:mod:`controllers.tracking`).
    """

    base_points: np.ndarray
    geometry: HexapodGeometry
    camera: Any
    dt: float
    goal: Goal
    stroke_margin: float = 0.002
    reference: Any = None

    @property
    def stroke(self) -> tuple[float, float]:
        """(q_min, q_max) [m]."""
        return self.geometry.stroke

    @property
    def max_speed(self) -> float:
        """Leg speed limit [m/s]."""
        return self.geometry.max_speed


@dataclass
class Command:
    """A controller's output for one step, with its diagnostics.

    What it commands is :attr:`actuation`: leg velocities (the default; ``velocities``)
    or leg forces (``forces``, with ``velocities`` zeros); build a force command with
    :meth:`of_forces`. :attr:`values` is the command of its kind.

    Attributes:
        velocities: (6,) leg velocity command [m/s]; zeros when the controller refuses
            or commands forces. Not limited to the robot's leg speed (the QP and
            predictive laws bound it themselves; the backends and the simulator clamp
            every command).
        twist: (6,) platform twist ``(v, w)`` in the camera frame, if the law computes one.
        error: The stacked task error.
        error_norm: Its Euclidean norm.
        rank: Rank of the (stacked) interaction matrix.
        condition: Its condition number.
        features_used: Number of scalar feature rows used.
        active_constraints: Names of the active constraints (QP laws).
        reason: Why the command is zero (None when the command is valid).
        notes: Other diagnostics (e.g. "using 10 of 12 edges").
        actuation: What the command sets (:class:`~hexapod.actuation.Actuation`).
        forces: (6,) leg force command [N] of a force command (zeros when refused),
            else None.
    """

    velocities: np.ndarray
    twist: np.ndarray | None = None
    error: np.ndarray = field(default_factory=lambda: np.zeros(0))
    error_norm: float = 0.0
    rank: int = 0
    condition: float = float("nan")
    features_used: int = 0
    active_constraints: list[str] = field(default_factory=list)
    reason: str | None = None
    notes: list[str] = field(default_factory=list)
    actuation: Actuation = Actuation.VELOCITY
    forces: np.ndarray | None = None

    @property
    def ok(self) -> bool:
        """True when the controller produced a movement command."""
        return self.reason is None

    @property
    def values(self) -> np.ndarray:
        """(6,) the command of its kind, velocities [m/s] or forces [N]."""
        if self.actuation is Actuation.FORCE:
            return np.zeros(6) if self.forces is None else self.forces
        return self.velocities

    @staticmethod
    def of_forces(forces: np.ndarray, **diagnostics: Any) -> Command:
        """A leg-force command [N] (``velocities`` zeros), with its diagnostics."""
        return Command(np.zeros(6), actuation=Actuation.FORCE,
                       forces=np.asarray(forces, dtype=float), **diagnostics)

    @staticmethod
    def refuse(reason: str, error: np.ndarray | None = None,
               actuation: Actuation = Actuation.VELOCITY) -> Command:
        """A zero command with its reason (never NaN)."""
        err = np.zeros(0) if error is None else np.nan_to_num(error)
        return Command(np.zeros(6), reason=reason, error=err,
                       error_norm=float(np.linalg.norm(err)), actuation=actuation,
                       forces=np.zeros(6) if actuation is Actuation.FORCE else None)


@dataclass
class ObservationBatch:
    """Observations of several trials at one period, for :meth:`Controller.step_batch`:
    the :class:`Observation` fields (but ``quality``) with a leading trial axis (n, ...),
    a field None for every row or none, and

    Attributes:
        trials: (n,) integer indices of the trials, into the contexts given to
            ``reset_batch``, each at most once.
    """

    trials: np.ndarray
    t: np.ndarray
    lengths: np.ndarray
    normals: np.ndarray | None
    lines: np.ndarray | None
    directions: np.ndarray | None
    edge_visible: np.ndarray
    direction_visible: np.ndarray
    image_t: np.ndarray | None = None
    q_dot: np.ndarray | None = None
    #: The observation a batch of one was made of (:meth:`of`), else None (not an init
    #: field: a batch derived with ``dataclasses.replace`` does not keep it).
    single: Observation | None = field(default=None, init=False, repr=False, compare=False)

    def __len__(self) -> int:
        return len(self.trials)

    def shape_problem(self) -> str | None:
        """Why these arrays are not ``len(trials)`` rows of an observation's shapes (the
        field, its shape and the one expected) or the trials not distinct integers, or
        None."""
        if np.ndim(self.trials) != 1:
            return f"observations.trials of shape {np.shape(self.trials)}, expected (n,)"
        n = len(self.trials)
        trials = np.asarray(self.trials)
        if n and trials.dtype.kind not in "iu":
            return f"observations.trials of dtype {trials.dtype}, expected integers"
        if n > 1 and not (trials[1:] > trials[:-1]).all():  # (the loop's rows increase)
            values, counts = np.unique(trials, return_counts=True)
            if (counts > 1).any():
                return (f"observations.trials repeat trial {values[counts > 1][0].item()}: each "
                        "row of a batch is another trial")
        for name, row in _ROW_SHAPES:
            value = getattr(self, name)
            if value is not None and np.shape(value) != (n, *row):
                return f"observations.{name} of shape {np.shape(value)}, expected {(n, *row)}"
        return None

    def write_rows(self, rows: Any, rates: bool = True) -> None:
        """Copy the batch into a one-step C's arrays (:class:`hexapod.c_step.RowArrays`):
        its ``trials``, times ``t`` [s], ``lengths`` into ``q`` [m] and, with ``rates``,
        ``q_dot`` into ``qd`` [m/s] (assignments: a third of ``np.copyto``'s cost, which a
        per-trial step pays every period; :meth:`shape_problem` checked the trials are
        integers)."""
        rows.trials[...] = self.trials
        rows.t[...] = self.t
        rows.q[...] = self.lengths
        if rates:
            rows.qd[...] = self.q_dot

    def item(self, k: int) -> Observation:
        """The observation of row ``k`` (views of the batch arrays; for a batch made of
        one observation by :meth:`of`, that observation)."""
        if self.single is not None:
            return self.single
        return Observation(
            t=float(self.t[k]), lengths=self.lengths[k],
            normals=None if self.normals is None else self.normals[k],
            lines=None if self.lines is None else self.lines[k],
            directions=None if self.directions is None else self.directions[k],
            edge_visible=self.edge_visible[k], direction_visible=self.direction_visible[k],
            image_t=None if self.image_t is None else float(self.image_t[k]),
            q_dot=None if self.q_dot is None else self.q_dot[k])

    def rows(self, rows: np.ndarray) -> ObservationBatch:
        """The batch of the rows ``rows`` (copies)."""
        def take(value: Any) -> Any:
            return None if value is None else np.asarray(value)[rows]

        return ObservationBatch(**{name: take(getattr(self, name)) for name in _BATCH_FIELDS})

    @staticmethod
    def of(obs: Observation) -> ObservationBatch | None:
        """The batch of one observation (trial 0; views of its arrays in the common case,
        else converted and checked by :func:`_one_row`), or None when it is malformed (then
        :meth:`Controller.step` refuses it with the reason)."""
        lengths, edges, seen = obs.lengths, obs.edge_visible, obs.direction_visible
        normals, lines, directions, q_dot = obs.normals, obs.lines, obs.directions, obs.q_dot
        try:
            if (type(lengths) is _ARRAY and lengths.shape == (6,) and lengths.dtype == _FLOAT
                    and type(edges) is _ARRAY and edges.shape == (6, 2)
                    and edges.dtype == _BOOL
                    and type(seen) is _ARRAY and seen.shape == (6,) and seen.dtype == _BOOL
                    and (normals is None or (type(normals) is _ARRAY
                                             and normals.shape == (6, 2, 3)
                                             and normals.dtype == _FLOAT))
                    and (lines is None or (type(lines) is _ARRAY and lines.shape == (6, 2, 3)
                                           and lines.dtype == _FLOAT))
                    and (directions is None or (type(directions) is _ARRAY
                                                and directions.shape == (6, 3)
                                                and directions.dtype == _FLOAT))
                    and (q_dot is None or (type(q_dot) is _ARRAY and q_dot.shape == (6,)
                                           and q_dot.dtype == _FLOAT))):
                rows: list[np.ndarray | None] = [  # the common case: views
                    lengths[None], edges[None], seen[None],
                    None if normals is None else normals[None],
                    None if lines is None else lines[None],
                    None if directions is None else directions[None],
                    None if q_dot is None else q_dot[None]]
            else:  # convert and check every field
                rows = [_one_row(v, shape, kind) for v, shape, kind in zip(
                    (lengths, edges, seen, normals, lines, directions, q_dot), _SHAPES, _KINDS,
                    strict=True)]
            t = np.array([float(obs.t)])
            image_t = None if obs.image_t is None else np.array([float(obs.image_t)])
        except (TypeError, ValueError):
            return None
        b_lengths, b_edges, b_seen, b_normals, b_lines, b_directions, b_q_dot = rows
        if b_lengths is None or b_edges is None or b_seen is None:
            return None
        batch = ObservationBatch(TRIAL_ZERO, t, b_lengths, b_normals, b_lines, b_directions,
                                 b_edges, b_seen, image_t, b_q_dot)
        batch.single = obs
        return batch


#: The shape of one row of each array field of :class:`ObservationBatch`.
_ROW_SHAPES = (("t", ()), ("lengths", (6,)), ("normals", (6, 2, 3)), ("lines", (6, 2, 3)),
               ("directions", (6, 3)), ("edge_visible", (6, 2)), ("direction_visible", (6,)),
               ("image_t", ()), ("q_dot", (6,)))
#: The init fields of :class:`ObservationBatch`.
_BATCH_FIELDS = tuple(f.name for f in fields(ObservationBatch) if f.init)
#: The shapes and kinds of the fields of one observation, in :meth:`ObservationBatch.of`'s
#: order (lengths, edge_visible, direction_visible, normals, lines, directions, q_dot).
_SHAPES = ((6,), (6, 2), (6,), (6, 2, 3), (6, 2, 3), (6, 3), (6,))
_KINDS = (np.float64, np.bool_, np.bool_, np.float64, np.float64, np.float64, np.float64)
_ARRAY, _FLOAT, _BOOL = np.ndarray, np.dtype(np.float64), np.dtype(np.bool_)


def _one_row(value: Any, shape: tuple[int, ...], kind: Any) -> np.ndarray | None:
    """``value`` as an array of ``shape`` with a leading axis of one (a view when it is
    one already), None for None; ValueError for another shape."""
    if value is None:
        return None
    arr = value if type(value) is np.ndarray and value.dtype == kind else np.asarray(value,
                                                                                    kind)
    if arr.shape != shape:
        raise ValueError(f"expected shape {shape}, got {arr.shape}")
    return arr[None]  # type: ignore[no-any-return]


#: The trials of a batch of one, ``[0]`` (read-only; sliced ``[:0]`` for none).
TRIAL_ZERO = np.zeros(1, dtype=int)
TRIAL_ZERO.flags.writeable = False


@dataclass
class GoalBatch(_GoalFields):
    """Goals of several trials: the :class:`Goal` fields with a leading row axis (m, ...),
    a field None when no row has it, for ``retarget_batch(trials, goals)`` (the goal of
    each period of a trajectory task, :mod:`controllers.tracking`)."""

    def __len__(self) -> int:
        for name in GOAL_FIELDS:
            value = getattr(self, name)
            if value is not None:
                return len(value)
        return 0

    def item(self, k: int) -> Goal:
        """The goal of row ``k`` (views of the batch arrays)."""
        return Goal(**{name: None if getattr(self, name) is None else getattr(self, name)[k]
                       for name in GOAL_FIELDS})

    @staticmethod
    def of(goal: Goal) -> GoalBatch:
        """A batch of one goal (its arrays with a leading axis of one)."""
        return GoalBatch(**{name: None if getattr(goal, name) is None
                            else np.asarray(getattr(goal, name))[None]
                            for name in GOAL_FIELDS})


#: The fields of :class:`Goal` (and of :class:`GoalBatch`, which has them with a row axis).
GOAL_FIELDS = tuple(f.name for f in fields(Goal))


@dataclass
class CommandBatch:
    """The commands of :meth:`Controller.step_batch`, one row per observation row.

    Attributes:
        velocities: (n, 6) leg velocities [m/s] (zeros where refused or for forces;
            never NaN).
        error_norm: (n,) norm of each task error.
        reasons: (n,) why a command is zero (None where it is valid).
        actuation: What every row commands (one kind per batch).
        forces: (n, 6) leg forces [N] of a force batch (zeros where refused), else None.
        commands: (n,) the full :class:`Command` of the rows stepped one by one (None
            elsewhere, or None when no row was).
    """

    velocities: np.ndarray
    error_norm: np.ndarray
    reasons: list[str | None]
    actuation: Actuation = Actuation.VELOCITY
    forces: np.ndarray | None = None
    commands: list[Command | None] | None = None

    @property
    def values(self) -> np.ndarray:
        """(n, 6) the commands of their kind, velocities [m/s] or forces [N]."""
        if self.actuation is Actuation.FORCE:
            return np.zeros_like(self.velocities) if self.forces is None else self.forces
        return self.velocities

    @staticmethod
    def zeros(n: int, actuation: Actuation = Actuation.VELOCITY) -> CommandBatch:
        """``n`` rows of zero commands, zero norms and no reasons, to be filled."""
        forces = np.zeros((n, 6)) if actuation is Actuation.FORCE else None
        return CommandBatch(np.zeros((n, 6)), np.zeros(n), [None] * n, actuation, forces)

    @staticmethod
    def of_row(command: Command, actuation: Actuation) -> CommandBatch:
        """A batch of one row, ``command`` (of ``actuation``, checked by the caller): the
        arrays :meth:`zeros` and :meth:`put` would hold, without their zeros."""
        velocities = np.empty((1, 6))
        velocities[0] = command.velocities
        forces = None
        if actuation is Actuation.FORCE:
            forces = np.empty((1, 6))
            forces[0] = command.values
        error_norm = np.empty(1)
        error_norm[0] = command.error_norm
        return CommandBatch(velocities, error_norm, [command.reason], actuation, forces,
                            [command])

    def put(self, k: int, command: Command) -> None:
        """Set row ``k`` to a per-trial :class:`Command` (of the batch's actuation), kept
        for :meth:`command`.

        Raises:
            ActuationError: The command is of another kind than the batch.
        """
        if command.actuation is not self.actuation:
            from hexapod.actuation import check_actuation

            check_actuation(command.actuation, (self.actuation,),
                            f"a batch of {self.actuation.quantity}", "row " + str(k))
        self.velocities[k] = command.velocities
        if self.forces is not None:
            self.forces[k] = command.values
        self.error_norm[k] = command.error_norm
        self.reasons[k] = command.reason
        if self.commands is None:
            self.commands = [None] * len(self.reasons)
        self.commands[k] = command

    def command(self, k: int) -> Command:
        """Row ``k`` as a :class:`Command`: its command from the arrays, with the
        diagnostics of the one :meth:`put` there (a row computed as arrays has only its
        norm and reason)."""
        kept = None if self.commands is None else self.commands[k]
        if kept is not None:  # the arrays hold the command (a wrapper may have added to it)
            kept.velocities = self.velocities[k].copy()
            if self.forces is not None:
                kept.forces = self.forces[k].copy()
            return kept
        reason = self.reasons[k]
        forces = None if self.forces is None else self.forces[k].copy()
        return Command(self.velocities[k].copy(), error_norm=float(self.error_norm[k]),
                       reason=reason, actuation=self.actuation, forces=forces)


def observation_problem(obs: Observation, features: frozenset[str],
                        stroke: tuple[float, float] | None = None) -> str | None:
    """Return why an observation cannot be used (None if it can): what every controller's
    ``step`` checks before computing.

    Checks that the needed fields exist with the right shapes, and that every
    value flagged visible is finite; a malformed observation (wrong types) is a reason too.
    With the nominal robot's ``stroke`` [m], lengths no leg of it can have (millimetres
    for metres: :func:`controllers.plausible.implausible_lengths`) are a reason.
    """
    try:
        q = np.asarray(obs.lengths, dtype=float)
        if q.shape != (6,):
            return f"lengths: expected 6 values, got shape {q.shape}"
        bad = np.flatnonzero(~np.isfinite(q))
        if len(bad):
            return f"lengths: leg {int(bad[0])} is {q[bad[0]]} (not finite)"
        if stroke is not None and (wrong := implausible_lengths(q, stroke)) is not None:
            return f"lengths: {wrong}"
        if not np.isfinite(obs.t):
            return f"time is {obs.t} (not finite)"
        for name, shape, mask_field in FEATURE_FIELDS:
            if name not in features:
                continue
            value = getattr(obs, name)
            if value is None:
                return f"{name}: not measured by this sensor"
            arr = np.asarray(value, dtype=float)
            if arr.shape != shape:
                return f"{name}: expected shape {shape}, got {arr.shape}"
            visible = np.asarray(getattr(obs, mask_field), dtype=bool)
            bad_idx = np.argwhere(visible & ~np.all(np.isfinite(arr), axis=-1))
            if len(bad_idx):
                return (f"{name}: visible feature {tuple(int(x) for x in bad_idx[0])} is "
                        "not finite")
    except (TypeError, ValueError) as exc:
        return f"malformed observation: {exc}"
    return None
