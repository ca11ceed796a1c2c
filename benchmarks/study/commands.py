"""The study commands of ``hexapod-bench``: ``run`` (locked results directory, progress,
honest summary, live viewer), ``report`` and ``calibrate`` (``viz``:
:mod:`benchmarks.study.viz_command`)."""

from __future__ import annotations

import argparse
import contextlib
import errno
import json
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

from benchmarks.exceptions import BenchmarkError, ClusterError
from benchmarks.termination import exit_status, how_stopped
from hexapod.outputs import replace_whole


def console() -> Any:
    """A rich console: the terminal's width, or 200 columns for a pipe or a CI log."""
    from rich.console import Console

    # a pipe or a CI log gets the whole table, not an 80-column squeeze
    return Console() if sys.stdout.isatty() else Console(width=200)


def cmd_run(args: argparse.Namespace) -> int:
    """Run studies and write results.jsonl and report.md."""
    import controllers  # noqa: F401 - registers the built-ins
    from benchmarks.study.scenario import load_scenario

    out = Path(args.out)
    names = [str(s) for s in args.scenarios]
    if len(set(names)) < len(names):  # each trial would run twice, its rows duplicated
        twice = sorted({n for n in names if names.count(n) > 1})
        raise BenchmarkError(f"scenario {', '.join(twice)} given twice: a study runs once")
    ctrl_list = [c.strip() for c in args.controllers.split(",")] if args.controllers else None
    loaded = [load_scenario(s) for s in args.scenarios]
    args.override_warnings = [  # (it was replaced without a word; then run.json's too)
        f"--calibration {args.calibration} replaces scenario {sc.name}'s [calibration] "
        "method = \"linear\": its controllers get this file's base points, no trial is "
        "calibrated in its own world" for sc in loaded
        if args.calibration and sc.calibration.method == "linear"]
    scenarios = [sc.with_overrides(args.trials, args.seed, ctrl_list, args.max_steps,
                                   args.calibration) for sc in loaded]
    if getattr(args, "world", None):  # --world: every scenario in that world
        scenarios = [replace(sc, world=args.world) for sc in scenarios]
    if getattr(args, "goal", None):  # --goal: every scenario in that goal setting
        scenarios = [sc.with_goal(args.goal) for sc in scenarios]
    from benchmarks.study.options_file import goal_mismatches, with_options_file

    scenarios, args.options_record = with_options_file(scenarios,
                                                       getattr(args, "options_file", None))
    for text in goal_mismatches(scenarios, args.options_record):
        print(f"warning: {text}", file=sys.stderr)
    return run_studies(scenarios, out, args)


def _resume_command(args: argparse.Namespace, out: Path) -> str:
    """The command that finishes an interrupted run (or tune, whose candidates' run it
    is): its own words (the options that make its study: seed, trials, controllers...)
    with ``--resume`` (a command without them was refused: '--seed: 7 in the directory, 1
    given')."""
    import shlex

    argv = list(getattr(args, "argv", None) or [])
    if not argv or argv[0] not in ("run", "tune"):  # (tune: its candidates' run)
        return f"hexapod-bench run {' '.join(args.scenarios)} --out {out} --resume"
    return "hexapod-bench " + shlex.join(argv + ([] if "--resume" in argv else ["--resume"]))


def run_studies(scenarios: list[Any], out: Path, args: argparse.Namespace) -> int:
    """Check and run loaded scenarios into ``out`` (``run``'s work after the command-line
    overrides; ``tune`` runs its candidates through it)."""
    for option, least in (("workers", 1), ("chunk", 1), ("record", 0)):
        value = getattr(args, option, None)
        if value is not None and value < least:
            raise BenchmarkError(f"--{option} {value}: at least {least}")
    from benchmarks.study.preflight import preflight, refusal, warning_lines
    from benchmarks.study.runner import run_lock

    if getattr(args, "allow_foreign_calibration", False):  # the run records what it allowed
        scenarios = [replace(sc, calibration=replace(sc.calibration, allow_foreign=True))
                     if sc.calibration.method == "file" else sc for sc in scenarios]
    # the pre-flight of 'hexapod-bench check', the same function
    pre = preflight(scenarios, getattr(args, "allow_foreign_calibration", False),
                    measure=not getattr(args, "no_check", False))
    warnings = [*getattr(args, "override_warnings", []), *pre.warnings]
    for text in warnings:
        print(f"warning: {text}", file=sys.stderr)
    args.calibration_warnings = warnings
    scenarios = pre.scenarios
    for check in pre.checks:
        refused = refusal(check)
        if refused is not None:
            raise refused
        for line in warning_lines(check):
            print(line, file=sys.stderr)
    from benchmarks.study.runner import backend_factory

    backend_factory(args.backend)  # validates the spec before any work
    from benchmarks.study.outdir import check_run_directory

    check_run_directory(out, getattr(args, "overwrite", False))  # before the lock file
    from benchmarks.study.failures import summarised_warnings

    # one run per results directory, from the check to the report
    with run_lock(out), summarised_warnings(not getattr(args, "verbose", False)) as repeated:
        code, results = _run_locked(scenarios, out, args)
    return _failure_epilogue(out, repeated.repeats(), code, results)


def _failure_epilogue(out: Path, repeats: list[str], code: int, results: Any = None) -> int:
    """Print the failures once per cause (with their counts) and the repeated warnings;
    the exit code is 1 when every trial of the results directory failed, 3 when a
    controller failed every one of its trials (the others ran). ``results``: the
    directory's rows when the run read them for its report (``report.read_rows``)."""
    from benchmarks.study.failures import (
        CONTROLLER_FAILED,
        EVERY_TRIAL_FAILED,
        controllers_failing_every_trial,
        every_trial_failed,
        failure_summary,
    )
    from benchmarks.study.report import read_rows

    rows = (results if results is not None else read_rows(out)).rows
    con = console()
    for line in repeats:
        con.print(f"warning: {line}", markup=False, highlight=False, soft_wrap=True)
    lines = failure_summary(rows)
    for line in lines:
        con.print(line, markup=False, highlight=False, soft_wrap=True)
    if lines:
        con.print(f"(every failure in full: {out / 'report.md'}, section Failures; the "
                  "tracebacks of unexpected errors: hexapod-bench -v run ...)", markup=False,
                  highlight=False, soft_wrap=True)
    if code == 0 and every_trial_failed(rows):
        print("hexapod-bench: error: every trial failed: the setup cannot run as it is (the "
              "causes are above)", file=sys.stderr)
        return EVERY_TRIAL_FAILED
    dead = controllers_failing_every_trial(rows)
    if code == 0 and dead:
        print("hexapod-bench: error: " + "; ".join(
            f"{label} failed all its {n} trials" for label, n in dead.items())
            + f" (the causes are above; exit code {CONTROLLER_FAILED}: the other controllers "
              "ran)", file=sys.stderr)
        return CONTROLLER_FAILED
    return code


def auto_chunk(scenarios: list[Any], workers: int, backend: str) -> int:
    """Trials per work unit: large enough for the batched engine to step many trials as
    arrays, small enough to keep every worker busy and the results streaming (results do
    not depend on it)."""
    if backend != "sim":
        return 25
    trials = max((sc.trials for sc in scenarios), default=1)
    groups = sum(len(sc.expand()) * len(sc.controllers) for sc in scenarios)
    share = -(-trials * groups // (4 * max(1, workers)))  # 4 units per worker at least
    return int(min(1000, trials, max(25, share)))


def _run_locked(scenarios: list[Any], out: Path, args: argparse.Namespace
                ) -> tuple[int, Any]:
    """Run the planned trials and write the report; the exit code and the rows read for
    the report (None after a live-viewer run)."""
    from concurrent.futures.process import BrokenProcessPool

    from rich.markup import escape

    from benchmarks.study.report import (
        META_FILE,
        import_drawing_modules,
        read_rows,
        write_report,
    )
    from benchmarks.study.runner import completed_keys, dask_workers, plan, run_units

    meta_path = out / META_FILE
    try:
        meta: dict[str, Any] = json.loads(meta_path.read_text()) if meta_path.exists() else {}
    except ValueError as exc:
        raise BenchmarkError(f"{meta_path}: not the run's record (not JSON: {exc}); its "
                             "study cannot be checked: run into another --out") from None
    from benchmarks.study.study_record import check_same_study, command_entry, record_command

    existing = (out / "results.jsonl").exists() and (out / "results.jsonl").stat().st_size > 0
    if existing and not meta and args.resume:  # (a run writes run.json before any trial)
        raise BenchmarkError(f"{out}: holds results.jsonl but no {META_FILE}: the study its "
                             "trials ran cannot be checked, and a resume could mix another "
                             f"study's trials into them; restore {META_FILE}, or run into "
                             "another --out")
    grows = check_same_study(out, meta, scenarios)  # before any trial: one study per directory
    if existing and not args.resume:
        raise BenchmarkError(f"{out}: already holds results; use --resume to finish that run "
                             "or choose another --out")
    done = completed_keys(out) if args.resume else set()
    # the workers that share the units: a Dask scheduler's threads (it was --workers,
    # default 1: every unit a whole controller's trials, rows written in its jumps)
    workers = dask_workers(args.dask, args.workers) if args.dask else args.workers
    chunk = args.chunk or auto_chunk(scenarios, workers, args.backend)
    if chunk < 1:
        raise BenchmarkError(f"--chunk must be >= 1, got {chunk}")
    units = plan(scenarios, chunk, args.record, done, args.backend, args.engine)
    total = sum(len(u.trials) for u in units)
    con = console()
    did = [f"grew {name} from {a} to {b} trials per sweep point and controller"
           for name, (a, b) in grows.items()]
    for text in did:
        con.print(f"growing the study: {text} (everything else as in the directory)")
    if done:
        con.print(f"resuming: {len(done)} trials already done, {total} to go")
    did.append(f"{len(done)} trials already done, {total} to run" if done else
               f"{total} trials to run")
    executor = "dask" if args.dask else ("process pool" if args.workers > 1 else "in-process")
    record_command(meta, command_entry(getattr(args, "argv", sys.argv[1:]), "; ".join(did)))
    meta.update({
        "workers": workers, "executor": executor,
        "warnings": getattr(args, "calibration_warnings", []),
        "scenarios": {**meta.get("scenarios", {}), **{
            sc.name: {"description": sc.description, "reference": sc.reference,
                      "source": sc.source} for sc in scenarios}},
    })
    _keep_inputs(out, scenarios, meta, args, continued=meta_path.exists())
    from benchmarks.study.options_file import record_options

    record_options(meta, getattr(args, "options_record", None))  # "tuned" or "as given"
    replace_whole(meta_path, json.dumps(meta, indent=2))
    if args.viz:
        return _run_with_viz(scenarios, out, args), None
    t0 = time.perf_counter()
    show = sys.stdout.isatty() and not args.no_progress
    interrupted = False
    written = 0
    from benchmarks.study.runner import read_results

    def rows_written() -> int:
        return len(read_results(out)) if (out / "results.jsonl").exists() else 0

    rows_before = rows_written()  # a resumed run's earlier rows
    status = 0

    def advance(unit: Any) -> None:
        nonlocal written
        written += len(unit.trials)

    try:
        if show and total:
            from rich.progress import (
                BarColumn,
                MofNCompleteColumn,
                Progress,
                TimeElapsedColumn,
                TimeRemainingColumn,
            )

            with Progress("[progress.description]{task.description}", BarColumn(),
                          MofNCompleteColumn(), TimeElapsedColumn(), TimeRemainingColumn(),
                          console=con) as prog:
                task = prog.add_task("trials", total=total)

                def advance_bar(unit: Any) -> None:
                    advance(unit)
                    prog.advance(task, len(unit.trials))

                run_units(units, out, args.workers, args.dask, progress=advance_bar,
                          meanwhile=import_drawing_modules)
        else:
            run_units(units, out, args.workers, args.dask, progress=advance,
                      meanwhile=import_drawing_modules)
    except KeyboardInterrupt as stop:  # Ctrl-C, or SIGTERM (benchmarks.termination)
        interrupted, status = True, exit_status(stop)
        # Ctrl-C may land between a chunk's write and its progress call: count the file
        written = rows_written() - rows_before
        word = how_stopped(stop).split()[0]
        con.print(f"\n[yellow]{word}[/yellow]: {written} of {total} trials written to "
                  f"{out}/results.jsonl; finish with: {escape(_resume_command(args, out))}",
                  soft_wrap=True)  # (one line to paste)
    except OSError as exc:  # a file not written (a full disk: the error names it); exit 2
        if exc.errno not in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS):
            raise  # (a connection refused, a file not found: its own message)
        written = rows_written() - rows_before
        con.print(f"\n[red]a file could not be written[/red]: {written} of {total} trials "
                  f"are in {out}/results.jsonl; once it can be (room on the disk), finish "
                  f"with: {escape(_resume_command(args, out))}",
                  soft_wrap=True)  # (one line to paste)
        raise
    except ClusterError as exc:  # the Dask cluster failed: its rows stay, resume finishes
        interrupted, status = True, 1
        written = rows_written() - rows_before
        con.print(f"\n[red]{escape(str(exc))}[/red]: {written} of {total} trials written to "
                  f"{out}/results.jsonl (its units in flight are not); finish with: "
                  f"{escape(_resume_command(args, out))}", soft_wrap=True)
    except BrokenProcessPool:  # a worker killed from outside (the OOM killer, kill -9)
        interrupted, status = True, 1
        written = rows_written() - rows_before
        con.print(f"\n[red]a worker process ended abruptly[/red] (killed from outside: out "
                  f"of memory?): {written} of {total} trials written to {out}/results.jsonl "
                  f"(its unit's trials are not); finish with: "
                  f"{escape(_resume_command(args, out))}", soft_wrap=True)  # (one line to paste)
    wall = time.perf_counter() - t0
    meta["wall_time_s"] = wall
    replace_whole(meta_path, json.dumps(meta, indent=2))
    results = read_rows(out)  # once: the report, the table and the failure summary
    report = write_report(out, getattr(args, "overwrite", False), results)
    _print_summary(out, con, results)
    done_text = f"{written} of {total} trials" if written != total else f"{total} trials"
    con.print(f"{done_text} in {wall:.1f} s ({executor}, {workers} worker(s))"
              f"{' before the interruption' if interrupted else ''}; report: {report}")
    return status, results


def _keep_inputs(out: Path, scenarios: list[Any], meta: dict[str, Any],
                 args: argparse.Namespace, continued: bool) -> None:
    """Copy each scenario and its files into ``out/inputs/`` and record its settings and
    the ``--record`` count in ``meta`` (see :mod:`benchmarks.study.inputs`; ``continued``:
    the directory's run goes on, its kept copies stay)."""
    from benchmarks.study.inputs import copy_inputs, settings
    from benchmarks.study.study_record import study_of

    if continued and meta.get("record") not in (None, args.record):
        print(f"warning: --record {args.record}: the directory's run recorded "
              f"{meta['record']} trial(s) per controller and sweep point (trials/ keeps "
              f"them); the trials run now are recorded by {args.record}, and run.json "
              "says so", file=sys.stderr)
    meta["record"] = args.record
    for sc in scenarios:
        kept = copy_inputs(out, sc, getattr(args, "allow_foreign_calibration", False),
                           keep=continued)
        if kept.get("changed"):
            print(f"warning: {sc.source} differs from the copy this run started with "
                  f"({out / kept['folder'] / 'source.toml'}, kept); the study it describes was "
                  "checked against the directory's, setting by setting", file=sys.stderr)
        meta["scenarios"][sc.name].update(inputs=kept, settings=settings(sc),
                                          study=study_of(sc))


def _run_with_viz(scenarios: list[Any], out: Path, args: argparse.Namespace) -> int:
    """Run in-process with a live MeshCat view (loopback server)."""
    from benchmarks.sim import load_camera, load_geometry
    from benchmarks.study.runner import ResultsWriter, execute, plan
    from hexapod.visualize import HexapodViewer

    con = console()
    sc0 = scenarios[0].expand()[0]
    g = load_geometry(sc0)
    cam = load_camera(sc0, g)
    viewer = HexapodViewer(g)
    viewer.show_camera(cam.camera_from_base.as_matrix(), cam.K, cam.width, cam.height,
                       kind=cam.kind)
    con.print(f"MeshCat viewer: {viewer.url()}")

    def on_step(trial: int, R: Any, t: Any, vis: Any) -> None:
        viewer.display(R, t, vis)

    writer = ResultsWriter(out)
    try:
        for unit in plan(scenarios, 1, args.record, set(), args.backend):
            rows, records = execute(unit, on_step=on_step)
            writer.write(rows, records)
    finally:
        writer.close()
        viewer.close()
    from benchmarks.study.report import write_report

    write_report(out, getattr(args, "overwrite", False))
    _print_summary(out, con)
    return 0


def _print_summary(out: Path, con: Any, results: Any = None) -> None:
    """The results table of a run directory, per scenario after its task: tracking
    figures for a trajectory task, convergence and final errors for a point-to-point one
    (the failed trials counted apart and left out of the error columns); fitted to the
    terminal's width (:mod:`benchmarks.study.fit_table`). ``results``: the directory's
    rows when the caller read them (``report.read_rows``)."""
    from benchmarks.study.fit_table import print_table
    from benchmarks.study.metrics import summarize
    from benchmarks.study.report import TABLE_HEADER, duplicate_note, read_rows, summary_table_rows
    from benchmarks.study.tracking_report import is_tracking, tracking_header, tracking_rows

    results = results if results is not None else read_rows(out)
    rows, dropped, conflicting = results.rows, results.dropped, results.conflicting
    if dropped:
        con.print(f"[yellow]warning[/yellow]: {out / 'results.jsonl'}: "
                  f"{duplicate_note(dropped, conflicting)}")
    by_scenario: dict[str, list[dict[str, Any]]] = {}
    for r in rows:
        by_scenario.setdefault(r["scenario"], []).append(r)
    point_to_point = []
    for name, rs in by_scenario.items():
        if not is_tracking(rs):
            point_to_point += rs
            continue
        print_table(con, f"Trajectory tracking ({out}) - scenario: {name}",
                    tracking_header(rs), tracking_rows(rs, with_intervals=False),
                    keys=(0, 1), left=(0, 1), wrap=(0,))
    if point_to_point or not rows:
        every = len(point_to_point) == len(rows)  # every row: the report's summaries
        summaries = results.summaries() if every else summarize(point_to_point)
        print_table(con, f"Results ({out})", TABLE_HEADER,
                    summary_table_rows(summaries), keys=(0, 1, 2, 3),
                    left=(0, 1, 2, 3), wrap=(1,))


def cmd_report(args: argparse.Namespace) -> int:
    """Rebuild report.md from results.jsonl: under the directory's lock, recording the
    command in run.json; while a run writes into the directory (it holds the lock), the
    report of the rows written so far, run.json left to the run (its whole record
    replaced at each write would drop an entry added beside it)."""
    from benchmarks.exceptions import DirectoryLockedError
    from benchmarks.study.runner import run_lock

    busy = None
    with contextlib.ExitStack() as held:
        if (Path(args.dir) / "results.jsonl").is_file():  # (a mistyped path: not made)
            try:
                held.enter_context(run_lock(Path(args.dir)))
            except DirectoryLockedError as exc:
                busy = exc
        return _report(args, busy)


def _report(args: argparse.Namespace, busy: Any) -> int:
    """:func:`cmd_report`'s work; ``busy``: the run writing into the directory, or None."""
    from benchmarks.study.outdir import META_FILE, check_report_file
    from benchmarks.study.report import write_report
    from benchmarks.study.study_record import command_entry, record_command

    out, overwrite = Path(args.dir), getattr(args, "overwrite", False)
    check_report_file(out, overwrite)
    from benchmarks.exceptions import ResultsError
    from benchmarks.study.report import read_rows

    rows = read_rows(out)
    if not rows.rows:  # (as export: a report of no trial says nothing)
        raise ResultsError(str(out / "results.jsonl"), "no trial rows: nothing to report")
    meta_path = out / META_FILE
    kept = meta_path.read_text() if meta_path.is_file() and busy is None else None
    if kept is not None:  # run.json keeps every command that wrote the directory
        try:
            meta = json.loads(kept)
        except ValueError as exc:
            raise ResultsError(str(meta_path), f"not the run's record (not JSON: {exc}); the "
                               "rows are in results.jsonl") from None
        record_command(meta, command_entry(getattr(args, "argv", sys.argv[1:]),
                                           "rebuilt report.md and its figures"))
        replace_whole(meta_path, json.dumps(meta, indent=2))
    try:
        path = write_report(out, overwrite, rows)
    except BaseException:
        if kept is not None:  # nothing written: the record stays as it was
            replace_whole(meta_path, kept)
        raise
    _print_summary(out, console())
    print(f"report: {path}")
    if busy is not None:
        who = f"PID {busy.pid}" if busy.pid is not None else "another process"
        what = busy.holder.split(" (since")[0] if busy.holder else "?"
        print(f"note: another hexapod-bench command ({who}: {what}) holds {out}: this "
              f"report holds the {len(rows.rows)} rows written so far, and {META_FILE} was "
              "left to that command (a run writes its own report when it ends)")
    return 0
