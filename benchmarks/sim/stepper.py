"""Closed-loop trials: a work unit (one scenario point, one controller, some trials) run
through the one closed loop (:func:`benchmarks.sim.loop.closed_loop`).

With the geometric sensor and the simulated robot, the ``batched`` engine steps every
trial of the unit as one batch, whatever their worlds, through the controller's
``step_batch``. Otherwise, or with ``engine="per-trial"``, the trials whose world is the
nominal one are stepped together through one controller object per trial, each a batch
of one (:class:`controllers.batch.ForeignController`), the others one by one. Each trial
has its own random streams seeded from ``(scenario seed, trial index)``, so its result
does not depend on which other trials run beside it.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, fields, is_dataclass, replace
from typing import Any, TypeVar

import numpy as np

from benchmarks.exceptions import BatchFailedError, ScenarioError
from benchmarks.sim.book import Book, OnStep, TrialResult, failure_row
from benchmarks.sim.clock import CameraClock, clock_active
from benchmarks.sim.goal import (
    AnchoredReference,
    cartesian_goal,
    goal_setting,
    measured_goals,
)
from benchmarks.sim.inputs import SimScenario
from benchmarks.sim.loop import closed_loop
from benchmarks.sim.plant import BackendPlant, KinematicPlant, Plant, make_plant, world_actuation
from benchmarks.sim.reference import Targets, task_batch_controller, trial_reference
from benchmarks.sim.sensors import (
    GeometricSensor,
    RowSensor,
    make_sensor,
    reads_features,
    rows_generators,
    trial_goal,
)
from benchmarks.sim.world import (
    Calibrate,
    TrialSetup,
    load_camera,
    load_geometry,
    make_trials,
    trial_rng,
)
from controllers.base import ControllerContext, Goal
from controllers.batch import actuation_of
from hexapod import HexapodGeometry
from hexapod.actuation import check_actuation
from hexapod.backends.base import Backend, halt_and_close

log = logging.getLogger(__name__)

#: The engines of :func:`run_trials`.
ENGINES = ("batched", "per-trial")


#: The scenario type a caller passes (its sensor factory receives it).
S = TypeVar("S", bound=SimScenario)
T = TypeVar("T")
#: Builds the backend of a trial from its true geometry and start lengths [m].
BackendFactory = Callable[[HexapodGeometry, np.ndarray], Backend]


def run_trials(
    sc: S,
    controller_index: int,
    trials: list[int],
    record_trials: int = 0,
    backend_factory: BackendFactory | None = None,
    calibrate: Calibrate | None = None,
    on_step: OnStep | None = None,
    sensor_factory: Callable[[S, TrialSetup], Any] | None = None,
    engine: str = "batched",
) -> list[TrialResult]:
    """Run trials of one scenario point with one controller, in groups by engine (the
    module docstring; both give the same rows); a crash in a trial is its failure.

    Args:
        sc: An expanded scenario (one sweep point).
        controller_index: Index into ``sc.controllers``.
        trials: Trial indices.
        record_trials: Trials with an index below this keep their time series.
        backend_factory: :data:`BackendFactory` (default: the simulated robot).
        calibrate: Optional calibration run per trial (returns estimated base points).
        on_step: A live view's callback (:data:`benchmarks.sim.book.OnStep`).
        sensor_factory: The sensor of a group from the scenario and its first trial
            (default :func:`make_sensor`), with ``measure`` and ``measure_goal`` like
            :class:`GeometricSensor`.
        engine: ``"batched"`` (default) or ``"per-trial"``.

    Returns:
        One :class:`TrialResult` per trial, in the order of ``trials``.
    """
    spec = sc.controllers[controller_index]
    results: dict[int, TrialResult] = {}
    setups: list[TrialSetup] = []
    for k, made in zip(trials, point_trials(sc, trials, calibrate), strict=True):
        if isinstance(made, Exception):  # a crash in one trial is that trial's failure
            results[k] = TrialResult(failure_row(sc, spec, k, made))
        else:
            setups.append(made)
    if getattr(sc, "world", "kinematic") == "dynamic" and backend_factory is not None:
        raise ScenarioError(sc.source, "the dynamic world simulates the robot: it runs with "
                            "the simulated backend only (a robot or an emulator is its own "
                            "world; the emulators take --dynamics)", key="robot.world")
    if engine not in ENGINES:
        raise ValueError(f"engine: expected one of {', '.join(ENGINES)}, got {engine!r}")
    batched = (engine == "batched" and backend_factory is None and sensor_factory is None
               and sc.sensor == "geometric")
    if batched:
        groups = [setups] if setups else []
    else:
        shared = [s for s in setups if s.shared and backend_factory is None]
        groups = ([shared] if shared else []) + [[s] for s in setups if s not in shared]
    unit = _Unit(sc, spec, record_trials, batched, backend_factory, on_step,
                 sensor_factory or make_sensor)
    for group in groups:
        for res in unit.isolated(group):
            results[res.row["trial"]] = res
    return [results[k] for k in trials]


#: The trials drawn for the last scenario point: its scenario, calibration and the setups
#: per tuple of trial indices (:func:`point_trials`; one point's at a time), with the
#: targets of its groups (:func:`point_targets`).
_drawn: list[Any] = [None, None, {}]


#: The trials a study's pre-flight drew without calibration (:func:`preflight_trials`),
#: per scenario point: ``(point, {trial: setup or exception})``, each trial taken once by
#: the run's :func:`point_trials` (at most :data:`PREFLIGHT_POINTS` points are kept).
_preflight: list[tuple[SimScenario, dict[int, Any]]] = []
#: Scenario points whose pre-flight draws are kept for the run (the oldest dropped first;
#: about 1.3 MB a point of 200 trials with calibration errors).
PREFLIGHT_POINTS = 64


def forget_trials() -> None:
    """Empty the drawn trials of :func:`point_trials` and those the pre-flight kept (a
    timing that includes the draws)."""
    _drawn[:] = [None, None, {}]
    _preflight.clear()


def preflight_trials(sc: SimScenario, trials: list[int]) -> list[TrialSetup | Exception]:
    """:func:`benchmarks.sim.world.make_trials` of a scenario point without calibration
    (the pre-flight's draws, :mod:`benchmarks.study.trajectory_check`), kept for the
    run's :func:`point_trials` of an equal point: the same function of the same values,
    drawn once. The caller only reads the setups."""
    nominal = load_geometry(sc)
    made = make_trials(sc, list(trials), nominal, load_camera(sc, nominal))
    _preflight[:] = [e for e in _preflight if not _same_point(e[0], sc)]
    _preflight.append((sc, dict(zip(trials, made, strict=True))))
    del _preflight[:-PREFLIGHT_POINTS]
    return made


def _same_point(a: SimScenario, b: SimScenario) -> bool:
    """Whether two scenario points are equal in every field (so their draws are): the
    same object, or equal dataclasses (False where a field does not compare, an array
    of another object)."""
    if a is b:
        return True
    try:
        return bool(a == b)
    except (TypeError, ValueError):  # an array field of two objects: not known equal
        return False


def _from_preflight(sc: SimScenario, trials: list[int]) -> list[TrialSetup | Exception] | None:
    """The pre-flight's draws of ``trials`` of a point equal to ``sc`` (taken: each once),
    or None when it did not draw all of them."""
    for point, made in _preflight:
        if _same_point(point, sc) and all(t in made for t in trials):
            return [made.pop(t) for t in trials]
    return None


def point_trials(sc: SimScenario, trials: list[int], calibrate: Calibrate | None = None
                 ) -> list[TrialSetup | Exception]:
    """:func:`benchmarks.sim.world.make_trials` of a scenario point, drawn once for every
    controller of the point (the same ``sc`` and ``calibrate`` objects, the last point's
    only), or taken from the pre-flight's draws of an equal point when no calibration
    changes them (:func:`preflight_trials`). Each call gets its own copies of a setup's
    arrays and dict (the objects a setup shares with other trials, its robots and
    cameras, are shared anyway).
    """
    if _drawn[0] is not sc or _drawn[1] is not calibrate:
        _drawn[:] = [sc, calibrate, {}]
    key = tuple(trials)
    if key not in _drawn[2]:
        made = None if calibrate is not None else _from_preflight(sc, list(trials))
        if made is None:
            nominal = load_geometry(sc)
            made = make_trials(sc, list(trials), nominal, load_camera(sc, nominal), calibrate)
        _drawn[2][key] = made
    return [m if isinstance(m, Exception) else own_copy(m) for m in _drawn[2][key]]


def point_targets(sc: SimScenario, group: list[TrialSetup]) -> Targets:
    """The :class:`~benchmarks.sim.reference.Targets` of a group of the point's drawn trials
    (:func:`point_trials`), sampled once for every controller of the point (read only:
    its calls return copies)."""
    key = ("targets", *(s.trial for s in group))
    if _drawn[0] is not sc:  # (trials not drawn by point_trials)
        return Targets(sc, group)
    if key not in _drawn[2]:
        _drawn[2][key] = Targets(sc, group)
    return _drawn[2][key]  # type: ignore[no-any-return]


def own_copy(setup: T) -> T:
    """``setup`` (a dataclass) with its own copies of its writable arrays and dicts, and
    of those of the dataclasses it holds (a trial's world); read-only arrays and frozen
    objects (geometries, cameras) stay shared."""
    changes: dict[str, Any] = {}
    for f in fields(setup):  # type: ignore[arg-type]
        value = getattr(setup, f.name)
        if isinstance(value, np.ndarray) and value.flags.writeable:
            changes[f.name] = value.copy()
        elif isinstance(value, dict):
            changes[f.name] = dict(value)
        elif (is_dataclass(value) and not isinstance(value, type)
              and not type(value).__dataclass_params__.frozen):  # type: ignore[attr-defined]
            copied = own_copy(value)
            if copied is not value:
                changes[f.name] = copied
    return replace(setup, **changes) if changes else setup  # type: ignore[type-var]


@dataclass
class _Unit:
    """How the groups of a work unit run (the arguments of :func:`run_trials`)."""

    sc: SimScenario
    spec: Any
    record_trials: int
    batched: bool
    backend_factory: BackendFactory | None
    on_step: OnStep | None
    sensor_factory: Callable[[Any, TrialSetup], Any]

    def isolated(self, group: list[TrialSetup]) -> list[TrialResult]:
        """The results of a group; when it fails before its first step (a reset, a
        refusal: no trial has run yet), of its trials one by one to find the one(s) at
        fault (a crash in a trial is that trial's failure). A group stopped while
        stepping is not rerun (:meth:`run`)."""
        try:
            return self.run(group)
        except Exception as exc:
            if len(group) == 1:
                return [TrialResult(failure_row(self.sc, self.spec, group[0].trial, exc))]
        out = []
        for s in group:
            try:
                out += self.run([s])
            except Exception as exc2:
                out.append(TrialResult(failure_row(self.sc, self.spec, s.trial, exc2)))
        return out

    def run(self, setups: list[TrialSetup]) -> list[TrialResult]:
        """Run a group through the closed loop (a trial whose goal cannot be measured in
        a batched group gets its failure row; the others run)."""
        sc, spec = self.sc, self.spec
        sensor: GeometricSensor | RowSensor
        if self.batched:
            sensor = GeometricSensor.of_trials(sc, setups)
            goals = _goals(sc, sensor, setups)
        else:
            sensor = RowSensor(self.sensor_factory(sc, setups[0]),
                               [trial_rng(sc.seed, s.trial, 1) for s in setups])
            goals = [trial_goal(sensor.sensor, s, sc) for s in setups]
        out = {k: TrialResult(failure_row(sc, spec, setups[k].trial, g))
               for k, g in enumerate(goals) if isinstance(g, Exception)}
        keep = [k for k in range(len(setups)) if k not in out]
        if len(keep) < len(setups):
            group = [setups[k] for k in keep]
            if group:  # (none left: each trial's failure row says why, not an IndexError)
                sensor = GeometricSensor.of_trials(sc, group)
        else:
            group = setups
        if group:
            contexts = [trial_context(sc, setups[k], goals[k]) for k in keep]
            try:
                results = self._loop(group, contexts, sensor)
            except BatchFailedError as exc:  # stopped while stepping: each trial says so
                # (not rerun trial by trial: a crashing controller must not run twice; a
                # per-trial controller's own crash is isolated inside the batch)
                results = _stopped(sc, spec, [s.trial for s in group], exc)
            for k, res in zip(keep, results, strict=True):
                out[k] = res
        return [out[k] for k in range(len(setups))]

    def _loop(self, group: list[TrialSetup], contexts: list[ControllerContext],
              sensor: GeometricSensor | RowSensor) -> list[TrialResult]:
        sc, spec = self.sc, self.spec
        controller = task_batch_controller(sc, spec, self.batched)
        sensor.features = reads_features(controller)
        actuation = actuation_of(controller)
        if self.backend_factory is None:  # (a backend says itself what it applies)
            check_actuation(actuation, *world_actuation(sc), spec.label)
        controller.reset_batch(contexts)
        q = np.array([s.start_lengths for s in group])
        R = np.array([s.start_rotation for s in group])
        t = np.array([s.start_translation for s in group])
        offsets = np.array([s.world.joint_offsets for s in group])
        g = group[0].world.geometry
        if isinstance(sensor, GeometricSensor):
            A, E = sensor.params.base_points, sensor.params.platform_points
        else:  # one world
            A, E = g.base_points, g.platform_points
        opened: list[Backend] = []
        try:
            if self.backend_factory is None:
                plant: Plant = make_plant(sc, group, q, R, t, A, E)
            else:
                for s in group:
                    opened.append(self.backend_factory(g, s.start_lengths + s.world.joint_offsets))
                poses = KinematicPlant(q, R, t, A, E, g.stroke, g.max_speed)
                plant = BackendPlant(opened, q, R, t, offsets, poses.solve_poses, g.stroke)
            plant.use_actuation(actuation, spec.label)
            book = Book(sc, group, self.record_trials, plant, point_targets(sc, group), actuation,
                        spec.label, self.on_step)
            clock = CameraClock(sc, group, q, R, t, A, E) if clock_active(sc) else None
            closed_loop(plant, sensor, clock, controller, book, sc.dt, offsets,
                        sc.task.max_steps)
        finally:
            _close_all(opened)
        return book.results(sc, spec, group, R, t, sensor.detect_times, plant.row_figures)


def _stopped(sc: SimScenario, spec: Any, trials: list[int], exc: BatchFailedError
             ) -> list[TrialResult]:
    """The rows of a group stopped at a step: each with the step, its last errors and the
    exception (a batch of several trials says it failed as a whole)."""
    batch = (f"the batch of {len(trials)} trials of {spec.label} failed at step {exc.step} "
             "(every trial of it counted failed, not rerun)" if len(trials) > 1 else None)
    return [TrialResult(failure_row(sc, spec, trial, exc.cause, batch=batch, step=exc.step,
                                    errors=(exc.errors[0][j], exc.errors[1][j])))
            for j, trial in enumerate(trials)]


def _goals(sc: SimScenario, sensor: GeometricSensor, setups: list[TrialSetup]
           ) -> list[Goal | Exception]:
    """The goal of every trial (:func:`benchmarks.sim.sensors.trial_goal`): measured in one
    batch when one frame is taught (:func:`benchmarks.sim.goal.measured_goals`), trial by
    trial otherwise (and to find the trials at fault when the batch fails); a trial whose
    goal cannot be measured has its error."""
    if sc.teach_frames == 1:
        try:
            if goal_setting(sc) == "cartesian":  # nothing measured at the goal
                return [cartesian_goal(s) for s in setups]
            m = sensor.sample(np.array([s.goal_rotation for s in setups]),
                              np.array([s.goal_translation for s in setups]),
                              np.arange(len(setups)),
                              rows_generators(sc, setups, 2, sc.noise.on_goal),
                              apply_noise=sc.noise.on_goal)
            return list(measured_goals(m, setups, sc))
        except Exception:  # find the trial(s) at fault below
            pass
    goals: list[Goal | Exception] = []
    for s in setups:
        try:
            goals.append(trial_goal(GeometricSensor(sc, s.world, s.estimated_camera), s, sc))
        except Exception as exc:  # that trial's failure
            goals.append(exc)
    return goals


def _close_all(backends: list[Backend]) -> None:
    """Halt and close backends, whatever happened."""
    for b in backends:  # (their failures said, not raised: the trial ran to its end)
        halt_and_close(b)


def trial_context(sc: SimScenario, setup: TrialSetup, goal: Any) -> ControllerContext:
    """What the controllers of a trial are told: the estimated parameters and the goal
    (under ``[task] goal = "taught"``, a trajectory's reference moved to end at the
    taught goal pose, :class:`benchmarks.sim.goal.AnchoredReference`)."""
    reference: Any = trial_reference(sc, setup)
    if (reference is not None and goal_setting(sc) == "taught" and goal is not None
            and goal.rotation is not None and goal.translation is not None):
        reference = AnchoredReference(reference, goal.rotation, goal.translation)
    return ControllerContext(base_points=setup.base_points, geometry=setup.nominal_geometry,
                             camera=setup.estimated_camera, dt=sc.dt, goal=goal,
                             reference=reference)
