"""The report's section on trajectory tasks: the tracking metrics of every controller at
every sweep point (:mod:`benchmarks.sim.tracking`), and the tracking error against time
of the recorded trial. In the dynamic world the table also gives the drives' forces (the
peak over every physics step, the RMS over the control instants, the time at a force
limit) and a second figure their forces against time (the figures:
:mod:`benchmarks.study.tracking_figures`)."""

from __future__ import annotations

import logging
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.study import exact, intervals, stats
from benchmarks.study.metrics import format_sweep, sweep_values

log = logging.getLogger(__name__)

#: Columns of the tracking table (medians with their 95 % intervals in the report).
HEADER = ["sweep", "controller", "trials", "failed", "RMS mm (median)", "RMS mm (p95)",
          "max mm (median)", "max mm (worst)", "RMS deg (median)", "settled",
          "settling s (median)"]
#: Columns added in the dynamic world (rows with drive figures).
FORCE_HEADER = ["peak N (median)", "peak N (worst)", "RMS N (median)", "at limit s (median)",
                "at limit s (worst)"]


def is_tracking(rows: list[dict[str, Any]]) -> bool:
    """Whether the rows are those of a trajectory task (they carry tracking figures)."""
    return any("tracking_rms_position_mm" in r for r in rows)


def _cells(values: list[Any], hows: list[str], with_intervals: bool) -> list[str]:
    """The statistics ``hows`` (``median``, ``p95``, ``max``) of the finite values: the
    quantiles with their order-statistic intervals when ``with_intervals``, the maximum
    without (no interval says anything about the largest of n draws)."""
    arr = stats.finite_values(values)
    if arr.size == 0:
        return ["-" for _ in hows]
    q = {"median": 0.5, "p95": 0.95}
    qs = [q[h] for h in hows if h in q]
    qcells = iter(intervals.quantile_cells(list(arr), qs) if with_intervals
                  else [_fmt(float(np.quantile(arr, x))) for x in qs])
    return [_fmt(float(arr.max())) if h == "max" else next(qcells) for h in hows]


def _settling_cell(rs: list[dict[str, Any]], with_intervals: bool) -> str:
    """Median settling time [s] over every trial, a trial that did not settle (or failed)
    censored at the run's end (``> run``: more than half did not settle), with its
    order-statistic interval in the report."""
    if not rs:
        return "-"
    t = np.array([np.inf if r.get("settling_time_s") is None else r["settling_time_s"]
                  for r in rs], dtype=float)
    med = exact.censored_quantile(t, 0.5)
    if not with_intervals:
        return "> run" if med == np.inf else _fmt(med)
    return intervals.censored_median_cell(t, 3, "run")


def _fmt(x: float) -> str:
    return "-" if not np.isfinite(x) else f"{x:.3g}"


def _dynamic(rows: list[dict[str, Any]]) -> bool:
    """Whether the rows carry the dynamic world's drive figures."""
    return any(r.get("max_leg_force_n") is not None for r in rows)


def tracking_header(rows: list[dict[str, Any]]) -> list[str]:
    """The columns of the table of ``rows`` (the force columns in the dynamic world)."""
    return HEADER + (FORCE_HEADER if _dynamic(rows) else [])


def _force_cells(rs: list[dict[str, Any]], with_intervals: bool) -> list[str]:
    """Peak force [N] (median and worst trial), RMS force [N] (median) and time at a force
    limit [s] (median and worst) of one (sweep point, controller) group."""
    return [*_cells([r.get("max_leg_force_n") for r in rs], ["median", "max"], with_intervals),
            *_cells([r.get("rms_leg_force_n") for r in rs], ["median"], with_intervals),
            *_cells([r.get("saturation_time_s") for r in rs], ["median", "max"],
                    with_intervals)]


def tracking_rows(rows: list[dict[str, Any]], with_intervals: bool = True
                  ) -> list[list[str]]:
    """The table rows: one per (sweep point, controller) of the trajectory trials (with
    :data:`FORCE_HEADER`'s cells in the dynamic world).

    The failed trials (:func:`benchmarks.study.failures.is_failure`: an end stop, a
    crash) are counted in *failed*, as not settled in *settled* (the rate over every
    trial, with its Wilson interval) and as censored at the run's end in the settling
    time (a failed trial never settled), and left out of the tracking errors and forces,
    which are those of the trials that ran to their end.

    Args:
        rows: The result rows of one scenario.
        with_intervals: Medians and 95th percentiles with their 95 % order-statistic
            intervals (the report), or the values alone (the terminal).
    """
    from benchmarks.study.failures import is_failure

    groups: dict[tuple[int, str], list[dict[str, Any]]] = defaultdict(list)
    for r in rows:
        groups[(int(r.get("point", 0)), str(r["controller"]))].append(r)
    forces = _dynamic([r for rs in groups.values() for r in rs])
    out = []
    for (_, controller), every in sorted(groups.items()):
        rs = [r for r in every if not is_failure(r)]
        settled = sum(1 for r in rs if r.get("settling_time_s") is not None)
        rate = (stats.format_rate(settled, len(every)) if with_intervals
                else f"{settled}/{len(every)}")
        out.append([
            format_sweep(sweep_values(every[0])), controller, str(len(every)),
            str(len(every) - len(rs)),
            *_cells([r.get("tracking_rms_position_mm") for r in rs], ["median", "p95"],
                    with_intervals),
            *_cells([r.get("tracking_max_position_mm") for r in rs], ["median", "max"],
                    with_intervals),
            *_cells([r.get("tracking_rms_orientation_deg") for r in rs], ["median"],
                    with_intervals),
            rate,
            _settling_cell(every, with_intervals),
            *(_force_cells(rs, with_intervals) if forces else [])])
    return out


def tracking_section(out_dir: Path, scenario: str, rows: list[dict[str, Any]],
                     points: list[int]) -> list[str]:
    """The Markdown lines of the section (none for a scenario without trajectories).

    Args:
        out_dir: The results directory (plots are written there).
        scenario: The scenario's name.
        rows: Its result rows.
        points: The sweep points to plot.
    """
    if not is_tracking(rows):
        return []
    table = tracking_rows(rows)
    lines = ["Trajectory tracking (error of the TRUE pose from the reference while it moves, "
             "medians and 95th percentiles with their 95 % intervals; *failed*: trials that "
             "did not run to their end (section Failures), left out of every other column; "
             "*settled*: trials within the tolerances at the end; *settling*: time from the "
             "reference's end until the error stays within them"
             + ("; *peak N*: largest drive force over every physics step; *RMS N*: drive "
                "forces at the control instants, all legs; *at limit*: time any drive spent "
                "at its force limit" if _dynamic(rows) else "") + "):", ""]
    header = tracking_header(rows)
    lines += ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(r) + " |" for r in table]
    lines.append("")
    from benchmarks.study.saturation_report import saturation_section

    lines += saturation_section(rows)
    from benchmarks.study.tracking_figures import forces_plots, tracking_plots

    force_images = forces_plots(out_dir, scenario, points)
    for p, img in tracking_plots(out_dir, scenario, points).items():
        sweep = next((format_sweep(sweep_values(r)) for r in rows
                      if int(r.get("point", 0)) == p), "")
        lines += [f"Tracking error versus time (sweep: {sweep}):", "",
                  f"![tracking error]({img})", ""]
        forces = force_images.get(p)
        if forces:
            lines += [f"Drive forces versus time (sweep: {sweep}):", "",
                      f"![drive forces]({forces})", ""]
    return lines
