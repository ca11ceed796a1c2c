"""Computed torque in the space of the leg features: ``leg-edge-ctc`` (Özgür, Andreff and
Martinet, ICRA 2011) and ``leg-direction-ctc``.

The feature error (the leg-edge task ``e = n x n*``, or the leg-direction task
``e = u x u*``, :mod:`controllers.tasks`, camera frame) is given the second-order
dynamics ``e_ddot + 2 zeta omega_n e_dot + omega_n^2 e = 0`` through the NOMINAL inverse
dynamic model (:class:`~controllers.solvers.computed_torque.ComputedTorqueSolver`, least
squares over the rows seen). Models, never the world's truth:

- the task's state: the edge normals (or directions) the camera sees, the ESTIMATED base
  points ``A_i`` (context, camera frame) and the encoder lengths;
- the pose for the dynamic model and the task's frame: the nominal forward kinematics
  of the encoders; the twist ``K^-1 q_dot`` (nominal ``K``), brought to the camera frame
  through the ESTIMATED camera pose;
- the reference ``s*(t)``: the features the estimated camera would see of the NOMINAL
  robot along the reference pose trajectory (``context.reference``, or a quintic line
  from the first measured pose to ``goal.rotation``/``goal.translation``), anchored at the
  TAUGHT goal features as :mod:`controllers.tracking` does (``s* = s_taught +
  s_model(t) - s_model(end)``, renormalised): the path's end is the taught goal, reached
  whatever the calibration error; without a smooth goal, ``s*`` is the taught goal.

Only legs whose two edges (or whose direction) are seen take part; fewer than six
independent rows give a refusal with the reason.
"""

from __future__ import annotations

import numpy as np

from controllers.base import ControllerContext, Goal, Observation, ObservationBatch
from controllers.cartesian_ctc import directions_seen, every_seen
from controllers.control_grid import chunks, grid_step, grid_times, model_world
from controllers.exceptions import ContextError
from controllers.feature_grid import DUMMY, features_motion, grid_rows, sanitised
from controllers.task_ctc import CompiledTaskStep, TaskComputedTorque
from controllers.task_ctc_inputs import camera_and_base_points, goal_pose_of
from controllers.task_ctc_rows import TaskRows
from controllers.tasks.feature_kind import BuiltinFeature
from controllers.tasks.leg_direction import LEG_DIRECTIONS
from controllers.tasks.leg_edge import EDGE_NORMALS
from hexapod.kinematics import Transform
from vision.legs import directions_from_edges

#: The normal standing in for a hidden leg's edges (read only).
_DUMMY_NORMAL = np.cross(DUMMY, [1.0, 0.0, 0.0])
_DUMMY_NORMAL.flags.writeable = False
#: Every row of the edge task (36) and of the direction task (18) (read only).
_EVERY_EDGE = np.ones(36, bool)
_EVERY_EDGE.flags.writeable = False
_EVERY_LEG = np.ones(18, bool)
_EVERY_LEG.flags.writeable = False
#: Stands for the directions of the edge normals, computed by the compiled step.
_OF_NORMALS = np.full((6, 3), np.nan)


class FeatureCTC(TaskComputedTorque):
    """Computed torque on a leg-feature task (see the module docstring).

    Args:
        natural_frequency: Natural frequency ``f_n`` [Hz] of the error's second-order
            response (default 2 Hz: ``omega_n dt = 0.25`` at 20 ms).
        damping: Damping ratio ``zeta`` of that response (default 1).
        smooth_goal: Reach a fixed goal along the features of a quintic line (False: the
            taught features as a step).
    """

    #: The built-in feature object (its goal field holds the taught features; the
    #: reference and the task are its own).
    observed_feature: BuiltinFeature = EDGE_NORMALS
    #: The mask of every task row (read only): :meth:`compiled_features` gives this very
    #: array when every leg is seen.
    every_rows: np.ndarray = _EVERY_EDGE

    def prepare(self, context: ControllerContext) -> None:
        """Check the estimated camera pose and base points.

        Raises:
            ContextError: Naming the missing or bad field.
        """
        cam, A = camera_and_base_points(self.name, context)
        self._frame = cam
        self._A = A
        #: The reference's grid (:meth:`reference_grid`).
        self._grid: tuple[object, np.ndarray, np.ndarray, np.ndarray] | None = None

    def take_goal(self, goal: Goal) -> None:
        """The taught features (``goal.normals`` or ``goal.directions``).

        Raises:
            ContextError: They are missing, none is finite, or (``smooth_goal``) the goal
                has no pose of the robot (the smooth line's end).
        """
        value = getattr(goal, self.key)
        if value is None:
            raise ContextError(self.name, f"goal.{self.key}", "missing (the taught features)")
        taught = np.asarray(value, dtype=float)
        if taught.shape != self.observed_feature.shape:
            raise ContextError(self.name, f"goal.{self.key}", f"expected shape "
                               f"{self.observed_feature.shape}, got {taught.shape}")
        if not np.isfinite(taught).all(axis=-1).any():  # (it refused every step after)
            raise ContextError(self.name, f"goal.{self.key}", "no finite desired feature: "
                               "every taught feature hidden (a goal image where no leg was "
                               "seen)")
        if self.smooth_goal and self.context is not None:  # the smooth line's end, read now
            goal_pose_of(self.name, goal, self.context.geometry)  # (not at the first step)
        self._taught = taught
        self._grid = None  # the reference's features are anchored at the taught ones
        self.reference_changed()

    @property
    def taught(self) -> np.ndarray:
        """The taught features (``goal.normals`` or ``goal.directions``, as given)."""
        return self._taught

    @property
    def camera_frame(self) -> Transform:
        """The estimated camera pose (``camera_from_base``)."""
        return self._frame

    def goal_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """The goal pose, the end of the smooth line (nominal base frame)."""
        assert self.context is not None
        return goal_pose_of(self.name, self.context.goal, self.context.geometry)

    def compiled_features(self, observation: Observation
                          ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray] | str:
        """The directions (6, 3) seen, the normals (6, 2, 3) or None, and the rows to use
        (:attr:`every_rows` when every leg is seen), or why there are none."""
        raise NotImplementedError

    @property
    def key(self) -> str:
        """The goal (and observation) field of the taught features."""
        assert self.observed_feature.field is not None
        return self.observed_feature.field

    def _grid_index(self, tr: float) -> int | None:
        """The row of ``tr`` [s] in the reference's control grid (built on first use), or
        None off the grid."""
        ctx, ref = self.context, self.reference
        assert ctx is not None and ref is not None
        k = grid_step(tr, float(ctx.dt))
        if k < 0:
            return None
        grid = self._grid
        if grid is None or grid[0] is not ref:
            grid = self.reference_grid()
        return min(k, len(grid[1]) - 1)

    def reference_grid(self) -> tuple[object, np.ndarray, np.ndarray, np.ndarray]:
        """The reference's control grid ``k dt`` to a step past its end (built once per
        reference, or by :meth:`build_grids`): the reference, what
        :meth:`compiled_reference` gives there (n, 3 m) (:meth:`feature_rows` sanitised),
        the rows known (n, m) and whether they all are (n,)."""
        if self._grid is None or self._grid[0] is not self.reference:
            self._grid = (self.reference, *grid_rows(*self.motion_and_seen(
                self.grid_times())))
        return self._grid

    def grid_times(self) -> np.ndarray:
        """The control grid [s] (:func:`controllers.control_grid.grid_times`)."""
        ctx, ref = self.context, self.reference
        assert ctx is not None and ref is not None
        return grid_times(ref.duration, float(ctx.dt))

    def build_grids(self, laws: list[TaskComputedTorque]) -> None:
        """:meth:`TaskComputedTorque.build_grids`: the grids of the laws whose features
        are this class's model (:meth:`motion_and_seen`), one pass per model world
        (camera and robot): rows are independent, each grid holds its own numbers."""
        ours: list[FeatureCTC] = []
        contexts: list[ControllerContext] = []
        for law in laws:
            if (isinstance(law, FeatureCTC) and law.context is not None
                    and law.reference is not None
                    and type(law).motion_and_seen is _MOTION_AND_SEEN):
                ours.append(law)
                contexts.append(law.context)
        for members in chunks([model_world(c) for c in contexts], None):
            group = [ours[k] for k in members]
            times = [law.grid_times() for law in group]
            rows, known, every = grid_rows(*features_motion(group, times))
            start = 0
            for law, t in zip(group, times, strict=True):
                end = start + len(t)
                law.take_grid(rows[start:end], known[start:end], every[start:end])
                start = end

    def take_grid(self, rows: np.ndarray, known: np.ndarray, every: np.ndarray) -> None:
        """Take the grid of the reference built by :meth:`build_grids` (the parts of
        :meth:`reference_grid` after the reference)."""
        self._grid = (self.reference, rows, known, every)

    def feature_rows(self, times: np.ndarray) -> np.ndarray:
        """(m, 3, n) the anchored model features at ``times`` (m,) [s], their rate and
        acceleration; NaN where the model's camera does not see the feature
        (:meth:`motion_and_seen`)."""
        out, seen = self.motion_and_seen(times)
        return np.where(seen[:, None, :], out, np.nan)

    def motion_and_seen(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(m, 3, n) the anchored model features at ``times`` (m,) [s], their rate and
        acceleration, and (m, n) where the model's camera sees them."""
        return features_motion([self], [times])

    def compiled_reference(self, tr: float) -> tuple[np.ndarray, np.ndarray | None]:
        """(3 m,) the anchored model features at ``tr`` [s], their rate and acceleration
        (:mod:`controllers.solvers.reference_motion`) for the compiled step, the features
        the model's camera does not see (NaN) replaced by finite stand-ins, and the rows
        known (None: all). The control grid ``k dt`` is computed once per reference (one
        batched call, :meth:`reference_grid`); other instants on demand."""
        i = self._grid_index(tr)
        if i is None:
            return sanitised(self.feature_rows(np.array([tr]))[0])
        assert self._grid is not None
        return self._grid[1][i], None if self._grid[3][i] else self._grid[2][i]

    def _taught_reference(self) -> tuple[np.ndarray, np.ndarray | None]:
        """The taught features at rest, as :meth:`compiled_reference`."""
        taught = self._taught.ravel()
        return sanitised(np.stack([taught, np.zeros_like(taught), np.zeros_like(taught)]))

    def compiled_constants(self, step: CompiledTaskStep) -> None:
        """The estimated base points (camera frame) and the camera frame."""
        step.set("base", self._A.ravel())
        step.set("frame", np.concatenate([self._frame.rotation.ravel(),
                                          self._frame.translation]))

    def compiled_inputs(self, step: CompiledTaskStep, observation: Observation, tr: float,
                        q: np.ndarray) -> tuple[np.ndarray | None, str | None] | str:
        """The features seen and the rows to use (None: every row, all seen and known;
        fewer than six: the step's status says so); the reference at ``tr``; or why
        there are no features."""
        feats = self.compiled_features(observation)
        if isinstance(feats, str):
            return feats
        u, normals, rows = feats
        row, inputs = step.row, step.inputs.slices  # (the layout's slices: a dict)
        if normals is None:
            row[inputs["directions"]] = u.ravel()
        elif u is _OF_NORMALS:  # the compiled step takes the directions of the normals
            row[inputs["normals"]] = normals.ravel()
            row[inputs["of_normals"]] = 1.0
        else:
            row[inputs["normals"]] = normals.ravel()
            row[inputs["directions"]] = u.ravel()
            row[inputs["of_normals"]] = 0.0
        if self.reference is None:
            ref, known = self._taught_reference()
        else:
            ref, known = self.compiled_reference(tr)
        every: np.ndarray | None = None
        if known is None and rows is self.every_rows:
            row[inputs["mask"]] = 1.0
        else:
            if known is not None:  # a feature the model's camera does not see leaves its rows
                rows = rows & known
            row[inputs["mask"]] = rows.astype(float)
            every = rows
        row[inputs["reference_features"]] = ref
        return every, None

    def batch_grid(self) -> tuple[np.ndarray, np.ndarray | None] | None:
        """The sanitised reference on the control grid (:meth:`reference_grid`) and the
        grid steps whose rows are all known."""
        if self.reference is None:
            return None
        _, rows, _, every = self.reference_grid()
        return rows, every

    def retarget_trial(self, goal: Goal) -> None:
        """A new fixed goal; with a reference the taught features anchor it."""
        super().retarget_trial(goal)
        if self.context is not None and self.context.reference is not None:
            self.take_goal(goal)


#: The features' model of the built-in laws (:meth:`FeatureCTC.build_grids` builds the
#: grids of those that keep it; a law of its own, or one replaced, builds its own).
_MOTION_AND_SEEN = FeatureCTC.motion_and_seen


class LegEdgeCTC(FeatureCTC):
    """Computed torque on the leg edges (edge normals, ``e = n x n*``; see the module
    docstring)."""

    name = "leg-edge-ctc"
    features = frozenset({"lengths", EDGE_NORMALS.field})
    observed_feature = EDGE_NORMALS
    compiled_kind = EDGE_NORMALS
    batch_measurement = ("normals", "edge_visible", "normals", "of_normals")

    def features_seen(self, observation: Observation
                      ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray] | str:
        """:meth:`compiled_features` with every check (hidden or non-finite legs)."""
        if observation.normals is None:
            return "needs the edge normals (Observation.normals)"
        n = np.asarray(observation.normals, dtype=float)
        visible = observation.edge_visible
        if (visible is None or np.all(visible)) and np.isfinite(n).all():
            u = directions_from_edges(n)  # every edge seen: the general path's result
            if np.isfinite(u).all():
                return u, n, _EVERY_EDGE
        u, legs = directions_seen(None, n, None, visible)
        legs &= np.all(np.isfinite(n), axis=(-2, -1))
        u = np.where(legs[:, None], u, DUMMY)
        n = np.where(legs[:, None, None], n, _DUMMY_NORMAL)
        return u, n, np.repeat(legs, 6)

    def compiled_features(self, observation: Observation
                          ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray] | str:
        """Every edge seen: the normals, the directions left to the compiled step
        (``_OF_NORMALS``); else :meth:`features_seen`."""
        n = every_seen(observation.normals, observation.edge_visible)
        return self.features_seen(observation) if n is None else (_OF_NORMALS, n, _EVERY_EDGE)

    def batch_partly_seen(self, rows_batch: TaskRows, step: CompiledTaskStep,
                          X: np.ndarray, observations: ObservationBatch,
                          candidates: np.ndarray
                          ) -> dict[int, tuple[np.ndarray | None, str | None]]:
        """:meth:`features_seen` of the candidate rows with a hidden edge, all at once
        (the same operations on each row: the same numbers)."""
        if observations.normals is None or observations.edge_visible is None:
            return {}
        j = np.flatnonzero(candidates)
        visible = np.asarray(observations.edge_visible, dtype=bool)[j].reshape(-1, 6, 2)
        hidden = ~visible.all(axis=(1, 2))
        j, visible = j[hidden], visible[hidden]
        if not len(j):
            return {}
        n = np.asarray(observations.normals, dtype=float)[j].reshape(-1, 6, 2, 3)
        with np.errstate(invalid="ignore", divide="ignore"):
            u = directions_from_edges(n)  # directions_seen's, then features_seen's checks
        legs = (np.all(visible, axis=-1) & np.all(np.isfinite(u), axis=-1)
                & np.all(np.isfinite(n), axis=(-2, -1)))
        u = np.where(legs[..., None], u, DUMMY)
        n = np.where(legs[..., None, None], n, _DUMMY_NORMAL)
        X[j, step.inputs["normals"]] = n.reshape(len(j), -1)
        X[j, step.inputs["directions"]] = u.reshape(len(j), -1)
        X[j, step.inputs.index("of_normals")] = 0.0
        return {k: (u, None) for k, u in zip(j.tolist(), np.repeat(legs, 6, axis=1),
                                             strict=True)}


class LegDirectionCTC(FeatureCTC):
    """Computed torque on the leg directions (``e = u x u*``; see the module docstring)."""

    name = "leg-direction-ctc"
    features = frozenset({"lengths", LEG_DIRECTIONS.field})
    observed_feature = LEG_DIRECTIONS
    compiled_kind: BuiltinFeature | None = LEG_DIRECTIONS
    every_rows = _EVERY_LEG
    batch_measurement = ("directions", "direction_visible", "directions", None)

    def features_seen(self, observation: Observation
                      ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray] | str:
        """:meth:`compiled_features` with every check (hidden or non-finite legs)."""
        u, legs = directions_seen(observation.directions, observation.normals,
                                  observation.direction_visible, observation.edge_visible)
        if legs.all():
            return u, None, self.every_rows
        u = np.where(legs[:, None], u, DUMMY)
        return u, None, np.repeat(legs, self.every_rows.size // 6)

    def compiled_features(self, observation: Observation
                          ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray] | str:
        """Every direction given and seen: them (:meth:`features_seen`'s result without
        its general checks); else :meth:`features_seen`."""
        u = every_seen(observation.directions, observation.direction_visible)
        return self.features_seen(observation) if u is None else (u, None, self.every_rows)
