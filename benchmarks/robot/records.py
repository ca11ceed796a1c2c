"""The record of every servo session: one JSON Lines file, written whatever happens
(``docs/servo.md``, "The session record"): a header ``{"servo_session": 1, ...}``, one
line per period (:meth:`~benchmarks.robot.status.PeriodStatus.to_json`, flushed each
period) and the final record ``{"final": true, ...}``, written on every exit path once
the file exists. Where it goes: :func:`session_path`.
"""

from __future__ import annotations

import datetime as dt
import json
import math
from pathlib import Path
from typing import IO, Any

from hexapod.exceptions import OutputError
from hexapod.outputs import check_name, check_replace

#: Where sessions are recorded by default (relative to the working directory).
SESSIONS_DIR = "servo-runs"
#: The log's name in a session directory.
LOG_NAME = "servo.jsonl"
#: Version of the header.
FORMAT = 1


def is_period(row: Any) -> bool:
    """A record's line is a period (``step``, ``t_s``)."""
    return isinstance(row, dict) and {"step", "t_s"} <= set(row)


def is_header(row: Any) -> bool:
    """A record's line is the session's header."""
    return isinstance(row, dict) and "servo_session" in row


def is_servo_log(path: Path) -> bool:
    """A log ``servo`` wrote: its first line (blank lines skipped) is a session header,
    or (older logs) a period."""
    try:
        with path.open(encoding="utf-8") as f:
            first = next((line for line in f if line.strip()), "")
        row = json.loads(first)
    except (OSError, ValueError):  # UnicodeDecodeError and JSON errors are ValueErrors
        return False
    return is_header(row) or is_period(row)


def _has_final(path: Path) -> bool:
    """Whether a servo log ends with its final record."""
    try:
        lines = [line for line in path.read_text(encoding="utf-8").splitlines()
                 if line.strip()]
        return bool(lines) and json.loads(lines[-1]).get("final") is True
    except (OSError, ValueError, AttributeError):
        return False


def _safe(text: str) -> str:
    keep = "".join(c if c.isalnum() or c in "-_." else "-" for c in text)
    return keep.strip("-.") or "controller"


def session_path(out: str | None, log: str | None, controller: str,
                 now: dt.datetime | None = None) -> Path:
    """Where the session's log goes (checked; nothing is created): in ``--out DIR``
    (absent or empty), the ``--log FILE`` (an earlier servo log with its final record
    is replaced; one without, an interrupted session's, and any other file refused),
    else a new directory named by the time ``now`` (default: now, UTC) and the
    ``controller``.

    Raises:
        OutputError: ``--out`` is a file or a directory that is not empty, ``--log`` a
            file the project did not write, both given.
    """
    if out is not None and log is not None:
        raise OutputError(str(log), "give --log FILE or --out DIR, not both")
    if log is not None:
        check_replace(log, ours=is_servo_log, how="choose another --log, or delete it")
        if Path(log).is_file() and not _has_final(Path(log)):
            raise OutputError(str(log), "holds a session that ended without its final record "
                                        "(killed, or the power lost): it is the only record of "
                                        "what the robot did, and is not replaced; move it "
                                        "away or choose another --log")
        return Path(log)
    if out is not None:
        d = Path(out)
        if d.exists() and (not d.is_dir() or any(d.iterdir())):
            what = "is not a directory" if not d.is_dir() else "is not empty"
            raise OutputError(str(d), f"{what}; --out takes a new or empty directory (a "
                                      "session never replaces a record)")
        return d / LOG_NAME
    stamp = (now or dt.datetime.now(dt.UTC)).strftime("%Y%m%dT%H%M%SZ")
    name = f"{stamp}-{_safe(controller)}"
    check_name(name, "session directory")
    base = Path(SESSIONS_DIR) / name
    d, n = base, 1
    while d.exists():
        n += 1
        d = base.with_name(f"{name}-{n}")
    return d / LOG_NAME


def mm_list(values: Any) -> list[float]:
    """Lengths or speeds [m, m/s] as the records write them: mm (mm/s), to 0.1 um."""
    return [round(float(x) * 1e3, 4) for x in values]


def _clean(value: Any) -> Any:
    """JSON-safe: NaN and infinities as null."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _clean(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_clean(v) for v in value]
    return value


class SessionLog:
    """The session's JSON Lines record (created by :meth:`open`, closed by :meth:`final`).

    Args:
        path: The log file (its directory is created).
    """

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self._f: IO[str] | None = None

    def open(self, header: dict[str, Any]) -> SessionLog:
        """Create the file and write the header.

        Raises:
            OutputError: The directory or file cannot be created.
        """
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._f = self.path.open("w", encoding="utf-8")
        except OSError as exc:
            raise OutputError(str(self.path), f"cannot be written: {exc}") from None
        self.write({"servo_session": FORMAT, **header})
        return self

    def write(self, record: dict[str, Any]) -> None:
        """One line (a period's), flushed."""
        if self._f is None:
            return
        self._f.write(json.dumps(_clean(record)) + "\n")
        self._f.flush()  # readable live (tail -f), and complete after a crash

    def final(self, record: dict[str, Any]) -> None:
        """The final record, then close (once; nothing before :meth:`open`)."""
        if self._f is not None:
            self.write({"final": True, **record})
            self._f.close()
            self._f = None
