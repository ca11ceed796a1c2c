"""Aggregate result rows into per-(scenario, sweep point, controller) figures."""

from __future__ import annotations

import math
from collections import defaultdict
from dataclasses import dataclass
from typing import Any

import numpy as np

from benchmarks.study.stats import finite_values

#: Row keys that are not sweep values.
_NON_SWEEP = {
    "scenario", "controller", "controller_name", "controller_package", "controller_version",
    "trial", "point", "backend", "converged", "steps", "final_position_error_mm",
    "final_orientation_error_deg", "stroke_violations", "step_time_us", "failure",
    "rtt_median_ms", "rtt_p99_ms", "missed_periods", "detect_time_ms",
    "tail_position_error_mm", "tail_orientation_error_deg", "hidden_edge_periods",
    "cause",
    # the goal setting (benchmarks.sim.goal): the run's settings state it; a swept
    # setting has its sweep column, task_goal
    "goal",
    # the tracking metrics of a trajectory task (benchmarks.sim.tracking)
    "trajectory_duration_s", "tracking_rms_position_mm", "tracking_max_position_mm",
    "tracking_rms_orientation_deg", "tracking_max_orientation_deg", "settling_time_s",
    "rms_leg_force_n",
    # the dynamic world's drive figures (benchmarks.sim.dynamic_plant)
    "max_leg_force_n", "saturation_time_s", "drive_tracking_rms_mm_s",
    "drive_tracking_max_mm_s",
    # with a [payload]: the saturation per leg and the tracking while saturated
    "saturation_legs_s", "saturation_legs_fraction", "saturation_fraction",
    "saturated_periods", "tracking_saturated_rms_mm", "tracking_saturated_max_mm",
}


def sweep_values(row: dict[str, Any]) -> dict[str, Any]:
    """The sweep values of a row (keys like ``noise_amplitude_deg``)."""
    return {k: v for k, v in row.items() if k not in _NON_SWEEP
            and not k.startswith("calibration_")}


@dataclass
class Summary:
    """Figures of one controller at one sweep point of one scenario.

    ``failed`` counts the trials that did not run to their end
    (:func:`benchmarks.study.failures.is_failure`); they count in ``trials`` and as not
    converged, and are left out of the error, tail and drive figures, which are those of
    the trials that ran to their end.
    """

    scenario: str
    point: int
    sweep: dict[str, Any]
    controller: str
    package: str | None
    version: str | None
    backend: str
    trials: int
    converged: int
    crashed: int
    position_median_mm: float
    position_p95_mm: float
    position_max_mm: float
    orientation_median_deg: float
    orientation_p95_deg: float
    orientation_max_deg: float
    steps_median: float
    step_time_median_us: float
    stroke_violations: int
    rtt_median_ms: float
    rtt_p99_ms: float
    missed_periods: int
    calibration_median_mm: float
    calibration_max_mm: float
    detect_time_median_ms: float = float("nan")
    hidden_edge_periods: int = 0
    hidden_edge_trials: int = 0
    calibration_min_ratio: float = float("nan")
    calibration_ill_conditioned: int = 0
    calibration_refused: int = 0
    tail_position_median_mm: float = float("nan")
    tail_position_max_mm: float = float("nan")
    leg_force_max_n: float = float("nan")
    saturation_time_median_s: float = float("nan")
    saturated_trials: int = 0
    tracking_rms_median_mm_s: float = float("nan")
    tracking_max_mm_s: float = float("nan")
    failed: int = 0

    @property
    def convergence_rate(self) -> float:
        """Fraction of trials that converged."""
        return self.converged / self.trials if self.trials else float("nan")


def _stat(values: list[Any], fn: str) -> float:
    arr = finite_values(values)
    if arr.size == 0:
        return float("nan")
    if fn == "median":
        return float(np.median(arr))
    if fn == "p95":
        return float(np.percentile(arr, 95))
    if fn == "p99":
        return float(np.percentile(arr, 99))
    return float(np.max(arr))


def _censored_steps_median(rows: list[dict[str, Any]]) -> float:
    """Median steps to converge over every trial, a trial that did not converge (failed
    ones included) censored at the run's length: ``inf`` when the median is censored
    (more than half did not converge), not the median of the survivors."""
    from benchmarks.study.exact import censored_quantile

    steps = [float(r["steps"]) if r["converged"] and r.get("steps") is not None else math.inf
             for r in rows]
    return censored_quantile(steps, 0.5) if steps else float("nan")


def summarize(rows: list[dict[str, Any]]) -> list[Summary]:
    """One :class:`Summary` per (scenario, sweep point, controller, backend), sorted
    (the failed trials left out of the error figures, counted in ``failed``)."""
    from benchmarks.study.failures import is_failure

    groups: dict[tuple[str, int, str, str], list[dict[str, Any]]] = defaultdict(list)
    for r in rows:
        groups[(r["scenario"], int(r.get("point", 0)), r["controller"],
                r.get("backend", "sim"))].append(r)
    out = []
    for (scenario, point, controller, backend), rs in sorted(groups.items(),
                                                             key=lambda kv: kv[0]):
        done = [r for r in rs if not is_failure(r)]
        pos = [r["final_position_error_mm"] for r in done]
        ori = [r["final_orientation_error_deg"] for r in done]
        conv = [r for r in rs if r["converged"]]
        crashed = [r for r in rs if r["final_position_error_mm"] is None]
        out.append(Summary(
            scenario=scenario, point=point, sweep=sweep_values(rs[0]), controller=controller,
            package=rs[0].get("controller_package"), version=rs[0].get("controller_version"),
            backend=backend, trials=len(rs), converged=len(conv), crashed=len(crashed),
            position_median_mm=_stat(pos, "median"), position_p95_mm=_stat(pos, "p95"),
            position_max_mm=_stat(pos, "max"), orientation_median_deg=_stat(ori, "median"),
            orientation_p95_deg=_stat(ori, "p95"), orientation_max_deg=_stat(ori, "max"),
            steps_median=_censored_steps_median(rs),
            step_time_median_us=_stat([r["step_time_us"] for r in rs], "median"),
            stroke_violations=int(sum(r.get("stroke_violations") or 0 for r in rs)),
            rtt_median_ms=_stat([r.get("rtt_median_ms") for r in rs], "median"),
            rtt_p99_ms=_stat([r.get("rtt_p99_ms") for r in rs], "max"),
            missed_periods=int(sum(r.get("missed_periods") or 0 for r in rs)),
            calibration_median_mm=_stat([r.get("calibration_median_error_mm") for r in rs],
                                        "median"),
            calibration_max_mm=_stat([r.get("calibration_max_error_mm") for r in rs], "max"),
            detect_time_median_ms=_stat([r.get("detect_time_ms") for r in rs], "median"),
            hidden_edge_periods=int(sum(r.get("hidden_edge_periods") or 0 for r in rs)),
            hidden_edge_trials=sum(1 for r in rs if (r.get("hidden_edge_periods") or 0) > 0),
            calibration_min_ratio=-_stat([-(r["calibration_min_singular_ratio"])
                                          for r in rs
                                          if r.get("calibration_min_singular_ratio")
                                          is not None], "max"),
            calibration_ill_conditioned=sum(1 for r in rs
                                            if (r.get("calibration_ill_conditioned_legs")
                                                or 0) > 0),
            calibration_refused=sum(1 for r in rs if str(r.get("failure") or "").startswith(
                "CalibrationError")),
            tail_position_median_mm=_stat([r.get("tail_position_error_mm") for r in done],
                                          "median"),
            tail_position_max_mm=_stat([r.get("tail_position_error_mm") for r in done], "max"),
            failed=len(rs) - len(done),
            **_drive_figures(done),
        ))
    return out


def _drive_figures(rs: list[dict[str, Any]]) -> dict[str, Any]:
    """The dynamic world's drive figures of a group of rows (none in the kinematic world):
    the largest leg force, the median time at a force limit and the trials that reached
    one, the median RMS and the largest drive tracking error."""
    return {
        "leg_force_max_n": _stat([r.get("max_leg_force_n") for r in rs], "max"),
        "saturation_time_median_s": _stat([r.get("saturation_time_s") for r in rs], "median"),
        "saturated_trials": sum(1 for r in rs if (r.get("saturation_time_s") or 0) > 0),
        "tracking_rms_median_mm_s": _stat([r.get("drive_tracking_rms_mm_s") for r in rs],
                                          "median"),
        "tracking_max_mm_s": _stat([r.get("drive_tracking_max_mm_s") for r in rs], "max"),
    }


def format_sweep(sweep: dict[str, Any]) -> str:
    """``noise_amplitude_deg=0.05, calib_base_points_mm=1`` or ``-``."""
    if not sweep:
        return "-"
    return ", ".join(f"{k}={v}" for k, v in sweep.items())
