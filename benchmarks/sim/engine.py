"""The batched engine: every trial of a work unit stepped as arrays.

The per-trial path (:func:`benchmarks.sim.stepper._run_group`) steps the trials that
share a world together but crosses Python for every trial at every period: one
controller object, one :class:`~controllers.base.Observation`, one ``step`` call each.
Here the whole unit is one set of arrays, whatever their worlds (a calibration error
gives each trial its own robot and camera):

- the world: the legs, edges and visibility of every trial in one C call
  (:func:`vision.fast_observe.observe_batch`, each trial with its own robot, camera and
  pose); the scenario's noise per trial from the trial's own generator
  (:func:`benchmarks.sim.sensors.noisy_features`); the forward kinematics of the TRUE
  robots in one compiled batch, each trial with its own joint centres;
- the controller: one ``step_batch`` over the rows of an
  :class:`~controllers.base.ObservationBatch` (the built-in laws loop their compiled
  cores in C; a plugin without ``step_batch`` is looped trial by trial,
  :class:`controllers.batch.PerTrialLoop`);
- the bookkeeping: :class:`benchmarks.sim.book.Book`, shared with the per-trial path.

Every trial keeps its random streams (seeded from the scenario seed and the trial
index), so the results are those of the per-trial path, row for row (tested). The
engine applies to the geometric sensor with the simulated backend; images (rendered
per trial) and real-time backends take the per-trial path.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from benchmarks.exceptions import BatchFailedError
from benchmarks.sim.actuation import (
    drive_plant,
    require_actuation,
    require_batch,
    world_actuation,
)
from benchmarks.sim.book import Book, TrialResult, failure_row
from benchmarks.sim.clock import clocked_measure, make_clock
from benchmarks.sim.plant import make_plant
from benchmarks.sim.reference import Targets, task_batch_controller
from benchmarks.sim.sensors import GeometricSensor, draws_noise, noisy_features, trial_goal
from benchmarks.sim.world import TrialSetup, trial_rng
from benchmarks.study.scenario import Scenario
from controllers.base import Goal, ObservationBatch
from hexapod.actuation import Actuation
from hexapod.kinematics import inverse_kinematics
from hexapod.se3 import pose_error
from vision.fast_observe import WorldParams, observe_batch
from vision.legs import LegObservation

log = logging.getLogger(__name__)


class BatchSensor:
    """The geometric sensor over a batch of trials, each in its own world.

    Args:
        sc: The scenario (its noise).
        setups: The trials (their worlds and the estimated camera, the same for all).
    """

    def __init__(self, sc: Scenario, setups: list[TrialSetup]) -> None:
        self.sc = sc
        self.setups = setups
        worlds = [s.world for s in setups]
        self.params = WorldParams.from_worlds([w.geometry for w in worlds],
                                              [w.camera for w in worlds])
        self.estimated = setups[0].estimated_camera
        # rows of one camera object go through its methods together, as in the per-trial path
        ids: dict[int, int] = {}
        self._camera_group = np.array([ids.setdefault(id(w.camera), len(ids)) for w in worlds])
        self._group_camera = {g: worlds[k].camera for k, g in
                              reversed(list(enumerate(self._camera_group)))}

    def measure(self, rotations: np.ndarray, translations: np.ndarray, items: np.ndarray,
                rngs: Sequence[Any], apply_noise: bool = True) -> dict[str, Any]:
        """Features of the trials ``items`` at their true poses (one generator each, see
        :func:`rows_generators`)."""
        obs = observe_batch(self.params, rotations, translations, items)
        groups = self._camera_group[items]
        cameras = [(np.flatnonzero(groups == g), self._group_camera[int(g)])
                   for g in np.unique(groups)]

        def item(k: int) -> tuple[LegObservation, Any]:
            world = self.setups[int(items[k])].world
            return _leg_observation(obs, k, world.geometry.leg_radius,
                                    float(self.params.platform_radius[items[k]])), world.camera

        return noisy_features(self.sc, obs.normals, obs.edge_visible, rngs, apply_noise,
                              self.estimated, cameras, item)


def rows_generators(sc: Scenario, setups: list[TrialSetup], stream: int, apply_noise: bool
                    ) -> list[Any]:
    """The trials' random streams ``stream`` for the sensor, or Nones when the scenario's
    noise draws nothing (:func:`benchmarks.sim.sensors.draws_noise`)."""
    if not draws_noise(sc, apply_noise):
        return [None] * len(setups)
    return [trial_rng(sc.seed, s.trial, stream) for s in setups]


def _leg_observation(obs: Any, k: int, radius: float, platform_radius: float
                     ) -> LegObservation:
    """Row ``k`` of a batch observation as a :class:`LegObservation` (pixel noise)."""
    return LegObservation(
        base_points=obs.base_points[k], directions=obs.directions[k], lengths=obs.lengths[k],
        normals=obs.normals[k], exists=obs.exists[k], edge_visible=obs.edge_visible[k],
        visible_fraction=obs.visible_fraction[k], lines=None,
        segments=np.full((6, 2, 2, 2), np.nan), visible_interval=obs.visible_interval[k],
        platform_centre=obs.platform_centre[k], platform_normal=obs.platform_normal[k],
        platform_radius=platform_radius, radius=radius)


def run_batch(sc: Scenario, controller_index: int, setups: list[TrialSetup],
              record_trials: int,
              on_step: Callable[[int, np.ndarray, np.ndarray, np.ndarray], None] | None = None,
              batched: bool = True) -> list[TrialResult]:
    """Run trials of one scenario point with one controller, as arrays.

    Args:
        sc: An expanded scenario (one sweep point) with the geometric sensor.
        controller_index: Index into ``sc.controllers``.
        setups: The trials (any worlds).
        record_trials: Trials with an index below this keep their time series.
        on_step: Callback ``(trial, rotation, translation, edge_visible)`` every period.
        batched: Use the controller's ``step_batch`` (False: one controller per trial in
            a loop, for comparison).

    Returns:
        One :class:`TrialResult` per setup, in order (a trial whose goal or controller
        reset fails gets its failure row).
    """
    from benchmarks.sim.stepper import trial_context

    spec = sc.controllers[controller_index]
    failed: dict[int, TrialResult] = {}
    goals = _goals(sc, setups, failed, spec)
    contexts = {k: trial_context(sc, setups[k], goals[k]) for k in goals}
    keys = sorted(contexts)
    try:
        results = _run(sc, spec, [setups[k] for k in keys], [contexts[k] for k in keys],
                       record_trials, on_step, batched) if keys else []
    except BatchFailedError as exc:  # stopped while stepping: each of its trials says so
        # (not rerun trial by trial: a crashing controller must not run twice; a per-trial
        # controller's own crash is isolated inside the batch, PerTrialLoop)
        results = _stopped(sc, spec, [setups[k].trial for k in keys], exc)
    except Exception:  # before its first step (a reset, a refusal): no trial has run yet,
        results = []   # so each runs alone to find the one(s) at fault
        for k in keys:
            try:
                results += _run(sc, spec, [setups[k]], [contexts[k]], record_trials, on_step,
                                batched)
            except BatchFailedError as exc:
                results += _stopped(sc, spec, [setups[k].trial], exc)
            except Exception as exc:
                results.append(TrialResult(failure_row(sc, spec, setups[k].trial, exc)))
    out: list[TrialResult] = []
    it = iter(results)
    for k in range(len(setups)):
        out.append(failed[k] if k in failed else next(it))
    return out


def _stopped(sc: Scenario, spec: Any, trials: list[int], exc: BatchFailedError
             ) -> list[TrialResult]:
    """The rows of a batch stopped at a step: each with the step, its last errors and the
    exception (a batch of several trials says it failed as a whole)."""
    batch = (f"the batch of {len(trials)} trials of {spec.label} failed at step {exc.step} "
             "(every trial of it counted failed, not rerun)" if len(trials) > 1 else None)
    return [TrialResult(failure_row(sc, spec, trial, exc.cause, batch=batch, step=exc.step,
                                    errors=(exc.errors[0][j], exc.errors[1][j])))
            for j, trial in enumerate(trials)]


def _goals(sc: Scenario, setups: list[TrialSetup], failed: dict[int, TrialResult],
           spec: Any) -> dict[int, Goal]:
    """The goal of every trial (:func:`benchmarks.sim.sensors.trial_goal`): measured in one
    batch when one frame is taught, trial by trial otherwise; a trial whose goal cannot
    be measured gets its failure row in ``failed``."""
    goals: dict[int, Goal] = {}
    if sc.teach_frames == 1 and setups:
        try:
            sensor = BatchSensor(sc, setups)
            R = np.array([s.goal_rotation for s in setups])
            t = np.array([s.goal_translation for s in setups])
            items = np.arange(len(setups))
            m = sensor.measure(R, t, items, rows_generators(sc, setups, 2, sc.noise.on_goal),
                               apply_noise=sc.noise.on_goal)
            for k, s in enumerate(setups):
                goals[k] = Goal(
                    normals=m["normals"][k],
                    lines=None if m["lines"] is None else m["lines"][k],
                    directions=m["directions"][k],
                    lengths=inverse_kinematics(s.nominal_geometry, s.goal_rotation,
                                               s.goal_translation),
                    rotation=s.goal_rotation, translation=s.goal_translation,
                    edge_visible=m["edge_visible"][k])
            return goals
        except Exception:  # find the trial(s) at fault below
            goals = {}
    for k, s in enumerate(setups):
        try:
            goals[k] = trial_goal(GeometricSensor(sc, s.world, s.estimated_camera), s, sc)
        except Exception as exc:  # that trial's failure
            failed[k] = TrialResult(failure_row(sc, spec, s.trial, exc))
    return goals


def _run(sc: Scenario, spec: Any, group: list[TrialSetup], contexts: list[Any],
         record_trials: int,
         on_step: Callable[[int, np.ndarray, np.ndarray, np.ndarray], None] | None,
         batched: bool) -> list[TrialResult]:
    from benchmarks.sim.stepper import stroke_violations

    controller = task_batch_controller(sc, spec, batched)
    actuation = require_actuation(controller, spec.label, *world_actuation(sc))
    controller.reset_batch(contexts)
    sensor = BatchSensor(sc, group)
    rngs = rows_generators(sc, group, 1, True)
    noisy = draws_noise(sc, True)
    q = np.array([s.start_lengths for s in group])
    R = np.array([s.start_rotation for s in group])
    t = np.array([s.start_translation for s in group])
    targets = Targets(sc, group)
    offsets = np.array([s.world.joint_offsets for s in group])
    A = sensor.params.base_points
    E = sensor.params.platform_points
    g = group[0].world.geometry
    stroke, vmax = g.stroke, g.max_speed
    book = Book.new(sc, group, record_trials)
    recording = np.array(book.recording, dtype=bool)
    batch_times: list[float] = []  # controller time per row of each step [s]
    stepped = np.zeros(len(group), dtype=int)  # steps each trial was commanded (0, 1, ...)
    dt = sc.dt
    plant = make_plant(sc, group, q, R, t, A, E)
    drive_plant(plant, actuation, spec.label)
    book.follow(plant)
    clock = make_clock(sc, group, q, R, t, A, E)
    last = (np.full(len(group), np.nan), np.full(len(group), np.nan))  # errors [m], [rad]

    def measure(rows: np.ndarray, R_r: np.ndarray, t_r: np.ndarray) -> dict[str, Any]:
        return sensor.measure(R_r, t_r, rows, [rngs[k] for k in rows] if noisy
                              else [None] * len(rows))

    for step in range(sc.task.max_steps + 1):
        idx = np.flatnonzero(book.active)
        if len(idx) == 0:
            break
        R_i, t_i = R[idx], t[idx]
        dp, da = pose_error(R_i, t_i, *targets(step, idx))
        last[0][idx], last[1][idx] = dp, da
        done = book.check(sc, step, idx, dp, da)
        meas = clocked_measure(clock, step, idx, (R, t), measure)
        book.seen(idx, meas["edge_visible"])
        if on_step is not None:
            for j, k in enumerate(idx):
                on_step(group[k].trial, R[k], t[k], meas["edge_visible"][j])
        every = not done.any()  # the common case: no row copies
        rows = np.arange(len(idx)) if every else np.flatnonzero(~done)
        v_cmd = np.zeros((len(idx), 6))
        norms = np.full(len(idx), np.nan)
        if len(rows):
            tr = idx if every else idx[rows]
            obs = ObservationBatch(
                trials=tr, t=np.full(len(rows), step * dt),
                lengths=plant.measured_lengths(tr, offsets[tr]),
                q_dot=plant.measured_rates(tr),
                **{key: (meas[key] if every or meas[key] is None else meas[key][rows])
                   for key in ("normals", "lines", "directions", "edge_visible",
                               "direction_visible", "image_t")})
            t0 = time.perf_counter()
            try:
                cmds = controller.step_batch(obs)
                require_batch(cmds, actuation, spec.label, len(rows))
            except Exception as exc:  # the batch as a whole: reported as such, not rerun
                raise BatchFailedError(step, last, exc) from exc
            batch_times.append((time.perf_counter() - t0) / len(rows))
            stepped[tr] += 1
            norms[rows] = cmds.error_norm
            failed = book.commands(tr, cmds.values, cmds.reasons)
            crashes = getattr(controller, "crashes", None)  # a per-trial loop's rows
            if crashes:
                failed |= book.crashed(tr, crashes, spec.label, step, sc.name,
                                       [s.trial for s in group])
            done[rows[failed]] = True
            ok = rows[~failed]
            v_cmd[ok] = cmds.values[~failed]
        for j in np.flatnonzero(recording[idx]).tolist():
            r = int(idx[j])
            book.record(r, step * dt, q[r], R[r], t[r], meas["edge_visible"][j], norms[j],
                        dp[j], da[j], v_cmd[j])
            book.record_more(r, plant.series(r))
        finished = idx[done]
        book.active[finished] = False
        book.steps[finished] = step
        run = idx[~done]
        if len(run) == 0:
            continue
        v_run = v_cmd[~done]
        if actuation is Actuation.VELOCITY:  # leg forces are not checked as speeds
            book.violations[run] += stroke_violations(q[run], v_run, dt, stroke, vmax)
        book.world_failures(plant.advance(run, v_run, dt), step)
    times = np.array(batch_times)
    for m in range(len(group)):  # a trial is commanded from step 0 until it is done
        book.step_times[m] = times[:stepped[m]].tolist()
    return book.results(sc, spec, group, R, t, figures=plant.row_figures)
