"""Trial failures in the user's terms, grouped by cause.

A trial that cannot run to its end (no pose inside the strokes, a camera that sees no leg
at the goal, a controller that refuses its context...) gets a ``failure`` in its row (the
exception, for the record) and a ``cause``: one line in the user's terms, with the file
key to change where there is one. The command line prints each distinct cause once with
its count (:func:`failure_summary`), the report lists them in full (:func:`failure_groups`)
and a run where every trial failed exits non-zero (:func:`every_trial_failed`).

Repeated log warnings (the same warning for every sweep point of a large map) are printed
once per distinct message template and counted (:class:`RepeatedWarnings`).
"""

from __future__ import annotations

import logging
import math
import re
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

from benchmarks.exceptions import user_message  # noqa: F401 - where the study finds it

#: A failure that only says the trial did not converge: the trial ran to its end.
NOT_CONVERGED = "not conv"


def is_failure(row: dict[str, Any]) -> bool:
    """Whether a result row is a trial that did not run to its end (not merely unconverged).
    A missing failure is None in a row and NaN in a table's column (pandas 3 reads an
    empty one so: every converged trial was counted failed)."""
    failure = row.get("failure")
    if failure is None or (isinstance(failure, float) and math.isnan(failure)):
        return False
    return bool(failure) and not str(failure).startswith(NOT_CONVERGED)


def row_cause(row: dict[str, Any]) -> str:
    """The cause of a failed row: its ``cause`` (user's terms), else its ``failure``."""
    return str(row.get("cause") or row.get("failure"))


#: A measured value in a cause (a number with a decimal point or an exponent): the
#: integers of a cause name what is at fault (a leg, a step count) and stay in its kind.
_MEASURE = re.compile(r"(-?\d+\.\d+(?:e[-+]?\d+)?|-?\d+e[-+]?\d+)", re.IGNORECASE)


def cause_kind(cause: str) -> str:
    """The kind of a cause: its text with the measured values left out.

    ``leg 1 hit its end stop: 425.101 mm, stroke [400.000, 500.000] mm`` and the same
    with 426.3 mm are one kind (leg 1's end stop); leg 2's end stop is another.
    """
    return _MEASURE.sub("#", cause)


def _merge_causes(causes: list[str]) -> str:
    """One text for causes of one kind: each measured value that differs between them
    given as its range (``425.101 to 431.250 mm``), the others as they are."""
    parts = [_MEASURE.split(c) for c in causes]
    out = list(parts[0])
    for i in range(1, len(out), 2):  # the odd parts are the measured values
        texts = [p[i] for p in parts]
        if len(set(texts)) > 1:
            values = [float(t) for t in texts]
            out[i] = f"{texts[values.index(min(values))]} to {texts[values.index(max(values))]}"
    return "".join(out)


@dataclass
class FailureGroup:
    """The failed trials that share a kind of cause (:func:`cause_kind`).

    Attributes:
        cause: The cause, in the user's terms; the measured values that differ between
            the trials given as their range.
        count: Failed trials.
        controllers: Failed trials per controller label.
        points: Sweep points (``scenario/p<k>``) where it happened.
        example: The identity of the first such trial and its full exception text.
    """

    cause: str
    count: int = 0
    controllers: Counter[str] = field(default_factory=Counter)
    points: set[str] = field(default_factory=set)
    example: str = ""


def failure_groups(rows: list[dict[str, Any]]) -> list[FailureGroup]:
    """The failed rows grouped by kind of cause (:func:`cause_kind`: one group for leg
    1's end stop whatever length each trial reached), the most frequent first."""
    groups: dict[str, FailureGroup] = {}
    causes: dict[str, list[str]] = {}
    for r in rows:
        if not is_failure(r):
            continue
        cause = row_cause(r)
        kind = cause_kind(cause)
        g = groups.get(kind)
        if g is None:
            g = groups[kind] = FailureGroup(
                cause, example=f"{r.get('scenario')}/p{r.get('point', 0)}/"
                               f"{r.get('controller')}/trial {r.get('trial')}: {r['failure']}")
            causes[kind] = []
        causes[kind].append(cause)
        g.count += 1
        g.controllers[str(r.get("controller"))] += 1
        g.points.add(f"{r.get('scenario')}/p{r.get('point', 0)}")
    for kind, g in groups.items():
        g.cause = _merge_causes(causes[kind])
    return sorted(groups.values(), key=lambda g: -g.count)


#: Exit code of ``run`` when every trial of the results directory failed.
EVERY_TRIAL_FAILED = 1
#: Exit code of ``run`` when a controller failed every one of its trials (others ran).
CONTROLLER_FAILED = 3


def controllers_failing_every_trial(rows: list[dict[str, Any]]) -> dict[str, int]:
    """The controllers (labels, per scenario) none of whose trials ran to its end, with
    their trial counts."""
    by: dict[str, list[bool]] = {}
    for r in rows:
        key = f"{r.get('controller')}" + (f" ({r.get('scenario')})" if r.get("scenario")
                                          else "")
        by.setdefault(key, []).append(is_failure(r))
    return {k: len(v) for k, v in by.items() if v and all(v)}


def every_trial_failed(rows: list[dict[str, Any]]) -> bool:
    """True when there are rows and none of them ran to its end."""
    return bool(rows) and all(is_failure(r) for r in rows)


def failure_summary(rows: list[dict[str, Any]]) -> list[str]:
    """The lines the command line prints: one per distinct cause, with its count."""
    groups = failure_groups(rows)
    if not groups:
        return []
    failed = sum(g.count for g in groups)
    lines = [f"{failed} of {len(rows)} trials failed (did not run to their end):"]
    for g in groups:
        who = ", ".join(f"{c} {n}" for c, n in sorted(g.controllers.items()))
        where = f"; {len(g.points)} sweep points" if len(g.points) > 1 else ""
        lines.append(f"  {g.count} x ({who}{where}): {g.cause}")
    return lines


class RepeatedWarnings(logging.Filter):
    """Let the first warning of each distinct cause through, count the repeats.

    The cause of a record is its ``cause`` attribute (``extra={"cause": ...}``) when it
    has one, else its logger, message template and integer arguments: the integers name
    what is at fault (a leg, a count), the other values are measurements, so "leg 3 is
    ill-conditioned (ratio 0.011)" in every sweep point is one cause and leg 4 another.
    A record seen by several handlers is counted once. Records below WARNING pass.
    """

    def __init__(self) -> None:
        super().__init__()
        self.counts: Counter[tuple[str, str]] = Counter()
        self.first: dict[tuple[str, str], str] = {}
        self.summarised: set[tuple[str, str]] = set()
        self._last: tuple[logging.LogRecord, bool] | None = None

    def filter(self, record: logging.LogRecord) -> bool:
        """Whether to emit the record (the first of its cause)."""
        if record.levelno < logging.WARNING:
            return True
        if self._last is not None and self._last[0] is record:  # another handler: same answer
            return self._last[1]
        emit = self._count(record)
        self._last = (record, emit)
        return emit

    def _count(self, record: logging.LogRecord) -> bool:
        """Count a record once; True for the first of its cause."""
        cause = getattr(record, "cause", None)
        if cause:
            key = (record.name, str(cause))
        else:
            args = record.args if isinstance(record.args, tuple) else ()
            ints = [a for a in args if isinstance(a, int) and not isinstance(a, bool)]
            key = (record.name, f"{record.msg} {ints}")
        if cause:  # a trial failure: the failure summary counts it
            self.summarised.add(key)
        self.counts[key] += 1
        if self.counts[key] == 1:
            self.first[key] = record.getMessage()
            return True
        return False

    def repeats(self) -> list[str]:
        """One line per cause that was repeated (other than the trial failures, which
        :func:`failure_summary` counts): how many more, and the first message."""
        return [f"{n - 1} more warning(s) like: {self.first[k]}"
                for k, n in self.counts.items() if n > 1 and k not in self.summarised]


class summarised_warnings:  # noqa: N801 - used as a context manager, like contextlib's
    """Attach a :class:`RepeatedWarnings` to the root logger's handlers for a run.

    Args:
        enabled: False (``-v``): every warning is printed, nothing is counted.
    """

    def __init__(self, enabled: bool = True) -> None:
        self.filter = RepeatedWarnings()
        self.enabled = enabled
        self._handlers: list[logging.Handler] = []

    def __enter__(self) -> RepeatedWarnings:
        if self.enabled:
            self._handlers = list(logging.getLogger().handlers)
            for h in self._handlers:
                h.addFilter(self.filter)
        return self.filter

    def __exit__(self, *exc: object) -> None:
        for h in self._handlers:
            h.removeFilter(self.filter)
