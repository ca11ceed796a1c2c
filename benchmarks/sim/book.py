"""The bookkeeping of a group of trials stepped together, the book of the closed loop
(:class:`benchmarks.sim.loop.LoopBook`): the convergence test of every period, the
failures, timings and recorded series, and the result rows (one row of ``results.jsonl``
per trial)."""

from __future__ import annotations

import logging
import statistics
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from benchmarks.exceptions import BatchFailedError, user_message
from benchmarks.sim.inputs import SimScenario
from benchmarks.sim.reference import Targets
from benchmarks.sim.tolerance import unconverged_reason
from benchmarks.sim.world import TrialSetup
from controllers.base import CommandBatch, ObservationBatch
from controllers.exceptions import ControllerError
from controllers.registry import registry
from hexapod.actuation import Actuation, check_actuation
from hexapod.exceptions import HexapodError
from hexapod.se3 import pose_error
from vision.exceptions import VisionError

log = logging.getLogger(__name__)

#: Consecutive refused steps after which a trial is declared failed.
MAX_REFUSED_STEPS = 25
#: The recorded time series of a trial.
SERIES_KEYS = ("t", "lengths", "rotations", "translations", "edge_visible", "error_norm",
               "position_error", "orientation_error", "velocities")
#: The series whose values are arrays of the loop's (copied when recorded).
COPIED = ("lengths", "rotations", "translations", "edge_visible", "velocities")
#: A live view's callback ``(trial, rotation, translation, edge_visible)``.
OnStep = Callable[[int, np.ndarray, np.ndarray, np.ndarray], None]


@dataclass
class TrialResult:
    """Outcome of one trial (one row of ``results.jsonl``) and its time series."""

    row: dict[str, Any]
    series: dict[str, np.ndarray] | None = None


class Book:
    """Per-trial bookkeeping arrays of a group of trials (index = row of the group).

    Args:
        sc: The scenario (its task, period and name).
        group: The trials.
        record_trials: Trials with an index below this keep their time series.
        plant: The loop's plant (its true state; the tracking metrics sample its drive
            forces).
        targets: The pose each row is measured against
            (:class:`~benchmarks.sim.reference.Targets`: ``(step, rows) -> (R, t)``, a
            trajectory's durations).
        actuation: What the controller declared it commands.
        label: The controller's label.
        on_step: A live view's callback (:data:`OnStep`).
    """

    def __init__(self, sc: SimScenario, group: list[TrialSetup], record_trials: int,
                 plant: Any, targets: Targets,
                 actuation: Actuation, label: str,
                 on_step: OnStep | None) -> None:
        from benchmarks.sim.tracking import Tracker

        n = len(group)
        task = self.task = sc.task
        self.pos_tol = 1e-3 * task.position_tolerance_mm
        self.ori_tol = float(np.deg2rad(task.orientation_tolerance_deg))
        tail = max(1, task.max_steps // 5)
        self.tail_start = task.max_steps - tail
        if not task.fixed_duration:
            tail = 0
        self.active = np.ones(n, dtype=bool)
        self.steps = np.zeros(n, dtype=int)
        self.settled = np.zeros(n, dtype=int)
        self.last_bad = np.full(n, -1)
        self.converged = np.zeros(n, dtype=bool)
        self.violations = np.zeros(n, dtype=int)
        self.refused = np.zeros(n, dtype=int)
        #: Whether a refusal with a non-zero command was logged (once per run of a group).
        self.warned_moving_refusal = False
        #: Each row's last refusal reason (while it is refusing).
        self.refusal: dict[int, str] = {}
        self.hidden = np.zeros(n, dtype=int)
        #: (n,) bool: the rows whose series are kept.
        self.recording = np.array([s.trial < record_trials for s in group], dtype=bool)
        self._recorded = np.flatnonzero(self.recording).tolist()
        self.failure: list[str | None] = [None] * n
        #: A fixed-duration task's position [m] and orientation [rad] errors of the periods
        #: after ``tail_start`` (column ``step - tail_start - 1``), and which were measured.
        self.tail_pos, self.tail_ori = np.zeros((n, tail)), np.zeros((n, tail))
        self.tail_seen = np.zeros((n, tail), dtype=bool)
        self.series: list[dict[str, list[Any]]] = [
            {k: [] for k in SERIES_KEYS} if rec else {} for rec in self.recording]
        self.tracker = (Tracker(sc, targets.duration) if targets.duration is not None
                        else None)  # a trajectory's metrics
        self.dt = sc.dt
        g = group[0].world.geometry
        self.stroke, self.max_speed = g.stroke, g.max_speed  # the true legs' limits [m, m/s]
        self.trials = [s.trial for s in group]  # the trial index of each row
        self.batch_times: list[float] = []  # controller time per row [s], every period
        self.stepped = np.zeros(n, dtype=int)  # periods each row was commanded
        self.scenario = sc.name  # (log lines)
        self.causes: dict[int, str] = {}  # a crash's cause, in the user's terms
        #: The last position [m] and orientation [rad] errors of every row (NaN before its
        #: first period): a batch that fails as a whole reports them.
        self.last_errors = (np.full(n, np.nan), np.full(n, np.nan))
        self._errors: tuple[np.ndarray, np.ndarray] | None = None  # this period's errors
        self.plant, self.targets = plant, targets
        self.actuation, self.label, self.on_step = actuation, label, on_step
        if self.tracker is not None:
            self.tracker.follow(plant)

    def check(self, step: int, idx: np.ndarray) -> np.ndarray:
        """The convergence test of one period for the active rows ``idx`` (their pose
        errors to their targets); returns which of them are done."""
        R, t = self.plant.R, self.plant.t
        # every row (idx: sorted distinct rows): the arrays themselves, slices, no copies
        rows: np.ndarray | slice = slice(None) if len(idx) == len(self.active) else idx
        dp, da = pose_error(R[rows], t[rows], *self.targets(step, rows))
        self._errors = (dp, da)
        self.last_errors[0][rows], self.last_errors[1][rows] = dp, da
        ok = (dp < self.pos_tol) & (da < self.ori_tol)
        if self.tracker is not None:
            self.tracker.add(step, rows, dp, da)
        if not ok.all():
            self.last_bad[idx[~ok]] = step
        task = self.task
        if task.fixed_duration:  # every row runs to max_steps: no settling count
            if step > self.tail_start:  # (columns: no row loop)
                col = step - self.tail_start - 1
                self.tail_pos[rows, col] = dp
                self.tail_ori[rows, col] = da
                self.tail_seen[rows, col] = True
            self.converged[rows] = ok
            return np.full(len(idx), step == task.max_steps)
        self.settled[idx] = np.where(ok, self.settled[idx] + 1, 0)
        done = self.settled[idx] >= task.settle_steps
        self.converged[idx[done]] = True
        if step == task.max_steps:
            done[:] = True
        return done

    def observed(self, step: int, idx: np.ndarray, obs: ObservationBatch) -> np.ndarray:
        """Count the periods where a row measured fewer than its 12 edges, show the live
        view; every row has its image."""
        visible = np.asarray(obs.edge_visible, dtype=bool)
        if not visible.all():  # (the common case: every edge of every row)
            seen = visible.reshape(len(idx), -1).all(axis=1)
            self.hidden[idx[~seen]] += 1
        if self.on_step is not None:
            R, t = self.plant.R, self.plant.t
            for j, k in enumerate(idx.tolist()):
                self.on_step(self.trials[k], R[k], t[k], obs.edge_visible[j])
        return np.ones(len(idx), dtype=bool)

    def commanded(self, step: int, rows: np.ndarray, commands: CommandBatch,
                  seconds: float, crashes: dict[int, BaseException]
                  ) -> tuple[np.ndarray, np.ndarray]:
        """Refuse a batch of another kind than declared or of another shape than one row
        of 6 per stepped row; a row fails (its command not applied) with an invalid
        command, after too many refusals in a row, or when its own controller raised
        (``crashes``: see :meth:`benchmarks.sim.loop.LoopBook.commanded`).

        Raises:
            ActuationError: The batch is of another kind than declared.
            CommandError: The batch is of another shape than ``(len(rows), 6)``.
        """
        shape, n, declared = np.shape(commands.values), len(rows), self.actuation
        if shape != (n, 6):
            from controllers.exceptions import CommandError

            raise CommandError(self.label, f"returned commands of shape {shape} for {n} "
                               f"trials; expected ({n}, 6): one row of 6 leg values per trial")
        if commands.actuation is not declared:
            check_actuation(commands.actuation, (declared,),
                            f"a study whose controller declared {declared.quantity}", self.label)
        self.batch_times.append(seconds)
        every: np.ndarray | slice = slice(None) if n == len(self.active) else rows
        self.stepped[every] += 1
        v, reasons = commands.values, commands.reasons
        invalid = ~np.isfinite(v).all(axis=1)
        if (not crashes and reasons.count(None) == len(reasons)
                and not invalid.any()):  # the common case
            self.refused[every] = 0
            return ~invalid, invalid
        refused = np.fromiter((r is not None for r in reasons), dtype=bool, count=len(rows))
        self.refused[rows[~refused]] = 0
        self.refused[rows[refused]] += 1
        for r in np.flatnonzero(refused).tolist():  # (what a world failure then follows)
            self.refusal[int(rows[r])] = str(reasons[r])
        too_many = refused & (self.refused[rows] >= MAX_REFUSED_STEPS)
        for j in np.flatnonzero(invalid & ~too_many):
            values = np.array2string(v[j], separator=", ", max_line_width=10**6)
            legs = np.flatnonzero(~np.isfinite(v[j])).tolist()
            what = (f"a non-finite command for leg{'s' if len(legs) > 1 else ''} "
                    f"{', '.join(map(str, legs))} ({', '.join(str(v[j, i]) for i in legs)})")
            self.failure[rows[j]] = (f"controller {self.label!r} returned {what} at step "
                                     f"{step}: {values}")
            self.causes[int(rows[j])] = f"controller {self.label!r} returned {what}"
        for j in np.flatnonzero(too_many):
            self.failure[rows[j]] = f"controller refused to move: {reasons[j]}"
        failed = invalid | too_many
        if crashes:
            failed |= self._crashed(step, rows, crashes)
        moving = refused & ~failed & np.any(v != 0, axis=1)
        if moving.any() and not self.warned_moving_refusal:
            self.warned_moving_refusal = True
            log.warning("%s: controller %r refused trial %d with a non-zero command at step "
                        "%d; a refusal is a zero command (its values are not applied)",
                        self.scenario, self.label, self.trials[int(rows[np.argmax(moving)])],
                        step)
        return ~failed & ~refused, failed

    def _crashed(self, step: int, rows: np.ndarray, crashes: dict[int, BaseException]
                 ) -> np.ndarray:
        """End the rows whose controller raised at period ``step`` (``crashes``: by
        position in ``rows``), each with its exception; returns the (n,) mask of them."""
        mask = np.zeros(len(rows), dtype=bool)
        label, scenario = self.label, self.scenario
        for j, exc in crashes.items():
            r = int(rows[j])
            mask[j] = True
            self.failure[r] = f"{label} failed at step {step}: {type(exc).__name__}: {exc}"
            self.causes[r] = log_failure(scenario, label, self.trials[r], exc,
                                         f" at step {step}")
        return mask

    def stopped(self, step: int, exc: Exception) -> BaseException:
        """A :class:`~benchmarks.exceptions.BatchFailedError` with the last errors of every
        row (each trial of the group gets a failure row saying so; nothing is rerun)."""
        return BatchFailedError(step, self.last_errors, exc)

    def period(self, step: int, idx: np.ndarray, done: np.ndarray, obs: ObservationBatch,
               error_norm: np.ndarray, values: np.ndarray) -> None:
        """Record the period of the recorded rows (with the plant's extra values), end
        the ``done`` rows, count the leg velocity commands that would leave the stroke."""
        plant = self.plant
        dp, da = self._errors  # type: ignore[misc]
        full = len(idx) == len(self.active)  # (idx: sorted distinct rows)
        for j in (self._recorded if full else np.flatnonzero(self.recording[idx]).tolist()):
            r = int(idx[j])
            ser = self.series[r]
            for key, value in zip(SERIES_KEYS, (
                    step * self.dt, plant.q[r], plant.R[r], plant.t[r], obs.edge_visible[j],
                    error_norm[j], dp[j], da[j], values[j]), strict=True):
                ser[key].append(np.array(value, copy=True) if key in COPIED else value)
            for key, value in plant.series(r).items():
                ser.setdefault(key, []).append(value)
        run: np.ndarray | slice = slice(None) if full else idx
        if done.any():
            finished = idx[done]
            self.active[finished] = False
            self.steps[finished] = step
            run, values = idx[~done], values[~done]
        if self.actuation is Actuation.VELOCITY and len(values):
            self.violations[run] += stroke_violations(
                plant.q[run], values, self.dt, self.stroke, self.max_speed)

    def advanced(self, step: int, run: np.ndarray, failures: dict[int, str]) -> None:
        """End the rows whose true world failed during the period, each with its reason."""
        for k, reason in failures.items():
            if self.refused[k]:  # the world failed under a controller that refused
                reason += (f" (the controller had refused to move for the last "
                           f"{self.refused[k]} period(s): {self.refusal.get(k)})")
            self.failure[k] = reason
            self.active[k] = False
            self.steps[k] = step + 1

    def results(self, sc: SimScenario, spec: Any, group: list[TrialSetup], R: np.ndarray,
                t: np.ndarray, detect_times: list[float] | None = None,
                figures: Callable[[int], dict[str, Any]] | None = None) -> list[TrialResult]:
        """The result rows (and recorded series) of the group at the final poses
        (``figures``: a plant's extra figures of row ``m``)."""
        per_row = np.array(self.batch_times)  # a row is commanded from step 0 until done
        R_goal = np.array([s.goal_rotation for s in group])
        t_goal = np.array([s.goal_translation for s in group])
        dp, da = pose_error(R, t, R_goal, t_goal)
        out = []
        base = base_row(sc, spec, 0)
        medians: dict[int, float | None] = {}  # [us], by the periods a row was commanded
        # the tail medians of the rows measured at every period of it, in two calls (the
        # same numbers as row by row: order statistics)
        full = np.asarray(self.tail_seen.all(axis=1) if self.tail_seen.size
                          else np.zeros(len(group), bool))
        tails = {"tail_position_error_mm": np.median(self.tail_pos[full], axis=1) * 1e3,
                 "tail_orientation_error_deg": np.rad2deg(np.median(self.tail_ori[full], axis=1))
                 } if full.any() else {}
        at = np.cumsum(full) - 1  # a full row's place among them
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
            k = int(self.stepped[m])
            if k not in medians:
                times = per_row[:k].tolist()
                medians[k] = float(statistics.median(times) * 1e6) if times else None
            row.update({
                "converged": conv,
                "steps": settle,
                "final_position_error_mm": float(dp[m] * 1e3),
                "final_orientation_error_deg": float(np.rad2deg(da[m])),
                "stroke_violations": int(self.violations[m]),
                "hidden_edge_periods": int(self.hidden[m]),
                "step_time_us": medians[k],
                "failure": None if conv else fail,
            })
            if m in self.causes and not conv:
                row["cause"] = self.causes[m]
            seen = self.tail_seen[m] if self.tail_seen.size else None
            if full[m]:
                row.update({key: float(v[at[m]]) for key, v in tails.items()})
            elif seen is not None and seen.any():
                # the seeds' "median positioning error of the convergence tail": the last 20 %
                row["tail_position_error_mm"] = float(np.median(self.tail_pos[m][seen]) * 1e3)
                row["tail_orientation_error_deg"] = float(np.rad2deg(np.median(
                    self.tail_ori[m][seen])))
            if detect_times:
                row["detect_time_ms"] = float(np.median(detect_times) * 1e3)
            if self.tracker is not None:
                row.update(self.tracker.row(m, int(self.last_bad[m])))
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


def stroke_violations(q: np.ndarray, v: np.ndarray, dt: float,
                      stroke: tuple[float, float], max_speed: float) -> np.ndarray:
    """(n,) 1 where the (speed-limited) command would leave the stroke this period."""
    q_next = q + np.clip(v, -max_speed, max_speed) * dt
    return np.any((q_next < stroke[0] - 1e-9) | (q_next > stroke[1] + 1e-9), axis=1)


def base_row(sc: SimScenario, spec: Any, trial: int) -> dict[str, Any]:
    """The identity of a result row: scenario, controller (with its package), trial, the
    goal setting (``[task] goal``), sweep."""
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
        "goal": getattr(sc.task, "goal", "mixed"),  # the goal setting (benchmarks.sim.goal)
    }
    for key, value in sc.sweep.items():
        row[key.replace(".", "_").replace("calibration_error_", "calib_")] = value
    return row


def failure_row(sc: SimScenario, spec: Any, trial: int, exc: BaseException,
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
        "cause": log_failure(sc.name, spec.label, trial, exc),
    })
    return row


def log_failure(scenario: str, label: str, trial: int, exc: BaseException, when: str = ""
                ) -> str:
    """Log a trial's failure in one line in the user's terms (the command line prints
    each cause once and counts the repeats), the traceback of an unexpected error only
    with -v (INFO); returns that cause (:func:`benchmarks.exceptions.user_message`)."""
    cause = user_message(exc)
    log.warning("trial %s/%s/%d failed%s: %s", scenario, label, trial, when, cause,
                extra={"cause": cause})
    if not isinstance(exc, HexapodError | VisionError | ControllerError):
        log.info("traceback of trial %s/%s/%d:\n%s", scenario, label, trial,
                 "".join(traceback.format_exception(exc)))
    return cause
