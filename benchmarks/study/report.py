"""Markdown report with plots, rebuilt from ``results.jsonl`` at any time."""

from __future__ import annotations

import gc
import json
import logging
import math
from collections import defaultdict
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.study import curves_report, drawers, intervals, plots, profiles, stats
from benchmarks.study.intervals import format_value as _fmt
from benchmarks.study.metrics import Summary, format_sweep, summarize
from benchmarks.study.runner import deduplicate, machine_info, read_results
from benchmarks.study.study_record import command_lines
from benchmarks.study.tracking_report import tracking_section
from hexapod.outputs import TEXT_MARKER, replace_whole

log = logging.getLogger(__name__)

META_FILE = "run.json"


def summary_table_rows(summaries: list[Summary]) -> list[list[str]]:
    """Rows of the comparison table (shared by the terminal and the Markdown report)."""
    rows = []
    for s in summaries:
        rows.append([
            s.scenario, format_sweep(s.sweep), s.controller, s.backend,
            f"{100 * s.convergence_rate:.1f}% ({s.converged}/{s.trials})", str(s.failed),
            _fmt(s.position_median_mm), _fmt(s.position_p95_mm), _fmt(s.position_max_mm),
            _fmt(s.orientation_median_deg, 4), _fmt(s.orientation_max_deg, 4),
            "> run" if s.steps_median == np.inf else _fmt(s.steps_median, 0),
            _fmt(s.step_time_median_us, 1),
            str(s.stroke_violations),
        ])
    return rows


TABLE_HEADER = ["scenario", "sweep", "controller", "backend", "converged", "failed", "pos med mm",
                "pos p95 mm", "pos max mm", "rot med deg", "rot max deg", "steps med",
                "step us", "stroke viol."]
#: ``steps med``: median steps to converge (fixed-duration tasks: to settle within the
#: tolerances for good).


def _group(groups: dict[intervals.GroupKey, list[dict[str, Any]]], s: Summary
           ) -> list[dict[str, Any]]:
    """The rows of a summary's group."""
    return groups[(s.scenario, s.point, s.controller, s.backend)]


def _md_table(header: list[str], rows: list[list[str]]) -> str:
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(out)


def duplicate_note(dropped: int, conflicting: int) -> str:
    """What the report and the CLI say of duplicate trial rows."""
    text = (f"{dropped} duplicate row(s) ignored (several rows for one trial: two runs wrote "
            "into this directory); the first row of each trial is kept")
    if conflicting:
        text += f"; {conflicting} of them disagree with the kept row on the outcome"
    return text


def settings_lines(scenario_meta: dict[str, Any], out_dir: Path) -> list[str]:
    """The report's list of the settings that define a scenario's run (from ``run.json``)."""
    found = scenario_meta.get("settings")
    if not found:
        return []
    lines = ["Settings:", ""] + [f"- {k}: {v}" for k, v in found.items()]
    folder = (scenario_meta.get("inputs") or {}).get("folder")
    if folder:
        lines.append(f"- files: the scenario and every file it names are kept in `{folder}/` "
                     f"(rerun: `hexapod-bench run {out_dir / folder}/scenario.toml --out "
                     "NEW_DIR`)")
    return [*lines, ""]


def failures_section(rows: list[dict[str, Any]]) -> list[str]:
    """``## Failures``: the trials that did not run to their end, once per distinct cause
    with their count, controllers and sweep points, and the first one's full exception."""
    from benchmarks.study.failures import failure_groups

    groups = failure_groups(rows)
    if not groups:
        return []
    out = ["## Failures", "", f"{sum(g.count for g in groups)} of {len(rows)} trials did not "
           "run to their end; one entry per kind of cause (a measured value that differs "
           "between its trials given as its range):", ""]
    for g in groups:
        who = ", ".join(f"{c}: {n}" for c, n in sorted(g.controllers.items()))
        out += [f"- **{g.count} trial(s)** ({who}; sweep points: "
                f"{', '.join(sorted(g.points))}): {g.cause}",
                f"  - first: {g.example}"]
    return [*out, ""]


@dataclass
class ResultRows:
    """The rows of a results directory, read once (``results.jsonl`` without its duplicate
    rows: :func:`~benchmarks.study.results.deduplicate`) for the report, the terminal's
    table and the failure summary of ``run``.

    Attributes:
        rows: The rows, in file order.
        dropped: Duplicate rows dropped.
        conflicting: Dropped rows that disagree with the kept one.
    """

    rows: list[dict[str, Any]]
    dropped: int
    conflicting: int
    _summaries: list[Summary] | None = field(default=None, repr=False)

    def summaries(self) -> list[Summary]:
        """:func:`~benchmarks.study.metrics.summarize` of :attr:`rows` (computed once)."""
        if self._summaries is None:
            self._summaries = summarize(self.rows)
        return self._summaries


def import_drawing_modules() -> None:
    """Import the modules the report draws and tests with: matplotlib's figure on its
    Agg canvas (about 0.3 s) and ``scipy.special`` (the normal distribution of the
    Kaplan-Meier band and the log-rank test, about 0.15 s). ``run`` calls it in a thread
    while its workers run the trials, so that the report does not wait for them after."""
    from importlib import import_module

    for module in ("matplotlib.figure", "matplotlib.backends.backend_agg", "scipy.special"):
        import_module(module)


def read_rows(out_dir: Path) -> ResultRows:
    """The rows of ``out_dir/results.jsonl``, without duplicates."""
    return ResultRows(*deduplicate(read_results(Path(out_dir))))


def write_report(out_dir: Path, overwrite: bool = False,
                 results: ResultRows | None = None) -> Path:
    """Write ``DIR/report.md`` (and its PNG plots) from ``DIR/results.jsonl``.

    Args:
        out_dir: The results directory.
        overwrite: Replace a ``report.md`` the project did not write.
        results: Its rows when the caller has read them (:func:`read_rows`).

    Raises:
        OutputError: ``DIR/report.md`` is a file the project did not write (and not
            ``overwrite``).
        ResultsError: A figure could not be drawn (in the process that drew it:
            :func:`~benchmarks.study.drawers.drawing_aside`; report.md not written).
    """
    from benchmarks.study.outdir import check_report_file

    out_dir = Path(out_dir)
    results = results if results is not None else read_rows(out_dir)
    check_report_file(out_dir, overwrite)
    if results.dropped:
        log.warning("%s: %s", out_dir / "results.jsonl",
                    duplicate_note(results.dropped, results.conflicting))
    with _collector_paused(), drawers.drawing_aside(out_dir):  # figures on the idle cores
        lines = _report_lines(out_dir, results)
    # whole or not at all: a kill while writing it left an empty report.md, which
    # --resume then refused as not the project's
    return replace_whole(out_dir / "report.md", "\n".join(lines))


@contextmanager
def _collector_paused() -> Iterator[None]:
    """Python's cyclic garbage collector paused (if it runs) and resumed after: matplotlib
    makes many small objects while it draws, and the collections they trigger (each one
    visiting every object of a large process too) took about 6 % of a report's time; the
    figures' cycles are collected after."""
    if not gc.isenabled():
        yield
        return
    gc.disable()
    try:
        yield
    finally:
        gc.enable()


def incomplete_lines(study: dict[str, Any], rows: list[dict[str, Any]]) -> list[str]:
    """A note when a scenario's rows are fewer than its study plans (an interrupted run):
    the trials missing per controller over every sweep point the study plans (the
    product of its ``sweep.*`` lists), the sweep points and the controllers without any
    row (a report of such a run showed its tables as if whole)."""
    planned = study.get("trials")
    labels = [str(c).split(" (", 1)[0] for c in study.get("controllers") or []]
    if not isinstance(planned, int) or not labels or not rows:
        return []
    counts: dict[tuple[int, str], set[int]] = defaultdict(set)
    for r in rows:
        counts[(int(r.get("point", 0)), str(r["controller"]))].add(int(r["trial"]))
    seen = sorted({p for p, _ in counts})
    n_points = math.prod(len(v) for k, v in study.items()
                         if k.startswith("sweep.") and isinstance(v, list)) or 1
    points = sorted(set(range(n_points)) | set(seen))
    empty = [p for p in points if p not in seen]
    missing = {label: sum(planned - len(counts.get((p, label), ())) for p in points)
               for label in labels}
    absent = [label for label in labels if missing[label] == planned * len(points)]
    short = {label: m for label, m in missing.items() if m > 0 and label not in absent}
    if not absent and not short:
        return []
    total = planned * len(points) * len(labels)
    text = (f"**Incomplete**: {len(rows)} of the {total} trials planned ({planned} per "
            f"sweep point and controller, {len(points)} sweep point(s))")
    if short:
        text += "; missing " + ", ".join(f"{m} of {label}" for label, m in short.items())
    if absent:
        text += f"; no row of {', '.join(absent)}"
    if empty:
        text += f"; no row at sweep point(s) {', '.join(map(str, empty))}"
    return [text + ": an interrupted run (`--resume` finishes it); the tables hold the "
            "trials that ran.", ""]


def _report_lines(out_dir: Path, results: ResultRows) -> list[str]:
    """The lines of ``report.md`` (its figures saved on the way)."""
    rows, dropped, conflicting = results.rows, results.dropped, results.conflicting
    summaries = results.summaries()
    meta: dict[str, Any] = {}
    if (out_dir / META_FILE).exists():
        meta = json.loads((out_dir / META_FILE).read_text())
    info = machine_info()
    lines = ["# Benchmark report", "", f"<!-- {TEXT_MARKER}: hexapod-bench report -->", ""]
    lines.append(f"Generated {datetime.now(UTC).strftime('%Y-%m-%d %H:%M UTC')} from "
                 f"`{out_dir / 'results.jsonl'}` ({len(rows)} trials).")
    lines += command_lines(meta)
    from benchmarks.study.options_file import options_line

    lines += ["", options_line(meta)]
    if dropped:
        lines += ["", f"**Duplicate rows**: {duplicate_note(dropped, conflicting)}"]
    if meta.get("warnings"):
        lines += ["", "**Warnings of the run**:", ""] + [f"- {w}" for w in meta["warnings"]]
    lines += ["", "## Machine and libraries", ""]
    lines += [f"- {k}: {v}" for k, v in info.items()]
    if meta.get("wall_time_s") is not None:
        lines.append(f"- wall time of the last run: {meta['wall_time_s']:.1f} s "
                     f"({meta.get('workers', 1)} worker(s), executor {meta.get('executor')})")
    lines += ["", "## How to read this", "",
              "Each row is one controller at one point of the scenario's sweep. *converged*: "
              "trials whose true platform pose reached the position and orientation tolerances "
              "of the scenario. Final errors are those of the TRUE pose against the TRUE goal, "
              "over the trials that ran to their end (converged or not); *failed*: trials "
              "that did not run to their end (an end stop, a crash: section Failures), "
              "counted as not converged and left out of the error columns. *steps med*: "
              "median number of control "
              "periods to converge (for fixed-duration tasks: after which the error stayed "
              "within the tolerances), over every trial, a trial that did not converge "
              "counted as needing more than the run (`> N`). *step us*: the controller's "
              "time per trial within a period's batched step, median over the periods (it "
              "falls as more trials share a batch, and a batched law gains more than one "
              "stepped trial by trial: a cost to compare within one run, not across runs "
              "of other trial counts; `hexapod-bench perf controllers` times one step). "
              "*stroke viol.*: periods where a command would have "
              "driven a leg beyond its stroke (the backend clamped it).", "",
              intervals.method_note(), ""]
    groups = intervals.group_rows(rows)
    by_scenario: dict[str, list[Summary]] = defaultdict(list)
    for s in summaries:
        by_scenario[s.scenario].append(s)
    scen_meta = meta.get("scenarios", {})
    for name, ss in by_scenario.items():
        lines += [f"## Scenario `{name}`", ""]
        sm = scen_meta.get(name, {})
        if sm.get("description"):
            lines += [sm["description"], ""]
        lines += settings_lines(sm, out_dir)
        lines += incomplete_lines(sm.get("study") or {},
                                  [r for r in rows if r.get("scenario") == name])
        lines += [_md_table(TABLE_HEADER, intervals.summary_rows_with_intervals(ss, groups)),
                  ""]
        if any(np.isfinite(s.rtt_median_ms) for s in ss):
            lines += ["Robot link (communication time per period; *RTT median*: the median "
                      "over the trials of each trial's median, with its interval; *RTT p99*: "
                      "the largest of the trials' 99th percentiles):", ""]
            lines += [_md_table(["sweep", "controller", "backend", "RTT median ms",
                                 "RTT p99 ms", "missed periods"],
                                [[format_sweep(s.sweep), s.controller, s.backend,
                                  intervals.median_cell(_group(groups, s), "rtt_median_ms"),
                                  _fmt(s.rtt_p99_ms), str(s.missed_periods)]
                                 for s in ss]), ""]
        if any(np.isfinite(s.leg_force_max_n) for s in ss):
            lines += drive_section(ss, groups)
        if any(s.hidden_edge_periods for s in ss):
            lines += ["Visibility (periods where the camera saw fewer than the 12 edges, summed "
                      "over the trials; trials with at least one such period):", ""]
            lines += [_md_table(["sweep", "controller", "hidden-edge periods",
                                 "trials with a hidden edge"],
                                [[format_sweep(s.sweep), s.controller,
                                  str(s.hidden_edge_periods),
                                  f"{s.hidden_edge_trials}/{s.trials}: "
                                  f"{stats.format_rate(s.hidden_edge_trials, s.trials)}"]
                                 for s in ss]), ""]
        if any(np.isfinite(s.tail_position_median_mm) for s in ss):
            lines += ["Convergence tail (median of the position error over the last 20 % of "
                      "each fixed-duration trial, as the seeds read their tails):", ""]
            lines += [_md_table(["sweep", "controller", "tail median mm (median over trials)",
                                 "tail median mm (max over trials)"],
                                intervals.tail_rows(ss, groups)), ""]
        if any(np.isfinite(s.detect_time_median_ms) for s in ss):
            lines += ["Images in the loop (render, detect, estimate at every step):", ""]
            lines += [_md_table(["sweep", "controller", "detection median ms per frame"],
                                [[format_sweep(s.sweep), s.controller,
                                  intervals.median_cell(_group(groups, s), "detect_time_ms")]
                                 for s in ss]), ""]
        if any(np.isfinite(s.calibration_median_mm) or s.calibration_refused for s in ss):
            lines += ["Calibration of the base points before control (error per point: the "
                      "norm, and seed 001's measure, the largest error on any coordinate of "
                      "any point; "
                      "*ill-conditioned*: trials whose calibration warned that a leg's system "
                      "was below the warning ratio; *refused*: trials whose calibration "
                      "refused a leg below the hard limit, which then did not run):", ""]
            lines += [_md_table(intervals.CALIBRATION_HEADER,
                                intervals.calibration_rows(ss, groups)), ""]
        sweeps = {s.point: s.sweep for s in ss}
        scen_rows = [r for r in rows if r["scenario"] == name]
        lines += curves_report.time_to_converge_section(
            out_dir, name, scen_rows, sweeps, plots.representative(sorted(sweeps)))
        lines += curves_report.tolerance_section(scen_rows, sweeps)
        ref = sm.get("reference")
        if ref:
            lines += ["### The seed's figures beside ours", ""]
            if "text" in ref:
                lines += [str(ref["text"]), ""]
            if "rows" in ref and "header" in ref:
                lines += [_md_table([str(h) for h in ref["header"]],
                                    [[str(c) for c in r] for r in ref["rows"]]), ""]
        points = sorted({s.point for s in ss})
        lines += tracking_section(out_dir, name, [r for r in rows if r["scenario"] == name],
                                  plots.representative(points))
        for p, img in plots.time_series(out_dir, name, plots.representative(points)).items():
            sweep = format_sweep(next(s.sweep for s in ss if s.point == p))
            lines += [f"Error versus time, representative trial (sweep: {sweep}):", "",
                      f"![time series]({img})", ""]
        for img in plots.sweeps(out_dir, name, ss):
            lines += [f"![sweep]({img})", ""]
        heat = plots.heat_maps(out_dir, name, ss)
        if heat:
            lines += ["Convergence map (two swept axes): convergence rate and median final "
                      "position error at every point, one panel per controller:", "",
                      f"![convergence map]({heat})", ""]
        prof = profiles.plot_profiles(out_dir, name, [r for r in rows if r["scenario"] == name])
        if prof:
            lines += [profiles.profile_note(len({s.controller for s in ss})), "",
                      f"![performance profiles]({prof})", ""]
        cdf = plots.error_cdf(out_dir, name, [r for r in rows if r["scenario"] == name])
        if cdf:
            lines += ["Success against tolerance: the fraction of the trials whose final "
                      "position error is within each tolerance (the empirical CDF of the "
                      "errors, every trial" + (", all sweep points pooled" if len(points) > 1
                                               else "") + ", with 95 % Wilson bands):", "",
                      f"![error CDF]({cdf})", ""]
    return lines + failures_section(rows) + unconverged_lines(rows)


def unconverged_lines(rows: list[dict[str, Any]]) -> list[str]:
    """The report's count of the trials that ended outside the tolerances, by cause."""
    from benchmarks.sim.tolerance import outside_counts

    counts = outside_counts(rows)
    if not counts:
        return []
    kinds = ["position", "rotation", "position and rotation", "within, not settled"]
    return ["## Trials that ended outside the tolerances", "",
            "Trials that did not converge, by what was outside the tolerances at their end "
            "(each row's `failure` in results.jsonl gives the values, e.g. `not converged: "
            "rotation 0.0565 deg > 0.05 deg after 800 steps`):", "",
            _md_table(["controller", *kinds],
                      [[c, *(str(n.get(k, 0)) for k in kinds)] for c, n in counts.items()]),
            ""]


def drive_section(ss: list[Summary], groups: dict[intervals.GroupKey, list[dict[str, Any]]]
                  ) -> list[str]:
    """The dynamic world's drives: leg forces, saturation and tracking (markdown lines),
    medians and rates with their intervals, over the trials that ran to their end."""
    return ["Drives (dynamic world: the drives' forces on the legs, the time any drive spent "
            "at its force limit, the drive tracking error = velocity setpoint minus realised "
            "leg velocity, over every physics step; the trials that ran to their end, "
            "medians and rates with their 95 % intervals):", "",
            _md_table(intervals.DRIVE_HEADER, intervals.drive_rows(ss, groups)), ""]
