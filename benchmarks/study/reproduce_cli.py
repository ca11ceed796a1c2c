"""The ``hexapod-bench reproduce`` command: the scorecard of the declared paper figures,
or (``--sensitivity``) the same rows over a grid of the free parameters."""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

from benchmarks.exceptions import BenchmarkError
from benchmarks.study.outdir import OutputDir, OutputFile, add_command, unwritable

#: The sensitivity study's trials per study and point (``--trials``'s default): the
#: fewest for which every row has its interval (a median's 95 % needs 6; the worst of
#: the six base points, its 99.17 % after Bonferroni's correction, needs 8: at 6 that
#: row was never comparable)
SENSITIVITY_TRIALS = 8


def _scorecard(args: argparse.Namespace) -> int:
    from rich.markup import escape
    from rich.table import Table

    from benchmarks.study.commands import console
    from benchmarks.study.outdir import check_reproduce_directory
    from benchmarks.study.reproduce import (
        interval_text,
        markdown,
        reproduce,
        summary,
        target_text,
    )
    from hexapod.outputs import check_replace, write_output

    con = console()
    given = [f"--{k.replace('_', '-')}" for k in ("leg_radius_mm", "camera_distance_m", "gain",
                                                  "goal_noise") if getattr(args, k) is not None]
    if given or args.trials != SENSITIVITY_TRIALS:
        raise BenchmarkError(f"{', '.join(given) or '--trials'}: options of the sensitivity "
                             "study; add --sensitivity (the scorecard runs each study as its "
                             "scenario declares, --quick for fewer trials)")
    if args.markdown:
        check_replace(args.markdown, args.overwrite, kind="Markdown")  # before minutes of studies
    check_reproduce_directory(Path(args.out), args.overwrite)
    t0 = time.perf_counter()
    results = reproduce(args.which, Path(args.out), args.quick, args.workers,
                        say=lambda text: con.print(text, markup=False, highlight=False))
    t = Table(title=f"Papers and framework ({args.which}"
                    f"{', --quick' if args.quick else ''})")
    for col in ("id", "paper's figure (rule's range)", "framework", "95 % interval", "n",
                "verdict"):
        t.add_column(col, justify="right" if col == "n" else "left")
    for r in results:
        f = r.figure
        ident = f.id + (f" (variant of {f.variant_of})" if f.variant_of else "")
        t.add_row(*(escape(x) for x in (ident, target_text(f), r.framework,
                                         interval_text(r), str(r.n), r.verdict)))
    con.print(t)
    for r in results:
        if r.note:
            con.print(f"- {r.figure.id}: {r.note}", markup=False, highlight=False)
    for r in results:
        if r.why:
            con.print(f"- {r.figure.id} ({r.verdict}): {r.why}", markup=False,
                      highlight=False)
    con.print(summary(results) + f"; {time.perf_counter() - t0:.0f} s; studies in "
              f"{args.out}", markup=False, highlight=False)
    if args.markdown:
        write_output(args.markdown, markdown(results) + "\n", args.overwrite)
        con.print(f"wrote {args.markdown}")
    return 0


def _sensitivity(args: argparse.Namespace) -> int:
    from benchmarks.study.commands import console
    from benchmarks.study.sensitivity import (
        grid,
        parse_axis,
        report,
        run_sensitivity,
        sensitivity_entry,
        write,
    )
    from hexapod.outputs import check_output_dir

    con = console()
    if args.which != "all":
        raise BenchmarkError("reproduce --sensitivity evaluates every paper's rows together "
                             f"(which region matches all of them): drop {args.which!r}")
    if args.trials < 1:
        raise BenchmarkError(f"reproduce --sensitivity --trials: {args.trials} must be >= 1")
    if args.trials < SENSITIVITY_TRIALS:
        con.print(f"warning: --trials {args.trials}: fewer than {SENSITIVITY_TRIALS} trials give "
                  "some rows no interval (a median's 95 %, the worst point's 99.17 %): those "
                  "rows will be not comparable (the run shows the command works, not which "
                  "region matches)", markup=False, highlight=False)
    axes = {k: parse_axis(k, v) for k, v in (
        ("leg_radius_mm", args.leg_radius_mm), ("camera_distance_m", args.camera_distance_m),
        ("gain", args.gain), ("goal_noise", args.goal_noise)) if v is not None}
    points = grid(axes)
    out = Path(args.out)
    check_output_dir(out, sensitivity_entry, "sensitivity directory (its points' study "
                     "directories and sensitivity.json / .md only)", args.overwrite)
    t0 = time.perf_counter()
    res = run_sensitivity(points, out, args.trials, args.workers,
                          say=lambda text: con.print(text, markup=False, highlight=False))
    j, m = write(out, res, args.trials)
    con.print(report(res, args.trials), markup=False, highlight=False)
    con.print(f"{len(points)} points in {time.perf_counter() - t0:.0f} s; wrote {j} and {m}",
              markup=False, highlight=False)
    return 0


def cmd_reproduce(args: argparse.Namespace) -> int:
    """Run the studies behind the papers' figures; paper and framework side by side."""
    problem = unwritable(Path(args.out), "directory")  # the default is not checked by
    if problem is not None:  # argparse's action
        raise BenchmarkError(f"--out {args.out}: {problem}")
    return _sensitivity(args) if args.sensitivity else _scorecard(args)


def add_reproduce_command(sub: Any) -> None:
    """Register ``reproduce`` on the CLI's sub-parsers (``sub``: what
    ``ArgumentParser.add_subparsers`` returns)."""
    s = add_command(sub, "reproduce", cmd_reproduce,
                    "run the studies behind the papers' figures and set paper and framework side "
                    "by side")
    s.add_argument("which", nargs="?", default="all",
                   choices=("seed000", "seed001", "seed002", "seed003", "all"),
                   help="one paper's studies, or all (the default: every paper's, tens of "
                        "minutes; --quick: minutes)")
    s.add_argument("--quick", action="store_true",
                   help="fewer trials (30 per noise level for seed 001, 1000 pairs for seed "
                        "003, 30 calibrations): minutes instead of tens of minutes")
    s.add_argument("--out", default="runs/reproduce", action=OutputDir,
                   help="where the studies' results go (default runs/reproduce; a study "
                        "already there is finished or reused, not redone)")
    s.add_argument("--workers", type=int, default=1, help="processes (default 1)")
    s.add_argument("--markdown", metavar="FILE", action=OutputFile,
                   help="also write the table as Markdown")
    s.add_argument("--overwrite", action="store_true",
                   help="replace the --markdown file even if hexapod-bench did not write "
                        "it, or write into an --out that holds other files")
    g = s.add_argument_group("sensitivity study (docs/reproduction.md, \"Sensitivity\")")
    g.add_argument("--sensitivity", action="store_true",
                   help="evaluate the declared rows (image studies aside) over a grid of "
                        "the free parameters; one directory per point under --out")
    g.add_argument("--trials", type=int, default=SENSITIVITY_TRIALS,
                   help="trials per run study and calibrations per calibration study at "
                        f"each point (default {SENSITIVITY_TRIALS}: fewer give some rows no "
                        "interval)")
    g.add_argument("--leg-radius-mm", metavar="LIST",
                   help="leg radii [mm], comma-separated (default 10,15,20)")
    g.add_argument("--camera-distance-m", metavar="LIST",
                   help="front camera distances [m] (default 0.7,0.8,0.9)")
    g.add_argument("--gain", metavar="LIST",
                   help="'declared' (each study's adaptive gain) or constant gains [1/s] "
                        "(default declared,1)")
    g.add_argument("--goal-noise", metavar="LIST",
                   help="declared, on, off (default declared,on,off)")
