"""The analysis commands of ``hexapod-bench``: ``export``, ``compare``, ``reproduce``.

They read run directories written by ``hexapod-bench run`` (``reproduce``, in
:mod:`benchmarks.study.reproduce_cli`, runs the built-in scenarios first).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

from benchmarks.study.outdir import OutputFile, add_command


def cmd_export(args: argparse.Namespace) -> int:
    """Write a run's trials as a Parquet table (one row per trial)."""
    from benchmarks.study.table import export_parquet

    path, n = export_parquet(Path(args.dir), Path(args.parquet), args.overwrite)
    print(f"wrote {n} trials of {args.dir} to {path} (read it back with "
          f"pandas.read_parquet('{path}'))")
    return 0


def _num(v: float, spec: str) -> str:
    """A value, ``censored`` for an infinite one (steps of trials that did not converge)."""
    if v is None or v != v:
        return "-"
    if v in (float("inf"), float("-inf")):
        return "censored" if v > 0 else "-censored"
    return format(v, spec)


def _fmt_value(c: Any, v: float) -> str:
    if v is None or v != v:
        return "-"
    return f"{100 * v:.1f} %" if c.metric == "converged" else _num(v, ".4g")


def _fmt_diff(c: Any) -> str:
    lo, hi = c.interval
    if c.difference != c.difference and lo != lo and hi != hi:
        return "-"
    if c.metric == "converged":
        return f"{100 * c.difference:+.1f} [{100 * lo:+.1f}, {100 * hi:+.1f}] pts"
    return f"{_num(c.difference, '+.3g')} [{_end(lo, '+.3g')}, {_end(hi, '+.3g')}]"


def _end(v: float, spec: str) -> str:
    """An interval's end: ``-inf``/``inf`` where it has no finite bound (outside the
    sample, or on a censored pair), never ``-censored`` (which read as the other
    controller's censoring)."""
    if v is not None and v in (float("inf"), float("-inf")):
        return "inf" if v > 0 else "-inf"
    return _num(v, spec)


def _fmt_verdict(c: Any, runs: tuple[str, str] | None) -> str:
    """The table's verdict cell: who is better, equivalent within the margin, or ``-``
    (not shown different, not shown equivalent)."""
    from benchmarks.study.compare import margin_text

    if c.better is not None:
        if runs is None:
            return f"{c.better} better"
        return f"{runs[0] if c.better == c.a else runs[1]} better"
    if c.outcome == "equivalent":
        return f"equivalent {margin_text(c)}"
    if c.outcome == "unclear":
        return "differ, side unclear"
    return "-"


def parse_margins(items: list[str] | None) -> dict[str, float]:
    """``--margin NAME=VALUE`` options as margins by metric (``converged`` given in
    percentage points, returned as a fraction).

    Raises:
        BenchmarkError: An item that is not ``NAME=NUMBER``.
    """
    from benchmarks.exceptions import BenchmarkError

    out: dict[str, float] = {}
    for item in items or []:
        name, sep, value = item.partition("=")
        try:
            number = float(value)
        except ValueError:
            number = float("nan")
        if not sep or not name or number != number:
            raise BenchmarkError(f"--margin {item!r}: expected NAME=NUMBER, e.g. "
                                 "final_error=0.01 (mm) or converged=5 (points)")
        if name == "converged" and not 0 < number <= 100:  # (said in the user's points)
            raise BenchmarkError(f"--margin {item}: converged's margin is in percentage "
                                 "points, in (0, 100]")
        out[name] = number / 100 if name == "converged" else number
    return out


def print_comparisons(comparisons: list[Any], title: str,
                      runs: tuple[str, str] | None = None) -> None:
    """The comparison table (fitted to the terminal), then the significant differences in
    plain words.

    Args:
        comparisons: From :func:`benchmarks.study.compare.compare_controllers` or
            :func:`benchmarks.study.compare.compare_runs`.
        title: The table's title.
        runs: Two runs: the names of run B and run A, which head their columns (one
            row per controller); None: one run (a row per pair of controllers).
    """
    from benchmarks.study.commands import console
    from benchmarks.study.compare import ALPHA
    from benchmarks.study.exact import format_p
    from benchmarks.study.fit_table import print_table

    con = console()
    if runs is None:
        header = ["scenario", "sweep", "a", "b", "metric", "n", "a's value", "b's value",
                  "a - b [95 % CI]", "test", "p", "p Holm", "TOST p Holm", "verdict"]
        keys: tuple[int, ...] = (0, 1, 2, 3, 4)
        rows = [[c.scenario, c.sweep, c.a, c.b, c.metric, str(c.n), _fmt_value(c, c.a_value),
                 _fmt_value(c, c.b_value), _fmt_diff(c), c.test, format_p(c.p_value),
                 format_p(c.p_holm), format_p(c.p_equivalence_holm), _fmt_verdict(c, None)]
                for c in comparisons]
    else:
        name_b, name_a = runs
        header = ["scenario", "sweep", "controller", "metric", "n", name_b, name_a,
                  f"{name_b} - {name_a} [95 % CI]", "test", "p", "p Holm", "TOST p Holm",
                  "verdict"]
        keys = (0, 1, 2, 3)
        rows = [[c.scenario, c.sweep, c.a.split(":", 1)[-1], c.metric, str(c.n),
                 _fmt_value(c, c.a_value), _fmt_value(c, c.b_value), _fmt_diff(c), c.test,
                 format_p(c.p_value), format_p(c.p_holm), format_p(c.p_equivalence_holm),
                 _fmt_verdict(c, runs)]
                for c in comparisons]
    print_table(con, title, header, rows, keys=keys, left=(*keys, len(header) - 1),
                escape_cells=True, wrap=(1,))  # sweeps and intervals hold brackets
    significant = [c for c in comparisons if c.better is not None]
    con.print(f"Significant at {100 * ALPHA:.0f} % after Holm's correction within each "
              f"metric (the family-wise error holds per metric, not over the list; "
              f"{len(significant)} of {len(comparisons)} comparisons):")
    _print_verdicts(con, significant,
                    "- none: no difference between these controllers is significant")
    unclear = [c for c in comparisons if c.outcome == "unclear"]
    if unclear:
        con.print(f"Significant tests whose difference's interval does not say which is "
                  f"better (not counted above; {len(unclear)} of {len(comparisons)}):")
        _print_verdicts(con, unclear, "")
    equivalent = [c for c in comparisons if c.outcome == "equivalent"]
    open_ = [c for c in comparisons if c.outcome == "not shown equivalent"]
    con.print(f"Equivalent within their margins (TOST at {100 * ALPHA:.0f} % after Holm's "
              f"correction, whose interval is the {100 - 200 * ALPHA:.0f} % one: a 95 % "
              f"interval below may reach past the margin; {len(equivalent)} of "
              f"{len(comparisons)} comparisons):")
    _print_verdicts(con, equivalent, "- none")
    con.print(f"Neither shown different nor shown equivalent: {len(open_)} of "
              f"{len(comparisons)} comparisons (no conclusion: more trials, or a wider "
              "margin with --margin NAME=VALUE)")


def _print_verdicts(con: Any, comparisons: list[Any], none: str) -> None:
    """One line per comparison (where, then its verdict), or ``none`` for an empty list."""
    for c in comparisons:
        where = f"{c.scenario}" + (f" [{c.sweep}]" if c.sweep != "-" else "")
        con.print(f"- {where}: {c.verdict}", markup=False, highlight=False)
    if not comparisons:
        con.print(none)


def run_names(dir_a: str, dir_b: str) -> tuple[str, str]:
    """The names of two runs in the comparison table: ``A (before)``, ``B (after)``
    (their directories' names, or the paths as given when the names are the same)."""
    na, nb = Path(dir_a).name, Path(dir_b).name
    if na == nb:
        na, nb = dir_a, dir_b
    return f"A ({na})", f"B ({nb})"


def cmd_compare(args: argparse.Namespace) -> int:
    """Paired tests between the controllers of a run, or between two runs."""
    from benchmarks.study.compare import (
        compare_controllers,
        compare_runs,
        goal_mismatches,
        goal_settings,
        match_counts,
    )
    from benchmarks.study.run_facts import fixed_task_scenarios, run_meta, study_differences
    from benchmarks.study.table import load
    from hexapod.outputs import check_replace, write_output

    t0 = time.perf_counter()
    if args.json:
        check_replace(args.json, args.overwrite, kind="JSON")  # before the work
    metrics = tuple(args.metric) if args.metric else None  # None: the task's
    margins = parse_margins(args.margin)
    status = 0
    if len(args.dirs) == 1:
        df = load(args.dirs[0])
        comparisons = compare_controllers(df, args.baseline, metrics, margins)
        print_comparisons(comparisons, f"Paired comparisons ({args.dirs[0]}, "
                                       f"{len(df)} trials, goal setting "
                                       f"{goal_settings(df)})")
        for name in fixed_task_scenarios(run_meta(args.dirs[0])):
            print(f"note: {name} repeats ONE task (a fixed start and goal) with other noise "
                  "and calibration-error draws: its paired tests compare the controllers on "
                  "that task, not over tasks (docs/reproduction.md)")
        extra: list[dict[str, Any]] = []
    elif len(args.dirs) == 2:
        if args.baseline:
            from benchmarks.exceptions import BenchmarkError

            raise BenchmarkError("--baseline compares the controllers of one run; with two "
                                 "runs every controller is compared with itself")
        dir_a, dir_b = args.dirs
        df_a, df_b = load(dir_a), load(dir_b)
        comparisons, different, matched = compare_runs(df_a, df_b, "A", "B", metrics,
                                                       margins)
        _, only_a, only_b = match_counts(df_a, df_b)
        name_a, name_b = run_names(dir_a, dir_b)
        print_comparisons(comparisons, f"Run B ({dir_b}) against run A ({dir_a}), "
                                       f"{matched} matched trials, goal setting A "
                                       f"{goal_settings(df_a)}, B {goal_settings(df_b)}",
                          (name_b, name_a))
        mismatched = goal_mismatches(df_a, df_b)
        if mismatched:
            print(f"warning: the goal setting ([task] goal) differs between the runs in "
                  f"{len(mismatched)} scenario point(s): their differences include what the "
                  "controllers were told of the goal (docs/scenarios.md, Fairness), not only "
                  "how they control", file=sys.stderr)
            for line in mismatched:
                print(f"  {line}", file=sys.stderr)
        print(f"Trials matched by scenario, sweep point, controller and trial: {matched} "
              f"compared; unmatched, left out: {only_a} of the {len(df_a)} of run A "
              f"({dir_a}), {only_b} of the {len(df_b)} of run B ({dir_b})")
        regressions = [c for c in comparisons if c.verdict.startswith("REGRESSION")]
        print(f"Regressions (B significantly worse than A): {len(regressions)}")
        for c in regressions:
            print(f"- {c.scenario} [{c.sweep}] {c.verdict}")
        n_rows = different[["scenario", "point", "controller", "trial"]].drop_duplicates()
        studies = study_differences(run_meta(dir_a), run_meta(dir_b))
        if studies:
            print(f"Determinism check: {len(n_rows)} of {matched} matched trials differ between "
                  "the runs, whose studies differ (their rows are not expected to be "
                  "identical): " + "; ".join(studies))
        else:
            print(f"Determinism check: {len(n_rows)} of {matched} matched trials differ "
                  "between the runs" + (" (listed below; with the same code, seeds and "
                                        "libraries they should be identical)" if len(n_rows)
                                        else " (identical outcomes)"))
        for _, r in different.head(args.list).iterrows():
            print(f"  {r['scenario']} point {r['point']} {r['controller']} trial "
                  f"{r['trial']}: {r['column']} A={r['a']} B={r['b']}")
        if len(different) > args.list:
            print(f"  ... {len(different) - args.list} more (--list N shows more; --json "
                  "FILE has them all)")
        extra = [{"a": f"B:{dir_b}", "b": f"A:{dir_a}", "metric": "rows",
                  "test": "determinism", "n": matched, "statistic": len(n_rows),
                  "p_value": None, "p_holm": None,
                  "difference": len(n_rows) / matched if matched else None,
                  "interval": None, "unmatched": {"A": only_a, "B": only_b},
                  "goal": {"A": goal_settings(df_a), "B": goal_settings(df_b),
                           "differs": mismatched},
                  "studies_differ": studies,
                  "rows": json.loads(different.to_json(orient="records"))}]
        if args.check and (regressions or (len(n_rows) and not studies)):
            status = 1
    else:
        from benchmarks.exceptions import BenchmarkError

        raise BenchmarkError(f"compare takes one run directory or two, got {len(args.dirs)}")
    if args.json:
        write_output(args.json, {"comparisons": [c.to_json() for c in comparisons] + extra},
                     args.overwrite)
        print(f"wrote {len(comparisons) + len(extra)} comparison(s) to {args.json}")
    print(f"({time.perf_counter() - t0:.2f} s)")
    return status


def add_analysis_commands(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Register ``export``, ``compare`` and ``reproduce`` on the CLI's sub-parsers."""
    s = add_command(sub, "export", cmd_export, "write a run's trials as a table (Parquet)")
    s.add_argument("dir", help="a run directory")
    s.add_argument("--parquet", required=True, metavar="FILE", action=OutputFile,
                   help="output Parquet file")
    s.add_argument("--overwrite", action="store_true",
                   help="replace the --parquet file even if hexapod-bench did not write it")

    s = add_command(sub, "compare", cmd_compare,
                    "paired tests between the controllers of a run, or between two runs of the "
                    "same scenarios",
                    description="DIR: every pair of controllers (or each against --baseline) on "
                                "the trials both ran: McNemar's exact test on convergence with "
                                "Newcombe's interval, Wilcoxon's signed-rank test on final error "
                                "(a trajectory task: on tracking RMS, max, settling time, time "
                                "at a force limit) with the median paired difference and its "
                                "order-statistic interval, the sign test on steps censored at "
                                "the run's length, Holm's correction; equivalence within a "
                                "margin by two one-sided tests (TOST); failed trials left out of "
                                "all but convergence and steps. DIR_A DIR_B: the same trials of "
                                "two runs matched (the unmatched counted); regressions and rows "
                                "that differ listed.")
    s.add_argument("dirs", nargs="+", metavar="DIR", help="one run directory, or two (A B)")
    s.add_argument("--baseline", metavar="NAME", help="compare each controller with this one")
    s.add_argument("--metric", action="append", metavar="NAME",
                   help="converged, final_error, orientation_error, steps, tracking_rms, "
                        "tracking_max, settling, saturation or a numeric column "
                        "(repeatable; default: the task's: converged, final_error, steps "
                        "for a point-to-point task; tracking_rms, tracking_max, settling "
                        "and, in the dynamic world, saturation for a trajectory task)")
    s.add_argument("--margin", action="append", metavar="NAME=VALUE",
                   help="equivalence margin of a metric in its unit (repeatable; defaults: "
                        "converged=5 points, final_error=0.01 mm, orientation_error=0.001 "
                        "deg, steps=10, tracking_rms=0.01 mm, tracking_max=0.02 mm, "
                        "settling=0.05 s, saturation=0.05 s)")
    s.add_argument("--json", metavar="FILE", action=OutputFile,
                   help="write the comparisons as JSON")
    s.add_argument("--overwrite", action="store_true",
                   help="replace the --json file even if hexapod-bench did not write it")
    s.add_argument("--list", type=int, default=20, metavar="N",
                   help="two runs: rows that differ to print (default 20)")
    s.add_argument("--check", action="store_true",
                   help="two runs: exit 1 on a regression or a row that differs")

    from benchmarks.study.reproduce_cli import add_reproduce_command

    add_reproduce_command(sub)
