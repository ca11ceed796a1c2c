"""Closed-loop trials: true world -> sensor -> controller -> backend -> true world.

One trial (ARCHITECTURE.md, "one control step, as data"): the true world (true
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
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from benchmarks.sim.sensors import make_sensor, trial_goal
from benchmarks.sim.world import (
    TrialSetup,
    World,
    load_camera,
    load_geometry,
    make_trial,
    trial_rng,
)
from benchmarks.study.scenario import Scenario
from controllers.base import Command, ControllerContext, Observation, registry
from hexapod import HexapodGeometry, forward_kinematics_batch
from hexapod.backends.base import Backend, clamp_velocities
from hexapod.exceptions import HexapodError
from hexapod.se3 import pose_error
from vision.exceptions import VisionError

log = logging.getLogger(__name__)


#: Consecutive refused steps after which a trial is declared failed.
MAX_REFUSED_STEPS = 25


@dataclass
class TrialResult:
    """Outcome of one trial (one row of ``results.jsonl``) and its time series."""

    row: dict[str, Any]
    series: dict[str, np.ndarray] | None = None


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
) -> list[TrialResult]:
    """Run trials of one scenario point with one controller.

    Trials whose world is the nominal one are stepped together (vectorised);
    the others one by one. A crash in a trial is recorded as its failure.

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

    Returns:
        One :class:`TrialResult` per trial, in the order of ``trials``.
    """
    spec = sc.controllers[controller_index]
    nominal = load_geometry(sc)
    camera = load_camera(sc, nominal)
    results: dict[int, TrialResult] = {}
    setups: list[TrialSetup] = []
    for k in trials:
        try:
            setups.append(make_trial(sc, k, nominal, camera, calibrate))
        except Exception as exc:  # a crash in one trial is that trial's failure
            results[k] = TrialResult(_failure_row(sc, spec, k, exc))
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
                results[group[0].trial] = TrialResult(_failure_row(sc, spec, group[0].trial,
                                                                   exc))
            else:  # isolate the failing trial(s): run them one by one
                for s in group:
                    single_opened: list[Backend] = []
                    try:
                        res = _run_group(sc, controller_index, [s], record_trials,
                                         backend_factory, on_step, single_opened,
                                         sensor_factory)[0]
                    except Exception as exc2:
                        res = TrialResult(_failure_row(sc, spec, s.trial, exc2))
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


def _base_row(sc: Scenario, spec: Any, trial: int) -> dict[str, Any]:
    info = None
    try:
        info = registry.source(spec.name)
    except Exception:  # reported as the trial failure below
        info = None
    row: dict[str, Any] = {
        "scenario": sc.name,
        "controller": spec.label,
        "controller_name": spec.name,
        "controller_package": info.package if info else None,
        "controller_version": info.version if info else None,
        "trial": int(trial),
    }
    for key, value in sc.sweep.items():
        row[key.replace(".", "_").replace("calibration_error_", "calib_")] = value
    return row


def _failure_row(sc: Scenario, spec: Any, trial: int, exc: BaseException) -> dict[str, Any]:
    row = _base_row(sc, spec, trial)
    row.update({
        "converged": False, "steps": 0, "final_position_error_mm": None,
        "final_orientation_error_deg": None, "stroke_violations": 0, "step_time_us": None,
        "failure": f"{type(exc).__name__}: {exc}",
    })
    if isinstance(exc, HexapodError | VisionError):  # the user's data: the message says it
        log.warning("trial %s/%s/%d failed: %s", sc.name, spec.label, trial, exc)
    else:
        log.warning("trial %s/%s/%d failed: %s\n%s", sc.name, spec.label, trial, exc,
                    traceback.format_exc())
    return row


def _run_group(sc: Scenario, controller_index: int, group: list[TrialSetup],
               record_trials: int,
               backend_factory: Callable[[HexapodGeometry, np.ndarray], Backend] | None,
               on_step: Callable[[int, np.ndarray, np.ndarray, np.ndarray], None] | None,
               opened: list[Backend] | None = None,
               sensor_factory: Callable[[Scenario, TrialSetup], Any] | None = None
               ) -> list[TrialResult]:
    """Run trials sharing one world in lockstep (backends it opens go to ``opened``)."""
    if opened is None:
        opened = []
    spec = sc.controllers[controller_index]
    n = len(group)
    world = group[0].world
    g = world.geometry
    sensor = (sensor_factory or make_sensor)(sc, group[0])
    controllers = []
    for s in group:
        ctrl = registry.create(spec.name, **spec.options)
        goal = trial_goal(sensor, s, sc)
        ctx = ControllerContext(base_points=s.base_points, geometry=s.nominal_geometry,
                                camera=s.estimated_camera, dt=sc.dt, goal=goal)
        ctrl.reset(ctx)
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
    R_goal = np.array([s.goal_rotation for s in group])
    t_goal = np.array([s.goal_translation for s in group])
    offsets = world.joint_offsets
    pos_tol = 1e-3 * sc.task.position_tolerance_mm
    ori_tol = np.deg2rad(sc.task.orientation_tolerance_deg)
    active = np.ones(n, dtype=bool)
    steps = np.zeros(n, dtype=int)
    settled = np.zeros(n, dtype=int)
    last_bad = np.full(n, -1)
    tail_start = sc.task.max_steps - max(1, sc.task.max_steps // 5)
    tail_pos: list[list[float]] = [[] for _ in range(n)]
    tail_ori: list[list[float]] = [[] for _ in range(n)]
    converged = np.zeros(n, dtype=bool)
    violations = np.zeros(n, dtype=int)
    refused = np.zeros(n, dtype=int)
    failure: list[str | None] = [None] * n
    step_times: list[list[float]] = [[] for _ in range(n)]
    rtts: list[list[float]] = [[] for _ in range(n)]
    missed = np.zeros(n, dtype=int)
    recording = [s.trial < record_trials for s in group]
    series: list[dict[str, list[Any]]] = [
        {k: [] for k in ("t", "lengths", "rotations", "translations", "edge_visible",
                         "error_norm", "position_error", "orientation_error", "velocities")}
        if rec else {} for rec in recording
    ]
    dt = sc.dt
    for step in range(sc.task.max_steps + 1):
        idx = np.flatnonzero(active)
        if len(idx) == 0:
            break
        dp, da = pose_error(R[idx], t[idx], R_goal[idx], t_goal[idx])
        ok = (dp < pos_tol) & (da < ori_tol)
        settled[idx] = np.where(ok, settled[idx] + 1, 0)
        last_bad[idx[~ok]] = step
        if sc.task.fixed_duration and step > tail_start:
            for j, k in enumerate(idx):
                tail_pos[k].append(float(dp[j]))
                tail_ori[k].append(float(da[j]))
        if sc.task.fixed_duration:
            done = np.full(len(idx), step == sc.task.max_steps)
            converged[idx] = ok
        else:
            done = settled[idx] >= sc.task.settle_steps
            converged[idx[done]] = True
            if step == sc.task.max_steps:
                done[:] = True
        meas = sensor.measure(R[idx], t[idx], [rngs[k] for k in idx])
        if on_step is not None:
            for j, k in enumerate(idx):
                on_step(group[k].trial, R[k], t[k], meas["edge_visible"][j])
        v_cmd = np.zeros((len(idx), 6))
        for j, k in enumerate(idx):
            obs = Observation(
                t=step * dt, lengths=q[k] + offsets,
                normals=meas["normals"][j],
                lines=None if meas["lines"] is None else meas["lines"][j],
                directions=meas["directions"][j],
                edge_visible=meas["edge_visible"][j],
                direction_visible=meas["direction_visible"][j],
            )
            cmd: Command | None = None
            if not done[j]:
                t0 = time.perf_counter()
                cmd = controllers[k].step(obs)
                step_times[k].append(time.perf_counter() - t0)
                vel = np.asarray(cmd.velocities, dtype=float)
                if vel.shape != (6,) or not np.all(np.isfinite(vel)):
                    failure[k] = f"controller returned an invalid command {vel!r}"
                    done[j] = True
                else:
                    v_cmd[j] = vel
                if cmd.reason is not None:
                    refused[k] += 1
                    if refused[k] >= MAX_REFUSED_STEPS:
                        failure[k] = f"controller refused to move: {cmd.reason}"
                        done[j] = True
                else:
                    refused[k] = 0
            if recording[k]:
                ser = series[k]
                ser["t"].append(step * dt)
                ser["lengths"].append(q[k].copy())
                ser["rotations"].append(R[k].copy())
                ser["translations"].append(t[k].copy())
                ser["edge_visible"].append(meas["edge_visible"][j].copy())
                ser["error_norm"].append(cmd.error_norm if cmd is not None else np.nan)
                ser["position_error"].append(dp[j])
                ser["orientation_error"].append(da[j])
                ser["velocities"].append(v_cmd[j].copy())
        finished = idx[done]
        active[finished] = False
        for k in finished:
            steps[k] = step
        run = idx[~done]
        if len(run) == 0:
            continue
        v_run = v_cmd[~done]
        # a stroke violation: the (speed-limited) command would leave the stroke this period
        q_next = q[run] + np.clip(v_run, -g.max_speed, g.max_speed) * dt
        violations[run] += np.any((q_next < g.stroke[0] - 1e-9) | (q_next > g.stroke[1] + 1e-9),
                                  axis=1)
        if backends is None:
            vc, _ = clamp_velocities(q[run], v_run, dt, g.stroke, g.max_speed)
            q[run] = np.clip(q[run] + vc * dt, *g.stroke)
        else:
            for j, k in enumerate(run):
                bs = backends[k].step(v_run[j], dt)
                q[k] = bs.lengths - offsets
                rtts[k].append(bs.round_trip_s)
                missed[k] += int(bs.missed_period)
        sol = forward_kinematics_batch(g, q[run], R[run], t[run])
        bad = ~sol.converged
        if np.any(bad):
            for k in run[bad]:
                failure[k] = "forward kinematics of the true robot failed (singularity?)"
                active[k] = False
                steps[k] = step + 1
        okk = run[~bad]
        R[okk] = sol.rotations[~bad]
        t[okk] = sol.translations[~bad]
    dp, da = pose_error(R, t, R_goal, t_goal)
    out = []
    for m, s in enumerate(group):
        row = _base_row(sc, spec, s.trial)
        fail = failure[m]
        if fail is None and not converged[m]:
            fail = f"not converged within {sc.task.max_steps} steps"
        settle = int(last_bad[m] + 1) if sc.task.fixed_duration else int(steps[m])
        row.update({
            "converged": bool(converged[m]),
            "steps": settle,
            "final_position_error_mm": float(dp[m] * 1e3),
            "final_orientation_error_deg": float(np.rad2deg(da[m])),
            "stroke_violations": int(violations[m]),
            "step_time_us": float(np.median(step_times[m]) * 1e6) if step_times[m] else None,
            "failure": None if converged[m] else fail,
        })
        if tail_pos[m]:
            # the seeds' "median positioning error of the convergence tail": the last 20 %
            row["tail_position_error_mm"] = float(np.median(tail_pos[m]) * 1e3)
            row["tail_orientation_error_deg"] = float(np.rad2deg(np.median(tail_ori[m])))
        times = getattr(sensor, "detect_times", None)
        if times:
            row["detect_time_ms"] = float(np.median(times) * 1e3)
        if rtts[m]:
            arr = np.array(rtts[m]) * 1e3
            row["rtt_median_ms"] = float(np.median(arr))
            row["rtt_p99_ms"] = float(np.percentile(arr, 99))
            row["missed_periods"] = int(missed[m])
        for key, value in s.calibration.items():
            row[f"calibration_{key}"] = value
        ser_out = None
        if recording[m]:
            ser_out = {key: np.array(v) for key, v in series[m].items()}
            ser_out["goal_rotation"] = s.goal_rotation
            ser_out["goal_translation"] = s.goal_translation
        out.append(TrialResult(row, ser_out))
    return out
