"""``hexapod-bench``: list, check, run, tune, report, compare, export, reproduce, perf,
calibrate, identify, viz, servo, conformance, warm.

Examples::

    hexapod-bench list
    hexapod-bench check my-study.toml --picture view.png
    hexapod-bench run quick --out runs/quick
    hexapod-bench tune inertia-error --controllers leg-edge,computed-torque --out runs/tune
    hexapod-bench run inertia-error --options-file runs/tune/tuned.toml --out runs/tuned
    hexapod-bench run tahri2009-convergence --out runs/tahri --workers 2
    hexapod-bench run my-study.toml --out runs/mine --dask local --resume
    hexapod-bench report runs/quick
    hexapod-bench compare runs/tahri
    hexapod-bench export runs/tahri --parquet tahri.parquet
    hexapod-bench reproduce seed001 --quick
    hexapod-bench conformance emulator
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import logging
import os
import sys
from typing import Any

from benchmarks.exceptions import BenchmarkError
from benchmarks.study import viz_command
from benchmarks.study.calibrate_command import cmd_calibrate
from benchmarks.study.commands import cmd_report, cmd_run, console
from benchmarks.study.outdir import OutputDir, OutputFile, add_command
from benchmarks.termination import exit_status, how_stopped, sigterm_interrupts
from hexapod.exceptions import HexapodError

log = logging.getLogger("hexapod-bench")


def cmd_list(args: argparse.Namespace) -> int:
    """List built-in scenarios and registered controllers with their source package."""
    from rich.markup import escape
    from rich.table import Table

    import controllers  # noqa: F401 - registers the built-ins
    from benchmarks.study.scenario import builtin_scenarios, load_scenario
    from controllers.options import first_sentence
    from controllers.registry import registry

    con = console()
    if getattr(args, "options", None):
        return _list_options(args.options, con)
    t = Table(title="Scenarios")
    t.add_column("name")
    t.add_column("trials", justify="right")
    t.add_column("controllers")
    t.add_column("description")
    for name in builtin_scenarios():
        sc = load_scenario(name)
        points = len(sc.expand())
        t.add_row(name, f"{sc.trials} x {points} pt" if points > 1 else str(sc.trials),
                  ", ".join(c.label for c in sc.controllers),
                  escape(first_sentence(sc.description)))
    con.print(t)
    t = Table(title="Controllers")
    for col in ("name", "package", "version", "description"):
        t.add_column(col)
    for info in registry.info():
        t.add_row(info.name, info.package, info.version, escape(info.description))
    con.print(t)
    from hexapod.backends.registry import backends

    t = Table(title="Backends (--backend NAME[:ARGS])")
    for col in ("name", "package", "version", "description"):
        t.add_column(col)
    for binfo in backends.info():
        t.add_row(binfo.name, binfo.package, binfo.version, binfo.description)
    con.print(t)
    for err in registry.errors:
        con.print(f"[red]plugin failed to load:[/red] {err}")
    for berr in backends.errors:
        con.print(f"[red]backend plugin failed to load:[/red] {berr}")
    return 0


def _list_options(name: str, con: Any) -> int:
    """Print the options a controller declares (the table the scenario checks use)."""
    from rich.markup import escape
    from rich.table import Table

    from controllers.options import REQUIRED
    from controllers.registry import registry

    table = registry.options(name)
    info = registry.source(name)
    t = Table(title=escape(f"Options of {name} ({info.package} {info.version}): "
                           f"{info.description}"))
    for col in ("option", "type", "unit", "default", "meaning"):
        t.add_column(col, overflow="fold")
    for o in table.options:
        t.add_row(o.name, escape(o.type), o.unit or "-",
                  "(required)" if o.default is REQUIRED else escape(repr(o.default)),
                  escape(o.meaning) or "(not documented)")
    con.print(t)
    if table.open:
        con.print(f"{name} also takes further options it hands on"
                  + (f": {table.passes_on}" if table.passes_on else "")
                  + " (checked when the controller is built)", markup=False)
    con.print("Set them in a scenario: controllers = [{name = \"" + name + "\", option = "
              "value}], or [controller_options] for every controller that declares the option "
              "(docs/scenarios.md).", markup=False)
    return 0


PERF_MODULES = {
    "fk": "benchmarks.perf.fk",
    "controllers": "benchmarks.perf.controllers",
    "vision": "benchmarks.perf.vision",
    "detect": "benchmarks.perf.detect",
    "serial": "benchmarks.perf.serial",
    "calibration": "benchmarks.perf.calibration",
    "study": "benchmarks.perf.study",
    "dynamics": "benchmarks.perf.dynamics",
    "dynamic-world": "benchmarks.perf.dynamic_world",
    "features": "benchmarks.perf.features",
}


def cmd_perf(args: argparse.Namespace) -> int:
    """Performance and accuracy figures (medians of many runs, ratios to a baseline)."""
    import importlib

    module = importlib.import_module(PERF_MODULES[args.what])
    return int(module.main(list(args.rest)))


def cmd_warm(args: argparse.Namespace) -> int:
    """Compile the kernels of the built-in scenarios, one line per scenario."""
    import time

    from benchmarks.warm import WarmResult, cached_libraries, warm

    start, before = time.perf_counter(), cached_libraries()

    def report(res: WarmResult) -> None:
        print(f"warm {res.scenario}: {res.units} units stepped, {res.seconds:.1f} s", flush=True)

    print("compiling the C kernels of the built-in scenarios (first run only: ~2 min on "
          "2 cores; a warm cache only loads them)", flush=True)
    warm(args.scenarios or None, args.workers, report)
    compiled = len(cached_libraries() - before)
    print(f"warm: {compiled} kernels compiled, {len(before) + compiled} in the cache, "
          f"{time.perf_counter() - start:.1f} s", flush=True)
    return 0


def _version() -> str:
    """The installed distribution's version (``unknown`` when not installed)."""
    from importlib import metadata

    try:
        return metadata.version("hexapod-vs")
    except metadata.PackageNotFoundError:
        return "unknown"


def command_word(argv: list[str]) -> str | None:
    """The subcommand named on a command line (its first word not an option), if any."""
    return next((a for a in argv if not a.startswith("-")), None)


#: The subcommands of the last parser :func:`build_parser` made.
_COMMANDS: list[str] = []


def _unknown_command(word: str) -> str | None:
    """The refusal of a word that is no subcommand, with the close one (argparse printed
    its usage and 'invalid choice', no suggestion), or None."""
    from hexapod.config import suggest

    names = _COMMANDS
    if not names or word in names:
        return None
    hint = suggest(word, names)
    return (f"no command {word!r}; the commands: {', '.join(names)}"
            + (f" (did you mean '{hint}'?)" if hint else ""))


def build_parser(commands: set[str] | None = None) -> argparse.ArgumentParser:
    """The argument parser of ``hexapod-bench``.

    Args:
        commands: The subcommands whose arguments are needed (:func:`main`: the one on
            the command line); ``None``: every subcommand's. A subcommand whose
            definition imports heavy modules (``servo``) is otherwise only listed by
            name and help.
    """
    p = argparse.ArgumentParser(prog="hexapod-bench", description=__doc__.split("\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("-v", "--verbose", action="store_true", help="log at INFO level")
    p.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    sub = p.add_subparsers(dest="command", required=True)

    s = add_command(sub, "list", cmd_list,
                    "scenarios and controllers (with their source package); --options NAME: a "
                    "controller's options")
    s.add_argument("--options", metavar="NAME",
                   help="print the options of controller NAME (type, unit, default, "
                        "meaning): what a scenario may set for it")

    s = add_command(sub, "run", cmd_run, "run scenarios (built-in names or TOML paths)",
                    description="Run the trials of one or more scenarios and write their rows, "
                    "tables and report into --out.",
                    epilog="exit codes: 0 done; 1 every trial failed; 2 refused (a bad input, "
                    "nothing run); 3 a controller failed every trial of its own; 130 "
                    "interrupted (Ctrl-C: the command to resume is printed)")
    s.add_argument("scenarios", nargs="+", metavar="SCENARIO",
                   help="a built-in scenario's name (hexapod-bench list) or a scenario TOML "
                        "file (docs/scenarios.md)")
    s.add_argument("--out", required=True, action=OutputDir, help="results directory")
    s.add_argument("--trials", type=int,
                   help="trials per sweep point and controller (default: the scenario's)")
    s.add_argument("--seed", type=int, help="override the scenario seed (default: the "
                                           "scenario's)")
    s.add_argument("--max-steps", type=int,
                   help="override the step budget of each trial, in control periods "
                        "(default: the scenario's)")
    s.add_argument("--calibration", metavar="FILE",
                   help="controllers use the base points of this calibrated.toml (the "
                        "laws that see the legs; the encoder and pose laws ignore them: "
                        "docs/calibration.md); refused if made with another robot or "
                        "camera")
    s.add_argument("--allow-foreign-calibration", action="store_true",
                   help="use a calibration file made with another robot or camera anyway "
                        "(warned)")
    s.add_argument("--controllers", help="comma-separated names, labels or module:attr "
                                         "(default: the scenario's)")
    s.add_argument("--options-file", metavar="FILE",
                   help="per-controller options ([controllers.\"LABEL\"] tables, e.g. the "
                        "tuned.toml of 'hexapod-bench tune'): they replace the scenario's "
                        "options of the same names; recorded in run.json and the report "
                        "(docs/tuning.md)")
    s.add_argument("--workers", type=int, default=1, help="processes (default 1)")
    s.add_argument("--dask", metavar="ADDRESS", help="Dask scheduler address, or 'local'")
    s.add_argument("--resume", action="store_true", help="finish an interrupted run")
    s.add_argument("--overwrite", action="store_true",
                   help="write into a directory that holds files other than a run's (files "
                        "of the same names, e.g. report.md, are replaced; results are never "
                        "discarded: a directory with results needs --resume)")
    s.add_argument("--chunk", type=int, default=None,
                   help="trials per work unit (default: a quarter of a worker's share of "
                        "the trials, between 25 and 1000, at most a sweep point's trials; 25 "
                        "with a real-time backend)")
    s.add_argument("--record", type=int, default=2, metavar="K",
                   help="keep the time series of trials 0 to K-1 of each controller at each "
                        "sweep point in DIR/trials/ (default 2: trials 0 and 1; the others "
                        "keep only their row in results.jsonl); 'viz' replays them, the "
                        "report plots trial 0")
    s.add_argument("--backend", default="sim",
                   help="sim (default, vectorised), emulator (a firmware emulator on a pty), "
                        "serial:URL[?baud=N], gcs:tcp://HOST:PORT or gcs:serial:URL (a PI GCS "
                        "controller), gcs-emulator, a plugin's NAME[:ARGS] or "
                        "module:attr[:ARGS] (docs/backends.md)")
    s.add_argument("--world", choices=("kinematic", "dynamic"),
                   help="override the scenarios' [robot] world (docs/dynamic-world.md)")
    s.add_argument("--goal", choices=("mixed", "taught", "cartesian"),
                   help="override the scenarios' [task] goal: what the controllers are told "
                        "of the goal (docs/scenarios.md, Fairness)")
    s.add_argument("--engine", choices=("batched", "per-trial"), default="batched",
                   help="batched (default: every trial of a work unit as arrays) or per-trial "
                        "(one controller object per trial; same results, slower)")
    s.add_argument("--viz", action="store_true", help="live MeshCat view (in-process)")
    s.add_argument("--no-progress", action="store_true", help="no progress bar")
    s.add_argument("--no-check", action="store_true",
                   help="skip the pre-flight checks of 'hexapod-bench check' (a setup where "
                        "every trial would fail is refused otherwise)")

    s = add_command(sub, "calibrate", cmd_calibrate,
                    "calibrate the base points from leg observations")
    s.add_argument("scenario", metavar="SCENARIO")
    s.add_argument("--out", required=True, action=OutputDir, help="output directory")
    s.add_argument("--configurations", help="extremal (default) or random:N")
    s.add_argument("--repeat", type=int, help="repetitions (new noise each; default 1)")
    s.add_argument("--solver", choices=["lstsq", "irls"], help="default: the scenario's")
    s.add_argument("--correct-scale", action="store_true",
                   help="divide the estimates by the measured scale (uncertain leg radius)")
    s.add_argument("--seed", type=int, help="seed of the simulated world and its noise "
                   "(default: the scenario's seed)")
    s.add_argument("--warn-ratio", type=float, metavar="R",
                   help="warn when a leg's singular-value ratio is below R (default: the "
                        "scenario's [calibration] warn_singular_ratio, 0.005)")
    s.add_argument("--min-ratio", type=float, metavar="R",
                   help="refuse below R (default: [calibration] min_singular_ratio, 0.0015)")
    s.add_argument("--overwrite", action="store_true",
                   help="replace the calibration.json and calibrated.toml of --out, or write "
                        "into a directory that holds other files")
    s.add_argument("--observations", metavar="FILE",
                   help="calibrate from measured edge normals and leg lengths (.json/.npz) "
                        "instead of simulating the scenario's world")

    from benchmarks.identify import command as identify_command

    s = add_command(sub, "identify", identify_command.run,
                    "identify a robot's dynamic parameters (inertia, friction, rotor "
                    "inertia) from its own motion (docs/identification.md)")
    identify_command.add_arguments(s)

    servo_help = ("run one controller on a robot (serial link or emulator) with a camera, "
                  "until convergence or Ctrl-C; --teach records a goal")
    if commands is None or "servo" in commands:
        from benchmarks.robot import servo  # the servo loop, controllers, cameras: ~1 s

        s = add_command(sub, "servo", servo.run, servo_help)
        servo.add_arguments(s)
    else:  # named in the list of commands only: another command was asked for
        sub.add_parser("servo", help=servo_help, add_help=False)

    from benchmarks.robot import conformance_command

    s = add_command(sub, "conformance", conformance_command.run,
                    "check a robot backend against the simulator (exit 0: conforms, 1: a check "
                    "failed)",
                    description=conformance_command.__doc__.split("\n\n")[0]
                                if conformance_command.__doc__ else None)
    conformance_command.add_arguments(s)

    viz_command.add_arguments(add_command(sub, "viz", viz_command.cmd_viz,
                                          "replay a recorded trial or a servo session (MeshCat, "
                                          "or --html FILE)"))

    from benchmarks.study.check_command import cmd_check

    s = add_command(sub, "check", cmd_check,
                    "check a scenario, robot or camera file before a study (exit 1: the setup "
                    "cannot run)",
                    description="Load and validate FILE (a scenario or built-in scenario name, a "
                                "robot geometry file or a camera file) and print the home pose "
                                "and leg lengths, the reachable workspace, what the camera sees, "
                                "the conditioning at home and the problems with the key to "
                                "change (docs/robot-files.md). Exit code 0: the setup can run; "
                                "1: every trial would fail; 2: a file is invalid.")
    s.add_argument("file", metavar="FILE")
    s.add_argument("--picture", metavar="PNG", action=OutputFile,
                   help="write an image of the robot at home seen by the camera (edges "
                        "seen in green, hidden in red; .png or .jpg)")
    s.add_argument("--overwrite", action="store_true",
                   help="replace the --picture file even if hexapod-bench did not write it")

    s = add_command(sub, "report", cmd_report, "rebuild DIR/report.md from DIR/results.jsonl")
    s.add_argument("dir", action=OutputDir, help="a run directory (report.md and its "
                                                 "figures are written into it)")
    s.add_argument("--overwrite", action="store_true",
                   help="replace DIR/report.md even if hexapod-bench did not write it")

    s = add_command(sub, "perf", cmd_perf,
                    "performance and accuracy figures",
                    description="Extra arguments go to the figure's module (see --help of e.g. "
                                "python -m benchmarks.perf.fk).")
    s.add_argument("what", choices=sorted(PERF_MODULES))
    s.add_argument("rest", nargs=argparse.REMAINDER, help="arguments for the figure")

    s = add_command(sub, "warm", cmd_warm,
                    "compile every C kernel the built-in scenarios use (once; a warm cache only "
                    "loads them)")
    s.add_argument("scenarios", nargs="*", metavar="SCENARIO",
                   help="built-in scenario names (default: all)")
    s.add_argument("--workers", type=int, default=2, help="processes (default 2)")

    from benchmarks.study.tune_command import register as register_tune

    register_tune(sub)
    from benchmarks.study.analysis_cli import add_analysis_commands

    add_analysis_commands(sub)  # export, compare, reproduce
    _COMMANDS[:] = sorted(sub.choices or ())
    return p


#: What finishes an interrupted command that can be finished (said when it is stopped).
RESUME_HINTS = {"tune": "; finish the tuning with the same command and --resume",
                "reproduce": "; the same command again finishes it (the trials and "
                             "calibrations done are kept)"}


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``hexapod-bench``."""
    words = list(sys.argv[1:] if argv is None else argv)
    word = command_word(words)
    parser = build_parser({word} if word else set())
    if word is not None and (problem := _unknown_command(word)) is not None:
        print(f"hexapod-bench: error: {problem}", file=sys.stderr)
        return 2
    args = parser.parse_args(words)
    args.argv = words  # run.json's commands
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    os.environ.setdefault("PYTHONWARNINGS", "ignore")
    try:
        with sigterm_interrupts():  # SIGTERM as Ctrl-C (benchmarks.termination)
            return int(args.func(args))
    except KeyboardInterrupt as stop:  # Ctrl-C or SIGTERM in a command without its own
        # handling: no traceback
        if args.verbose:
            raise
        print(f"\nhexapod-bench {word or ''}: {how_stopped(stop)}: each file written is "
              "whole (replaced at once), but of several outputs some may be new and some "
              f"still the earlier ones{RESUME_HINTS.get(word or '', '')}", file=sys.stderr)
        return exit_status(stop)
    except (BenchmarkError, HexapodError) as exc:
        print(f"hexapod-bench: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError as exc:
        if not _stdout_reader_left():  # another pipe (a plugin's socket): an error
            print(f"hexapod-bench: error: {type(exc).__name__}: {exc}", file=sys.stderr)
            return 2
        # the reader of our output went away (`... | head`): stop quietly, as a Unix tool
        # does (Python's own flush at exit would print the error again)
        with contextlib.suppress(OSError):
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141  # 128 + SIGPIPE, what a shell reports for a writer whose reader left
    except OSError as exc:  # a file or folder the system refuses (permissions, a file where
        # a folder is asked, a full disk): the path and the reason, no traceback
        if args.verbose:
            raise
        where = exc.filename if exc.filename is not None else ""
        other = f" -> {exc.filename2}" if exc.filename2 is not None else ""
        reason = exc.strerror or type(exc).__name__
        print(f"hexapod-bench: error: {where}{other}: {reason}" if where else
              f"hexapod-bench: error: {type(exc).__name__}: {exc}", file=sys.stderr)
        return 2
    except Exception as exc:
        from controllers.exceptions import ControllerError
        from vision.exceptions import VisionError

        if isinstance(exc, ControllerError | VisionError):
            print(f"hexapod-bench: error: {exc}", file=sys.stderr)
            return 2
        raise
    finally:
        if argv is None:  # the command's process ends with this call
            # its objects are left to the exit (a run holds ~100,000: matplotlib's,
            # scipy's, casadi's), not collected one by one first (0.3-0.6 s)
            gc.freeze()


def _stdout_reader_left() -> bool:
    """Whether standard output is a pipe whose reader has closed it (poll reports an
    error on its write end)."""
    import select

    try:
        poller = select.poll()
        poller.register(sys.stdout.fileno(), select.POLLOUT)
        return any(events & (select.POLLERR | select.POLLHUP)
                   for _, events in poller.poll(0))
    except (OSError, ValueError, AttributeError):  # no real stdout (a test's capture)
        return False


if __name__ == "__main__":
    raise SystemExit(main())
