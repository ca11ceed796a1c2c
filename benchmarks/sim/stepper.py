"""Closed-loop trials: true world -> sensor -> controller -> backend -> true world.

One trial (``docs/architecture.md``, the loop): the true world (true
geometry, true camera, true pose) produces observations through :mod:`vision`
(geometric features + noise, or rendered images + detection); the controller,
built from the ESTIMATED parameters, returns leg velocities; the backend clamps
them to the stroke and speed limits and applies them for ``dt``; the new true
pose is the forward kinematics of the TRUE geometry, warm-started.

Trials that share one true world (no calibration error) are stepped together,
vectorised over a leading axis; each trial has its own random streams seeded
from ``(scenario seed, trial index)``, so a trial's result does not depend on
which other trials run beside it (nor on the executor or the chunking).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from benchmarks.exceptions import ScenarioError
from benchmarks.sim.actuation import drive_plant, require_actuation, world_actuation
from benchmarks.sim.book import Book, TrialResult, failure_row
from benchmarks.sim.clock import clocked_measure, make_clock
from benchmarks.sim.plant import FK_FAILURE, KinematicPlant, make_plant
from benchmarks.sim.reference import Targets, task_controller
from benchmarks.sim.sensors import make_sensor, trial_goal
from benchmarks.sim.world import (
    TrialSetup,
    World,
    load_camera,
    load_geometry,
    make_trials,
    trial_rng,
)
from benchmarks.study.scenario import Scenario
from controllers.base import Command, ControllerContext, Observation
from controllers.batch import actuation_of
from hexapod import HexapodGeometry
from hexapod.actuation import Actuation
from hexapod.backends.base import Backend
from hexapod.se3 import pose_error

log = logging.getLogger(__name__)

#: The engines of :func:`run_trials`.
ENGINES = ("batched", "per-trial")


def run_trials(
    sc: Scenario,
    controller_index: int,
    trials: list[int],
    record_trials: int = 0,
    backend_factory: Callable[[HexapodGeometry, np.ndarray], Backend] | None = None,
    calibrate: Callable[[World, np.random.Generator], tuple[np.ndarray, dict[str, float]]]
    | None = None,
    on_step: Callable[[int, np.ndarray, np.ndarray, np.ndarray], None] | None = None,
    sensor_factory: Callable[[Scenario, TrialSetup], Any] | None = None,
    engine: str = "batched",
) -> list[TrialResult]:
    """Run trials of one scenario point with one controller.

    With the geometric sensor and the simulated backend, every trial goes through the
    batched engine (:mod:`benchmarks.sim.engine`, ``engine="batched"``). Otherwise, or
    with ``engine="per-trial"``, trials whose world is the nominal one are stepped
    together with one controller object per trial, the others one by one. A crash in a
    trial is recorded as its failure. Both engines give the same rows.

    Args:
        sc: An expanded scenario (one sweep point).
        controller_index: Index into ``sc.controllers``.
        trials: Trial indices.
        record_trials: Trials with an index below this keep their time series.
        backend_factory: Builds a backend for a trial from the true geometry and
            start lengths (default: exact integration of the clamped command).
        calibrate: Optional calibration run per trial (returns estimated base points).
        on_step: Callback ``(trial, rotation, translation, edge_visible)`` for a live view.
        sensor_factory: Builds the sensor of a group of trials from the scenario and its
            first trial (default :func:`make_sensor`; studies swap sensors with it). The
            sensor has ``measure`` and ``measure_goal`` like :class:`GeometricSensor`.
        engine: ``"batched"`` (default) or ``"per-trial"``.

    Returns:
        One :class:`TrialResult` per trial, in the order of ``trials``.
    """
    spec = sc.controllers[controller_index]
    nominal = load_geometry(sc)
    camera = load_camera(sc, nominal)
    results: dict[int, TrialResult] = {}
    setups: list[TrialSetup] = []
    for k, made in zip(trials, make_trials(sc, list(trials), nominal, camera, calibrate),
                       strict=True):
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
    if (engine == "batched" and backend_factory is None and sensor_factory is None
            and sc.sensor == "geometric"):
        from benchmarks.sim.engine import run_batch

        for res in run_batch(sc, controller_index, setups, record_trials, on_step):
            results[res.row["trial"]] = res
        return [results[k] for k in trials]
    shared = [s for s in setups if s.shared and backend_factory is None]
    single = [s for s in setups if not (s.shared and backend_factory is None)]
    groups = ([shared] if shared else []) + [[s] for s in single]
    for group in groups:
        opened: list[Backend] = []
        try:
            for res in _run_group(sc, controller_index, group, record_trials, backend_factory,
                                  on_step, opened, sensor_factory):
                results[res.row["trial"]] = res
        except Exception as exc:
            if len(group) == 1:
                results[group[0].trial] = TrialResult(failure_row(sc, spec, group[0].trial,
                                                                   exc))
            else:  # isolate the failing trial(s): run them one by one
                for s in group:
                    single_opened: list[Backend] = []
                    try:
                        res = _run_group(sc, controller_index, [s], record_trials,
                                         backend_factory, on_step, single_opened,
                                         sensor_factory)[0]
                    except Exception as exc2:
                        res = TrialResult(failure_row(sc, spec, s.trial, exc2))
                    finally:
                        _close_all(single_opened)
                    results[s.trial] = res
        finally:
            _close_all(opened)
    return [results[k] for k in trials]


def _close_all(backends: list[Backend]) -> None:
    """Halt and close backends, whatever happened (a robot is never left moving)."""
    for b in backends:
        try:
            b.halt()
        except Exception as exc:  # already failing: report and go on closing
            log.warning("halting a backend failed: %s", exc)
        finally:
            b.close()


def _run_group(sc: Scenario, controller_index: int, group: list[TrialSetup],
               record_trials: int,
               backend_factory: Callable[[HexapodGeometry, np.ndarray], Backend] | None,
               on_step: Callable[[int, np.ndarray, np.ndarray, np.ndarray], None] | None,
               opened: list[Backend] | None = None,
               sensor_factory: Callable[[Scenario, TrialSetup], Any] | None = None
               ) -> list[TrialResult]:
    """Run trials sharing one world in lockstep, one controller object per trial (the
    per-trial path; backends it opens go to ``opened``)."""
    if opened is None:
        opened = []
    spec = sc.controllers[controller_index]
    world = group[0].world
    g = world.geometry
    sensor = (sensor_factory or make_sensor)(sc, group[0])
    controllers = []
    for s in group:
        ctrl = task_controller(sc, spec)
        if backend_factory is None:  # a backend says itself what it applies (Backend.apply)
            require_actuation(ctrl, spec.label, *world_actuation(sc))
        ctrl.reset(trial_context(sc, s, trial_goal(sensor, s, sc)))
        controllers.append(ctrl)
    rngs = [trial_rng(sc.seed, s.trial, 1) for s in group]
    backends = None
    if backend_factory is not None:
        backends = []
        for s in group:
            backends.append(backend_factory(g, s.start_lengths + world.joint_offsets))
            opened.append(backends[-1])
    q = np.array([s.start_lengths for s in group])
    R = np.array([s.start_rotation for s in group])
    t = np.array([s.start_translation for s in group])
    targets = Targets(sc, group)
    offsets = world.joint_offsets
    kinds = [Actuation.VELOCITY] * len(group)  # what each trial's last command set
    book = Book.new(sc, group, record_trials)
    dt = sc.dt
    poses = KinematicPlant(q, R, t, g.base_points, g.platform_points, g.stroke, g.max_speed)
    plant = poses if backends is not None else make_plant(sc, group, q, R, t,
                                                          g.base_points, g.platform_points)
    if backends is None:
        drive_plant(plant, actuation_of(controllers[0]), spec.label)
        book.follow(plant)
    clock = make_clock(sc, group, q, R, t, g.base_points, g.platform_points)

    def measure(rows: np.ndarray, R_r: np.ndarray, t_r: np.ndarray) -> dict[str, Any]:
        return sensor.measure(R_r, t_r, [rngs[k] for k in rows])  # type: ignore[no-any-return]

    for step in range(sc.task.max_steps + 1):
        idx = np.flatnonzero(book.active)
        if len(idx) == 0:
            break
        dp, da = pose_error(R[idx], t[idx], *targets(step, idx))
        done = book.check(sc, step, idx, dp, da)
        meas = clocked_measure(clock, step, idx, (R, t), measure)
        book.seen(idx, meas["edge_visible"])
        if on_step is not None:
            for j, k in enumerate(idx):
                on_step(group[k].trial, R[k], t[k], meas["edge_visible"][j])
        v_cmd = np.zeros((len(idx), 6))
        lengths = plant.measured_lengths(idx, offsets)
        rates = plant.measured_rates(idx)
        for j, k in enumerate(idx):
            obs = Observation(
                t=step * dt, lengths=lengths[j],
                normals=meas["normals"][j],
                lines=None if meas["lines"] is None else meas["lines"][j],
                directions=meas["directions"][j],
                edge_visible=meas["edge_visible"][j],
                direction_visible=meas["direction_visible"][j],
                image_t=None if meas["image_t"] is None else float(meas["image_t"][j]),
                q_dot=None if rates is None else rates[j],
            )
            cmd: Command | None = None
            if not done[j]:
                t0 = time.perf_counter()
                cmd = controllers[k].step(obs)
                book.step_times[k].append(time.perf_counter() - t0)
                if backends is None and cmd.actuation not in world_actuation(sc)[0]:
                    require_actuation(cmd, spec.label, *world_actuation(sc))
                kinds[k] = cmd.actuation
                if book.command(int(k), cmd.values, cmd.reason):
                    done[j] = True
                else:
                    v_cmd[j] = cmd.values
            if book.recording[k]:
                book.record(int(k), step * dt, q[k], R[k], t[k], meas["edge_visible"][j],
                            cmd.error_norm if cmd is not None else np.nan, dp[j], da[j],
                            v_cmd[j])
                book.record_more(int(k), plant.series(int(k)))
        finished = idx[done]
        book.active[finished] = False
        book.steps[finished] = step
        run = idx[~done]
        if len(run) == 0:
            continue
        v_run = v_cmd[~done]
        if kinds[run[0]] is Actuation.VELOCITY:  # leg forces are not checked as speeds
            book.violations[run] += stroke_violations(q[run], v_run, dt, g.stroke,
                                                      g.max_speed)
        if backends is None:
            book.world_failures(plant.advance(run, v_run, dt), step)
            continue
        for j, k in enumerate(run):
            bs = backends[k].apply(v_run[j], kinds[k], dt, spec.label)
            q[k] = bs.lengths - offsets
            book.rtts[k].append(bs.round_trip_s)
            book.missed[k] += int(bs.missed_period)
        bad = poses.solve_poses(run)  # the backends moved the legs: the poses follow
        book.world_failures(dict.fromkeys(run[bad].tolist(), FK_FAILURE), step)
    return book.results(sc, spec, group, R, t, getattr(sensor, "detect_times", None),
                        plant.row_figures)


def trial_context(sc: Scenario, setup: TrialSetup, goal: Any) -> ControllerContext:
    """What the controllers of a trial are told: the estimated parameters and the goal."""
    from benchmarks.sim.reference import trial_reference

    return ControllerContext(base_points=setup.base_points, geometry=setup.nominal_geometry,
                             camera=setup.estimated_camera, dt=sc.dt, goal=goal,
                             reference=trial_reference(sc, setup))


def stroke_violations(q: np.ndarray, v: np.ndarray, dt: float,
                      stroke: tuple[float, float], max_speed: float) -> np.ndarray:
    """(n,) 1 where the (speed-limited) command would leave the stroke this period."""
    q_next = q + np.clip(v, -max_speed, max_speed) * dt
    return np.any((q_next < stroke[0] - 1e-9) | (q_next > stroke[1] + 1e-9), axis=1)
