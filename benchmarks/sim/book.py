"""The bookkeeping of a group of trials stepped together, shared by both engines: the
convergence test of every period, the failures, timings and recorded series, and the
result rows (one row of ``results.jsonl`` per trial)."""

from __future__ import annotations

import logging
import statistics
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from benchmarks.sim.tolerance import unconverged_reason
from benchmarks.sim.world import TrialSetup
from benchmarks.study.failures import user_message
from benchmarks.study.scenario import Scenario
from controllers.exceptions import ControllerError
from controllers.registry import registry
from hexapod.exceptions import HexapodError
from hexapod.se3 import pose_error
from vision.exceptions import VisionError

log = logging.getLogger(__name__)

#: Consecutive refused steps after which a trial is declared failed.
MAX_REFUSED_STEPS = 25
#: The recorded time series of a trial.
SERIES_KEYS = ("t", "lengths", "rotations", "translations", "edge_visible", "error_norm",
               "position_error", "orientation_error", "velocities")


@dataclass
class TrialResult:
    """Outcome of one trial (one row of ``results.jsonl``) and its time series."""

    row: dict[str, Any]
    series: dict[str, np.ndarray] | None = None


@dataclass
class Book:
    """Per-trial bookkeeping arrays of a group of ``n`` trials (index = row of the group)."""

    n: int
    pos_tol: float
    ori_tol: float
    tail_start: int
    active: np.ndarray
    steps: np.ndarray
    settled: np.ndarray
    last_bad: np.ndarray
    converged: np.ndarray
    violations: np.ndarray
    refused: np.ndarray
    missed: np.ndarray
    hidden: np.ndarray
    recording: list[bool]
    failure: list[str | None] = field(default_factory=list)
    tail_pos: list[list[float]] = field(default_factory=list)
    tail_ori: list[list[float]] = field(default_factory=list)
    step_times: list[list[float]] = field(default_factory=list)
    rtts: list[list[float]] = field(default_factory=list)
    series: list[dict[str, list[Any]]] = field(default_factory=list)
    tracker: Any = None  # the tracking metrics of a trajectory task
    causes: dict[int, str] = field(default_factory=dict)  # a crash's cause, user's terms

    @classmethod
    def new(cls, sc: Scenario, group: list[TrialSetup], record_trials: int) -> Book:
        """Fresh bookkeeping of a group."""
        from benchmarks.sim.tracking import tracker_for

        n = len(group)
        recording = [s.trial < record_trials for s in group]
        pos_tol = 1e-3 * sc.task.position_tolerance_mm
        ori_tol = float(np.deg2rad(sc.task.orientation_tolerance_deg))
        return cls(
            n=n, pos_tol=1e-3 * sc.task.position_tolerance_mm,
            ori_tol=float(np.deg2rad(sc.task.orientation_tolerance_deg)),
            tail_start=sc.task.max_steps - max(1, sc.task.max_steps // 5),
            active=np.ones(n, dtype=bool), steps=np.zeros(n, dtype=int),
            settled=np.zeros(n, dtype=int), last_bad=np.full(n, -1),
            converged=np.zeros(n, dtype=bool), violations=np.zeros(n, dtype=int),
            refused=np.zeros(n, dtype=int), missed=np.zeros(n, dtype=int),
            hidden=np.zeros(n, dtype=int), recording=recording, failure=[None] * n,
            tail_pos=[[] for _ in range(n)], tail_ori=[[] for _ in range(n)],
            step_times=[[] for _ in range(n)], rtts=[[] for _ in range(n)],
            series=[{k: [] for k in SERIES_KEYS} if rec else {} for rec in recording],
            tracker=tracker_for(sc, group, pos_tol, ori_tol))

    def follow(self, plant: Any) -> None:
        """Let the tracking metrics sample ``plant``'s drive forces every period."""
        if self.tracker is not None:
            self.tracker.follow(plant)

    def check(self, sc: Scenario, step: int, idx: np.ndarray, dp: np.ndarray,
              da: np.ndarray) -> np.ndarray:
        """The convergence test of one period for the active rows ``idx`` (pose errors
        ``dp`` [m], ``da`` [rad]); returns which of them are done."""
        ok = (dp < self.pos_tol) & (da < self.ori_tol)
        if self.tracker is not None:
            self.tracker.add(step, idx, dp, da)
        self.settled[idx] = np.where(ok, self.settled[idx] + 1, 0)
        self.last_bad[idx[~ok]] = step
        if sc.task.fixed_duration and step > self.tail_start:
            for j, k in enumerate(idx):
                self.tail_pos[k].append(float(dp[j]))
                self.tail_ori[k].append(float(da[j]))
        if sc.task.fixed_duration:
            done = np.full(len(idx), step == sc.task.max_steps)
            self.converged[idx] = ok
        else:
            done = self.settled[idx] >= sc.task.settle_steps
            self.converged[idx[done]] = True
            if step == sc.task.max_steps:
                done[:] = True
        return done

    def seen(self, idx: np.ndarray, edge_visible: np.ndarray) -> None:
        """Count the periods where the rows ``idx`` measured fewer than their 12 edges."""
        self.hidden[idx] += ~np.asarray(edge_visible, dtype=bool).reshape(len(idx), -1).all(
            axis=1)

    def command(self, k: int, velocities: np.ndarray, reason: str | None) -> bool:
        """Account one command of row ``k``; returns True when the trial fails with it
        (an invalid command, or too many refusals in a row)."""
        vel = np.asarray(velocities, dtype=float)
        failed = False
        if vel.shape != (6,) or not np.all(np.isfinite(vel)):
            self.failure[k] = f"controller returned an invalid command {vel!r}"
            failed = True
        if reason is not None:
            self.refused[k] += 1
            if self.refused[k] >= MAX_REFUSED_STEPS:
                self.failure[k] = f"controller refused to move: {reason}"
                failed = True
        else:
            self.refused[k] = 0
        return failed

    def commands(self, rows: np.ndarray, velocities: np.ndarray, reasons: list[str | None]
                 ) -> np.ndarray:
        """:meth:`command` for many rows at once; returns the (n,) mask of failed rows."""
        rows = np.asarray(rows, dtype=int)
        v = np.asarray(velocities, dtype=float)
        invalid = ~np.isfinite(v).all(axis=1)
        if reasons.count(None) == len(reasons) and not invalid.any():  # the common case
            self.refused[rows] = 0
            return invalid
        refused = np.fromiter((r is not None for r in reasons), dtype=bool, count=len(rows))
        self.refused[rows[~refused]] = 0
        self.refused[rows[refused]] += 1
        too_many = refused & (self.refused[rows] >= MAX_REFUSED_STEPS)
        for j in np.flatnonzero(invalid & ~too_many):
            self.failure[rows[j]] = f"controller returned an invalid command {v[j]!r}"
        for j in np.flatnonzero(too_many):
            self.failure[rows[j]] = f"controller refused to move: {reasons[j]}"
        return invalid | too_many

    def crashed(self, rows: np.ndarray, crashes: dict[int, BaseException], label: str,
                step: int, scenario: str = "", trials: list[int] | None = None) -> np.ndarray:
        """End the rows whose controller raised at period ``step`` (``crashes``: by
        position in ``rows``), each with its exception; returns the (n,) mask of them.

        Args:
            scenario: The scenario's name and ``trials`` the trial index of each row of
                the group (for the log lines, as :func:`failure_row`'s).
        """
        mask = np.zeros(len(rows), dtype=bool)
        for j, exc in crashes.items():
            r = int(rows[j])
            mask[j] = True
            self.failure[r] = f"{label} failed at step {step}: {type(exc).__name__}: {exc}"
            self.causes[r] = user_message(exc)
            trial = trials[r] if trials is not None else r
            log.warning("trial %s/%s/%d failed at step %d: %s", scenario, label, trial, step,
                        self.causes[r], extra={"cause": self.causes[r]})
            if not isinstance(exc, HexapodError | VisionError | ControllerError):
                log.info("traceback of trial %s/%s/%d:\n%s", scenario, label, trial,
                         "".join(traceback.format_exception(exc)))
        return mask

    def world_failures(self, failed: dict[int, str], step: int) -> None:
        """End the rows whose true world failed during period ``step`` (a plant's
        :meth:`~benchmarks.sim.plant.Plant.advance`), each with its reason."""
        for k, reason in failed.items():
            self.failure[k] = reason
            self.active[k] = False
            self.steps[k] = step + 1

    def record(self, k: int, t: float, q: np.ndarray, R: np.ndarray, tr: np.ndarray,
               visible: np.ndarray, error_norm: float, dp: float, da: float,
               velocities: np.ndarray) -> None:
        """Append one period to row ``k``'s series."""
        ser = self.series[k]
        ser["t"].append(t)
        ser["lengths"].append(q.copy())
        ser["rotations"].append(R.copy())
        ser["translations"].append(tr.copy())
        ser["edge_visible"].append(np.array(visible, copy=True))
        ser["error_norm"].append(error_norm)
        ser["position_error"].append(dp)
        ser["orientation_error"].append(da)
        ser["velocities"].append(velocities.copy())

    def record_more(self, k: int, values: dict[str, np.ndarray]) -> None:
        """Append a plant's extra values of one period to row ``k``'s series
        (:meth:`benchmarks.sim.plant.Plant.series`)."""
        for key, value in values.items():
            self.series[k].setdefault(key, []).append(value)

    def results(self, sc: Scenario, spec: Any, group: list[TrialSetup], R: np.ndarray,
                t: np.ndarray, detect_times: list[float] | None = None,
                figures: Callable[[int], dict[str, Any]] | None = None) -> list[TrialResult]:
        """The result rows (and recorded series) of the group at the final poses
        (``figures``: a plant's extra figures of row ``m``)."""
        R_goal = np.array([s.goal_rotation for s in group])
        t_goal = np.array([s.goal_translation for s in group])
        dp, da = pose_error(R, t, R_goal, t_goal)
        out = []
        base = base_row(sc, spec, 0)
        for m, s in enumerate(group):
            row = dict(base)
            row["trial"] = int(s.trial)
            fail = self.failure[m]
            # a trial that failed (an end stop, a refused or invalid command) did not
            # converge, whatever its last convergence test said (a fixed-duration task
            # tests every period against the moving reference)
            conv = bool(self.converged[m]) and fail is None
            failed = fail is not None
            if fail is None and not conv:
                fail = unconverged_reason(sc.task, float(dp[m] * 1e3),
                                          float(np.rad2deg(da[m])))
            settle = int(self.last_bad[m] + 1) if sc.task.fixed_duration else int(self.steps[m])
            times = self.step_times[m]
            row.update({
                "converged": conv,
                "steps": settle,
                "final_position_error_mm": float(dp[m] * 1e3),
                "final_orientation_error_deg": float(np.rad2deg(da[m])),
                "stroke_violations": int(self.violations[m]),
                "hidden_edge_periods": int(self.hidden[m]),
                "step_time_us": float(statistics.median(times) * 1e6) if times else None,
                "failure": None if conv else fail,
            })
            if m in self.causes and not conv:
                row["cause"] = self.causes[m]
            if self.tail_pos[m]:
                # the seeds' "median positioning error of the convergence tail": the last 20 %
                row["tail_position_error_mm"] = float(np.median(self.tail_pos[m]) * 1e3)
                row["tail_orientation_error_deg"] = float(np.rad2deg(np.median(
                    self.tail_ori[m])))
            if detect_times:
                row["detect_time_ms"] = float(np.median(detect_times) * 1e3)
            if self.rtts[m]:
                arr = np.array(self.rtts[m]) * 1e3
                row["rtt_median_ms"] = float(np.median(arr))
                row["rtt_p99_ms"] = float(np.percentile(arr, 99))
                row["missed_periods"] = int(self.missed[m])
            if self.tracker is not None:
                row.update(self.tracker.row(m))
                if failed:  # it never reached the reference's end: it did not settle
                    row["settling_time_s"] = None
            if figures is not None:
                row.update(figures(m))
            for key, value in s.calibration.items():
                row[f"calibration_{key}"] = value
            ser_out = None
            if self.recording[m]:
                ser_out = {key: np.array(v) for key, v in self.series[m].items()}
                ser_out["goal_rotation"] = s.goal_rotation
                ser_out["goal_translation"] = s.goal_translation
            out.append(TrialResult(row, ser_out))
        return out


def base_row(sc: Scenario, spec: Any, trial: int) -> dict[str, Any]:
    """The identity of a result row: scenario, controller (with its package), trial, sweep."""
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


def failure_row(sc: Scenario, spec: Any, trial: int, exc: BaseException,
                batch: str | None = None, step: int = 0,
                errors: tuple[float, float] | None = None) -> dict[str, Any]:
    """The row of a trial that crashed (the crash is the trial's failure).

    Args:
        batch: How its batch failed (a batch stopped as a whole), or None.
        step: The period at which it happened.
        errors: The last position [m] and orientation [rad] errors measured, if any.
    """
    row = base_row(sc, spec, trial)
    finite = errors is not None and bool(np.all(np.isfinite(errors)))
    row.update({
        "converged": False, "steps": int(step),
        "final_position_error_mm": float(errors[0]) * 1e3 if finite and errors else None,
        "final_orientation_error_deg": (float(np.rad2deg(errors[1])) if finite and errors
                                        else None),
        "stroke_violations": 0, "step_time_us": None,
        "failure": (f"{batch}: " if batch else "") + f"{type(exc).__name__}: {exc}",
        "cause": user_message(exc),
    })
    # one line in the user's terms (the command line prints each cause once and counts
    # the repeats); the traceback of an unexpected error only with -v (INFO)
    log.warning("trial %s/%s/%d failed: %s", sc.name, spec.label, trial, row["cause"],
                extra={"cause": row["cause"]})
    if not isinstance(exc, HexapodError | VisionError | ControllerError):
        log.info("traceback of trial %s/%s/%d:\n%s", sc.name, spec.label, trial,
                 "".join(traceback.format_exception(exc)))
    return row
