"""What ``run``, ``report`` and ``calibrate`` accept as their output directory.

A command writes into a directory that is absent, empty or its own; a directory holding
files of another kind is refused (saying what it holds and how to proceed) unless the
user adds ``--overwrite``, and a file the project did not write is never replaced
silently. The rules are :mod:`hexapod.outputs`'; this module says which entries are
whose. See ``docs/outputs.md``.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path
from typing import Any

from benchmarks.study.results import LOCK_FILE, RESULTS_FILE, TRIALS_DIR
from hexapod.exceptions import OutputError
from hexapod.outputs import (
    GENERATOR,
    check_output_dir,
    check_replace,
    listing,
    written_by_project,
)

META_FILE = "run.json"
REPORT_FILE = "report.md"
#: The copies of the scenario and of the files it names (see :mod:`benchmarks.study.inputs`).
INPUTS_DIR = "inputs"
CALIBRATION_JSON = "calibration.json"
CALIBRATED_TOML = "calibrated.toml"
#: Entries of a run directory recognised by name.
_RUN_NAMES = frozenset({RESULTS_FILE, META_FILE, LOCK_FILE, TRIALS_DIR, INPUTS_DIR})
#: The first line of the reports written before the marker existed.
_LEGACY_REPORT = b"# Benchmark report\n"


def report_is_ours(path: Path) -> bool:
    """Whether ``report.md`` is a report ``hexapod-bench`` wrote (marked, or an older one)."""
    if written_by_project(path):
        return True
    try:
        with path.open("rb") as f:
            return f.read(len(_LEGACY_REPORT)) == _LEGACY_REPORT
    except OSError:
        return False


def _run_entry(entry: Path) -> bool:
    if entry.name in _RUN_NAMES:
        return True
    if entry.name == REPORT_FILE:
        return report_is_ours(entry)
    return entry.suffix == ".png" and entry.is_file() and written_by_project(entry)


def _fresh_entry(entry: Path) -> bool:
    """An entry a new run may write beside in a directory that is not a run directory yet:
    the project's report and figures, a lock, and the run's own folders while they hold no
    file (a user's files in a folder named ``trials`` or ``inputs`` are not the run's: the
    run would replace them)."""
    if entry.name in (TRIALS_DIR, INPUTS_DIR):
        return entry.is_dir() and not any(p.is_file() or p.is_symlink()
                                          for p in entry.rglob("*"))
    return _run_entry(entry)


def is_run_directory(out: Path) -> bool:
    """A directory ``run`` wrote: it holds ``results.jsonl`` or ``run.json``."""
    return (out / RESULTS_FILE).is_file() or (out / META_FILE).is_file()


def check_run_directory(out: Path, overwrite: bool = False) -> None:
    """Refuse a ``run --out`` that is not absent, empty or a run directory.

    A run directory keeps its rule (refused when it holds results, unless ``--resume``:
    checked under the lock); its ``report.md`` must be one the project wrote.

    Raises:
        OutputError: A file, a directory of another kind, or a report.md not ours.
    """
    out = Path(out)
    if is_run_directory(out):
        check_report_file(out, overwrite)
        return
    check_output_dir(out, _fresh_entry, "run directory (no results.jsonl or run.json)",
                     overwrite)


def check_report_file(out: Path, overwrite: bool = False) -> None:
    """Refuse to replace a ``report.md`` the project did not write, or a figure: a PNG
    of the directory's top level the project did not write (a user's edited figure),
    unless ``--overwrite``.

    Raises:
        OutputError: Naming the file(s) and how to proceed.
    """
    check_replace(Path(out) / REPORT_FILE, overwrite, ours=report_is_ours)
    if overwrite or not Path(out).is_dir():
        return
    theirs = sorted(p for p in Path(out).glob("*.png") if not written_by_project(p))
    if theirs:
        raise OutputError(str(out), f"holds {listing(theirs)}, PNG file(s) {GENERATOR} did "
                          "not write where the report writes its figures (an edited "
                          "figure?): move them, or add --overwrite to write the report anyway "
                          "(figures of the same names are replaced)")


def check_calibration_directory(out: Path, overwrite: bool = False) -> None:
    """Refuse a ``calibrate --out`` that holds other files, or a calibration already.

    Raises:
        OutputError: What the directory holds (the source of an existing
            ``calibrated.toml``) and how to proceed.
    """
    out = Path(out)
    check_output_dir(out, lambda e: e.name in (CALIBRATION_JSON, CALIBRATED_TOML, INPUTS_DIR),
                     "calibration directory", overwrite)
    if overwrite:
        return
    existing = [out / n for n in (CALIBRATED_TOML, CALIBRATION_JSON) if (out / n).exists()]
    if existing:
        names = ", ".join(e.name for e in existing)
        raise OutputError(str(out), f"already holds a calibration ({names}"
                          f"{_calibration_source(out / CALIBRATED_TOML)}); choose another "
                          "--out, or add --overwrite to replace it")


def _calibration_source(path: Path) -> str:
    """``; made from X`` for an existing calibrated.toml (empty when unreadable)."""
    try:
        import tomllib

        table = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return ""
    src = table.get("source")
    return f"; calibrated.toml made from {src}" if isinstance(src, str) and src else ""


def add_command(sub: Any, name: str, func: Any, help: str, **kwargs: Any
                ) -> argparse.ArgumentParser:
    """A subcommand of ``hexapod-bench`` that runs ``func(args)``.

    Args:
        sub: The CLI's sub-parsers (``add_subparsers``).
        name: The subcommand.
        func: Its function of the parsed arguments (returns the exit code).
        help: One line for ``hexapod-bench --help``.
        **kwargs: More ``add_parser`` arguments (``description``, ``epilog``: the
            command's :data:`benchmarks.cli_examples.EXAMPLES` are added after it).
    """
    from benchmarks.cli_examples import ExamplesFormatter, epilog

    kwargs["epilog"] = epilog(name, kwargs.get("epilog"))
    parser: argparse.ArgumentParser = sub.add_parser(
        name, help=help, formatter_class=ExamplesFormatter, **kwargs)
    parser.set_defaults(func=func)
    return parser


class _OutputAction(argparse.Action):
    """Stores the option's value, as argparse's default action does; the subclasses tag
    the option as an output (see :class:`OutputFile`)."""

    kind = ""

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: Any, option_string: str | None = None) -> None:
        problem = unwritable(Path(values), self.kind)
        if problem is not None:  # refused before any work (exit 2), not after the work,
            # in one line (an ArgumentError printed the whole usage before the reason)
            parser.exit(2, f"{parser.prog}: error: argument {option_string or self.dest}: "
                           f"{values}: {problem}\n")
        setattr(namespace, self.dest, values)


def unwritable(path: Path, kind: str) -> str | None:
    """Why the output ``path`` (a ``"file"`` or a ``"directory"``) cannot be written, or
    None: a directory where a file goes (or the reverse), a file where a folder on its way
    should be, or a folder that cannot be written in (read-only file system, permissions:
    tried with an unnamed temporary file, which leaves nothing behind). Checked when the
    command line is read, so that a long computation is not lost at its end."""
    if path.is_dir() and kind == "file":
        return "is a directory, not a file"
    if path.exists() and not path.is_dir() and kind == "directory":
        return "is a file, not a directory"
    folder = path if kind == "directory" else path.parent
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    if not folder.is_dir():
        return f"{folder} is a file: no folder can be made under it"
    try:
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as e:
        return f"no file can be created in {folder} ({e.strerror or e})"
    return None


class OutputFile(_OutputAction):
    """``add_argument(..., action=OutputFile)``: an option naming a file the command writes
    (with :func:`hexapod.outputs.write_output`: a user's file refused unless
    ``--overwrite``, the project's mark in it). The tag lets a test find every output
    option of every subcommand."""

    kind = "file"


class OutputDir(_OutputAction):
    """``add_argument(..., action=OutputDir)``: a directory the command writes into (absent,
    empty or its own; see :func:`hexapod.outputs.check_output_dir`)."""

    kind = "directory"


def study_entry(entry: Path) -> bool:
    """Whether an entry of ``reproduce --out`` is its own: a directory holding only what a
    run or a calibration writes (also one interrupted before its first row)."""
    return entry.is_dir() and all(
        _run_entry(e) or e.name in (CALIBRATION_JSON, CALIBRATED_TOML) for e in entry.iterdir())


def check_reproduce_directory(out: Path, overwrite: bool = False) -> None:
    """Refuse a ``reproduce --out`` that holds entries other than its studies' directories.

    Raises:
        OutputError: What it holds and how to proceed.
    """
    check_output_dir(out, study_entry, "reproduce directory (run and calibration "
                     "directories only)", overwrite)
