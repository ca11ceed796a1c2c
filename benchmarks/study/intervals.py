"""Table cells with their 95 % intervals for the Markdown report.

Rates get the Wilson score interval, medians and 95th percentiles the distribution-free
order-statistic interval (:mod:`benchmarks.study.exact`; a step count of a trial that
did not converge is censored at the run's length and printed ``> N``); a maximum gets
none (no interval says anything about the largest of n draws without a model of the
tail).
"""

from __future__ import annotations

import math
from collections import defaultdict
from typing import Any

import numpy as np

from benchmarks.study import exact, stats
from benchmarks.study.metrics import Summary, format_sweep

GroupKey = tuple[str, int, str, str]


def format_value(x: float | None, digits: int = 3) -> str:
    """A table's value with ``digits`` decimals (``-`` for none; powers of ten for the very
    small and the very large); with 0 decimals (step counts) a median between two counts
    keeps its half: ``98.5``, not ``98`` (Python rounds a half to even)."""
    if x is None or not np.isfinite(x):
        return "-"
    if x != 0 and (abs(x) < 10 ** (-digits) or abs(x) >= 1e5):
        return f"{x:.2e}"
    if digits == 0 and x != round(x):
        return f"{x:.1f}"
    return f"{x:.{digits}f}"


def group_rows(rows: list[dict[str, Any]]) -> dict[GroupKey, list[dict[str, Any]]]:
    """Rows by (scenario, sweep point, controller, backend), the groups of
    :func:`benchmarks.study.metrics.summarize`."""
    groups: dict[GroupKey, list[dict[str, Any]]] = defaultdict(list)
    for r in rows:
        groups[(r["scenario"], int(r.get("point", 0)), r["controller"],
                r.get("backend", "sim"))].append(r)
    return groups


def _bound(x: float, digits: int, cap: float | str | None) -> str:
    """One end of an interval: ``> cap`` for a censored value (``cap``: the run's length,
    or a word, ``run``), ``-inf``/``inf`` for an end outside the sample (too few trials
    for that side at 95 %)."""
    if x == np.inf and cap is not None:
        return f"> {cap if isinstance(cap, str) else format_value(cap, digits)}"
    if np.isinf(x):
        return "-inf" if x < 0 else "inf"
    return format_value(x, digits)


def with_interval(value: float, interval: tuple[float, float], digits: int = 3,
                  cap: float | str | None = None) -> str:
    """``0.049 [0.047, 0.051]`` (``-`` for a missing value; with ``cap``, an infinite
    value or end is a censored one, ``> cap``: ``> 500 [431, > 500]``)."""
    if value is None or np.isnan(value):
        return "-"
    low, high = interval
    text = _bound(value, digits, cap) if cap is not None else format_value(value, digits)
    if np.isnan(low) or np.isnan(high):
        return text
    return f"{text} [{_bound(low, digits, cap)}, {_bound(high, digits, cap)}]"


def quantile_cells(values: list[Any], quantiles: list[float], digits: int = 3) -> list[str]:
    """Quantiles of the finite values with their order-statistic intervals."""
    arr = stats.finite_values(values)
    if arr.size == 0:
        return ["-" for _ in quantiles]
    return [with_interval(float(np.quantile(arr, q)), exact.quantile_interval(arr, q), digits)
            for q in quantiles]


def censored_steps(rows: list[dict[str, Any]], run: float = math.nan
                   ) -> tuple[np.ndarray, float | None]:
    """The steps to converge of a group's trials, ``+inf`` for a trial that did not
    converge (failed ones included: they count as not converged), and the cap (the run's
    length ``run``, :func:`benchmarks.study.stats.run_length` of the sweep point, at
    least the longest run of the group; None when every trial converged)."""
    out = np.array([float(r["steps"]) if r.get("converged") else np.inf for r in rows])
    cap = float(np.nanmax([stats.run_length(rows), run]))
    return out, (cap if np.isfinite(cap) and not np.isfinite(out).all() else None)


def censored_median_cell(values: np.ndarray, digits: int, cap: float | str | None) -> str:
    """The median of a sample whose censored values are ``+inf`` with its order-statistic
    interval: ``> cap`` where the median or an end is a censored value, ``-inf``/``inf``
    where an end lies outside the sample (too few values for that side at 95 %, which
    says nothing of censoring)."""
    x = np.sort(values[~np.isnan(values)])
    if x.size == 0:
        return "-"
    lo, hi = exact.order_statistic_ranks(int(x.size), 0.5)
    low = "-inf" if lo is None else _bound(float(x[lo]), digits, cap)
    high = "inf" if hi is None else _bound(float(x[hi]), digits, cap)
    return f"{_bound(exact.censored_quantile(x, 0.5), digits, cap)} [{low}, {high}]"


def steps_cell(rows: list[dict[str, Any]], run: float = math.nan) -> str:
    """Median steps to converge over all the trials of a group, the ones that did not
    converge censored at the run's length (no survivorship: a controller that converges
    on half its trials has a median at the cap), with the order-statistic interval:
    ``> 500 [312, > 500]`` (``run``: :func:`censored_steps`)."""
    steps, cap = censored_steps(rows, run)
    return censored_median_cell(steps, 0, cap)


def completed(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The rows of the trials that ran to their end (the failed ones left out of the
    error statistics; the tables count them apart)."""
    from benchmarks.study.failures import is_failure

    return [r for r in rows if not is_failure(r)]


def summary_rows_with_intervals(summaries: list[Summary],
                                groups: dict[GroupKey, list[dict[str, Any]]]
                                ) -> list[list[str]]:
    """The rows of the report's main table (columns of
    :data:`benchmarks.study.report.TABLE_HEADER`), with intervals; the error columns
    over the trials that ran to their end."""
    runs: dict[tuple[str, int], list[dict[str, Any]]] = defaultdict(list)
    for (scenario, point, _, _), group in groups.items():  # the run's length: a point's
        runs[(scenario, point)] += group  # longest run, all controllers
    run = {key: stats.run_length(rs) for key, rs in runs.items()}
    out = []
    for s in summaries:
        rs = completed(groups[(s.scenario, s.point, s.controller, s.backend)])
        pos_med, pos_p95 = quantile_cells([r["final_position_error_mm"] for r in rs],
                                          [0.5, 0.95])
        rot_med, = quantile_cells([r["final_orientation_error_deg"] for r in rs], [0.5], 4)
        steps = steps_cell(groups[(s.scenario, s.point, s.controller, s.backend)],
                           run[(s.scenario, s.point)])
        out.append([
            s.scenario, format_sweep(s.sweep), s.controller, s.backend,
            stats.format_rate(s.converged, s.trials), str(s.failed), pos_med, pos_p95,
            format_value(s.position_max_mm), rot_med, format_value(s.orientation_max_deg, 4), steps,
            format_value(s.step_time_median_us, 1), str(s.stroke_violations),
        ])
    return out


def tail_rows(summaries: list[Summary], groups: dict[GroupKey, list[dict[str, Any]]]
              ) -> list[list[str]]:
    """Rows of the convergence-tail table: median over trials with its interval, max."""
    out = []
    for s in summaries:
        rs = completed(groups[(s.scenario, s.point, s.controller, s.backend)])
        med, = quantile_cells([r.get("tail_position_error_mm") for r in rs], [0.5])
        out.append([format_sweep(s.sweep), s.controller, med, format_value(s.tail_position_max_mm)])
    return out


def calibration_rows(summaries: list[Summary], groups: dict[GroupKey, list[dict[str, Any]]]
                     ) -> list[list[str]]:
    """Rows of the calibration table: the per-point norm (median with its interval, max)
    and seed 001's measure, the largest error on any coordinate of any base point."""
    out = []
    for s in summaries:
        rs = groups[(s.scenario, s.point, s.controller, s.backend)]
        med, = quantile_cells([r.get("calibration_median_error_mm") for r in rs], [0.5])
        comp = [r.get("calibration_max_component_error_mm") for r in rs]
        comp_f = [c for c in comp if c is not None and np.isfinite(c)]
        out.append([format_sweep(s.sweep), s.controller, med, format_value(s.calibration_max_mm),
                    format_value(max(comp_f)) if comp_f else "-",
                    format_value(s.calibration_min_ratio, 4),
                    f"{s.calibration_ill_conditioned}/{s.trials}",
                    f"{s.calibration_refused}/{s.trials}"])
    return out


def median_cell(rows: list[dict[str, Any]], key: str, digits: int = 3) -> str:
    """The median over the rows of a per-trial figure (``rtt_median_ms``,
    ``detect_time_ms``...) with its order-statistic interval."""
    cell, = quantile_cells([r.get(key) for r in rows], [0.5], digits)
    return cell


DRIVE_HEADER = ["sweep", "controller", "max leg force N", "saturation s (median)",
                "trials saturated", "tracking RMS mm/s (median)", "tracking max mm/s"]


def drive_rows(summaries: list[Summary], groups: dict[GroupKey, list[dict[str, Any]]]
               ) -> list[list[str]]:
    """Rows of the dynamic world's drives table (:data:`DRIVE_HEADER`), over the trials
    that ran to their end: the largest force, the median time at a force limit with its
    interval, the trials that reached a limit (rate with its Wilson interval), the
    median drive tracking RMS with its interval and the largest drive tracking error."""
    out = []
    for s in summaries:
        rs = completed(groups[(s.scenario, s.point, s.controller, s.backend)])
        sat, = quantile_cells([r.get("saturation_time_s") for r in rs], [0.5])
        rms, = quantile_cells([r.get("drive_tracking_rms_mm_s") for r in rs], [0.5])
        out.append([format_sweep(s.sweep), s.controller, format_value(s.leg_force_max_n, 1), sat,
                    stats.format_rate(s.saturated_trials, len(rs)), rms,
                    format_value(s.tracking_max_mm_s, 1)])
    return out


CALIBRATION_HEADER = ["sweep", "controller", "median error mm (per point)",
                      "max error mm (per point)", "max coordinate error mm (seed 001)",
                      "min singular ratio", "ill-conditioned", "refused"]


def method_note() -> str:
    """How the report's intervals are computed (seed and resamples included)."""
    return (f"Intervals are {100 * stats.LEVEL:.0f} % confidence intervals: Wilson score "
            "intervals (no continuity correction) for the convergence rates, "
            "distribution-free order-statistic intervals (from the binomial distribution "
            "of the ranks) for the medians and 95th percentiles, over the trials of the "
            "row; `-inf`/`inf`: too few trials to bound that side. *steps med* counts "
            "every trial, a trial that did not converge censored at the run's length: "
            "`> 500` is a median or an end known only to exceed the 500 steps run. "
            "Maxima have none. `hexapod-bench compare DIR` tests the differences between "
            "controllers on the trials they share.")
