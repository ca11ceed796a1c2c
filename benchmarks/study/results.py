"""The results directory: ``results.jsonl`` (one JSON row per trial, synced per chunk), the
recorded trials, the lock that keeps one run per directory, and reading the rows back
(a partial last line dropped, duplicate trials de-duplicated)."""

from __future__ import annotations

import contextlib
import fcntl
import functools
import json
import logging
import math
import os
import re
import shlex
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.exceptions import DirectoryLockedError, ResultsError
from hexapod.outputs import inside

log = logging.getLogger(__name__)

RESULTS_FILE = "results.jsonl"
TRIALS_DIR = "trials"
LOCK_FILE = ".lock"

#: Results directories this process holds: resolved path -> (lock file, hold count).
_HELD: dict[Path, tuple[Any, int]] = {}


def release_inherited_locks() -> None:
    """In a worker forked while :func:`run_lock` is held: close its copies of the locks'
    files, so that the lock ends with the process that took it (a forked worker holding
    the copy kept the directory locked after its parent was killed)."""
    for f, _ in _HELD.values():
        with contextlib.suppress(OSError):
            f.close()  # this process's descriptor only: the parent's lock stays
    _HELD.clear()


@contextlib.contextmanager
def run_lock(out_dir: Path) -> Iterator[None]:
    """Hold the exclusive lock of a results directory for the duration of a run.

    The lock is an ``flock`` on ``DIR/.lock`` (released by the kernel when the
    process ends, however it ends), which also holds the holder's PID and
    command. It is re-entrant within one process (the CLI holds it for the
    whole run, :func:`run_units` takes it again).

    Raises:
        DirectoryLockedError: Another process holds it (naming its PID).
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    key = out_dir.resolve()
    if key in _HELD:
        f, n = _HELD[key]
        _HELD[key] = (f, n + 1)
        try:
            yield
        finally:
            f, n = _HELD[key]
            _HELD[key] = (f, n - 1)
        return
    f = (out_dir / LOCK_FILE).open("a+", encoding="utf-8")
    try:
        fcntl.flock(f.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        f.seek(0)
        text = f.read().strip()
        f.close()
        pid_text, _, holder = text.partition(" ")
        pid = int(pid_text) if pid_text.isdigit() else None
        raise DirectoryLockedError(str(out_dir), pid, holder) from None
    f.seek(0)
    f.truncate()
    command = " ".join(shlex.quote(a) for a in sys.argv) or "python"
    f.write(f"{os.getpid()} {command} (since {time.strftime('%Y-%m-%d %H:%M:%S')})\n")
    f.flush()
    _HELD[key] = (f, 1)
    try:
        yield
    finally:
        f, n = _HELD.pop(key)
        with contextlib.suppress(OSError):
            f.seek(0)
            f.truncate()
        f.close()  # closing the descriptor releases the flock


def trial_key(row: dict[str, Any]) -> tuple[str, int, str, int]:
    """Identity of a result row: (scenario, sweep point, controller label, trial)."""
    return (str(row["scenario"]), int(row.get("point", 0)), str(row["controller"]),
            int(row["trial"]))


class ResultsWriter:
    """Appends rows to ``results.jsonl`` (flushed and synced per chunk) and saves records."""

    def __init__(self, out_dir: Path) -> None:
        self.out_dir = out_dir
        out_dir.mkdir(parents=True, exist_ok=True)
        (out_dir / TRIALS_DIR).mkdir(exist_ok=True)
        self.path = out_dir / RESULTS_FILE
        _repair_tail(self.path)
        _drop_parts(out_dir / TRIALS_DIR)
        self._f = self.path.open("a", encoding="utf-8")

    def write(self, rows: list[dict[str, Any]], records: list[tuple[str, dict[str, Any]]]
              ) -> None:
        """Write one chunk's rows and records.

        Raises:
            OSError: A file could not be written (a full disk), naming it.
        """
        from hexapod.visualize import save_trial

        for name, rec in records:
            save_trial(inside(self.out_dir / TRIALS_DIR, name), **rec)
        try:
            for row in rows:
                self._f.write(json.dumps(_jsonable(row), sort_keys=True) + "\n")
            self._f.flush()
            os.fsync(self._f.fileno())
        except OSError as exc:
            if exc.filename is not None:
                raise
            raise OSError(exc.errno, exc.strerror or str(exc), str(self.path)) from exc

    def close(self) -> None:
        """Close the file."""
        self._f.close()


def _jsonable(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def _drop_parts(trials: Path) -> None:
    """Remove the records a killed run left half written (``*.tmp.npz``: only this run
    writes into its directory, under its lock)."""
    from hexapod.visualize.records import TMP_SUFFIX

    for part in trials.glob(f"*{TMP_SUFFIX}"):
        part.unlink(missing_ok=True)
        log.warning("%s: removed a trial record an interrupted run left half written", part)


def _repair_tail(path: Path) -> None:
    """End the file of a killed run on a whole line: a last line without its newline is
    kept (the newline added) when it is a whole row, as :func:`read_results` and a
    resume count it done; a partial one is dropped."""
    if not path.exists():
        return
    data = path.read_bytes()
    if data and not data.endswith(b"\n"):
        cut = data.rfind(b"\n") + 1
        try:
            whole = isinstance(json.loads(data[cut:]), dict)
        except ValueError:
            whole = False
        if whole:
            with path.open("ab") as f:
                f.write(b"\n")
            log.warning("%s: ended its last row, written whole without its newline by an "
                        "interrupted run", path)
        else:
            path.write_bytes(data[:cut])
            log.warning("%s: dropped a partial last line from an interrupted run", path)


def read_results(out_dir: Path) -> list[dict[str, Any]]:
    """Read every row of ``DIR/results.jsonl``.

    Raises:
        ResultsError: No results file, or a corrupted line (named by number).
    """
    path = Path(out_dir) / RESULTS_FILE
    if not path.exists():
        raise ResultsError(str(path), "no results file (run 'hexapod-bench run' first)")
    rows = []
    lines = path.read_text(encoding="utf-8").splitlines()
    for n, line in enumerate(lines, 1):
        if not line.strip():
            continue
        try:
            row = json.loads(line)
        except json.JSONDecodeError as exc:
            if n == len(lines):  # partial last line of an interrupted run
                log.warning("%s:%d: ignoring a partial last line", path, n)
                continue
            raise ResultsError(f"{path}:{n}", f"not valid JSON: {exc}") from None
        check_row(row, f"{path}:{n}")
        rows.append(row)
    return rows


#: The row keys that name a trial, with their JSON types.
_KEY_TYPES: dict[str, tuple[type, ...]] = {"scenario": (str,), "controller": (str,),
                                           "trial": (int,), "point": (int,)}
#: A row key that ends so is a measure: a number, none, or a list of them (per leg).
_MEASURE = re.compile(r"(_(mm|deg|s|us|ms|n|mm_s|hz|fraction|kg|percent|px)|^steps)$")


def check_row(row: Any, where: str) -> None:
    """Refuse a row that the report, ``compare`` and ``export`` cannot read: not a JSON
    object, a trial key missing or of another type, a measure (a key with a unit
    suffix, ``steps``) that is not a number (or null, or a list of numbers).

    Raises:
        ResultsError: Naming ``where`` (the file and line) and the key.
    """
    if not isinstance(row, dict):
        raise ResultsError(where, f"a row is a JSON object ({{...}}), not a "
                                  f"{type(row).__name__}")
    for key, types in _KEY_TYPES.items():
        value = row.get(key)
        if value is None and key == "point":
            continue
        if not isinstance(value, types) or isinstance(value, bool):
            raise ResultsError(where, f"key {key!r}: {'missing' if value is None else repr(value)}"
                                      f"; a trial's row has its {key} as "
                                      f"{'text' if types == (str,) else 'an integer'}")
    for key, value in row.items():
        if _is_measure(key) and not _numbers(value):
            raise ResultsError(where, f"key {key!r}: {value!r} is not a number")


@functools.lru_cache(maxsize=4096)
def _is_measure(key: str) -> bool:
    """Whether a row key is a measure (the same few dozen keys in every row)."""
    return _MEASURE.search(key) is not None


def _numbers(value: Any) -> bool:
    """A number, null, or a list of them (booleans are not measures)."""
    if isinstance(value, list):
        return all(_numbers(v) and not isinstance(v, list) for v in value)
    return value is None or (isinstance(value, int | float) and not isinstance(value, bool))


def deduplicate(rows: list[dict[str, Any]]) -> tuple[list[dict[str, Any]], int, int]:
    """Keep the first row of every trial key (:func:`trial_key`).

    Two runs writing into one directory (before the directory lock existed, or
    files concatenated by hand) leave several rows for one trial.

    Returns:
        The rows without duplicates (file order), the number of rows dropped, and
        how many of those disagree with the kept row on the outcome (convergence or
        final errors, to 1e-9).
    """
    kept: dict[tuple[str, int, str, int], dict[str, Any]] = {}
    out: list[dict[str, Any]] = []
    dropped = conflicting = 0
    for row in rows:
        key = trial_key(row)
        first = kept.get(key)
        if first is None:
            kept[key] = row
            out.append(row)
            continue
        dropped += 1
        if not _same_outcome(first, row):
            conflicting += 1
    return out, dropped, conflicting


def _same_outcome(a: dict[str, Any], b: dict[str, Any]) -> bool:
    if a.get("converged") != b.get("converged"):
        return False
    for k in ("final_position_error_mm", "final_orientation_error_deg"):
        x, y = a.get(k), b.get(k)
        if x is None or y is None:
            if x is not y:
                return False
        elif abs(float(x) - float(y)) > 1e-9:
            return False
    return True


def completed_keys(out_dir: Path) -> set[tuple[str, int, str, int]]:
    """Keys of the trials already in ``DIR/results.jsonl`` (empty if none)."""
    path = Path(out_dir) / RESULTS_FILE
    if not path.exists():
        return set()
    return {trial_key(r) for r in read_results(out_dir)}
