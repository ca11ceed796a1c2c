"""Failure causes grouped by kind: one group per leg's end stop whatever length each
trial reached, its lengths given as their range; other kinds stay apart."""

from __future__ import annotations

from typing import Any

from benchmarks.study.failures import cause_kind, failure_groups, failure_summary
from benchmarks.study.report import failures_section

STROKE = "stroke [345.000, 485.000] mm"


def _row(trial: int, failure: str, controller: str = "computed-torque",
         point: int = 0) -> dict[str, Any]:
    return {"scenario": "circle", "point": point, "controller": controller, "trial": trial,
            "converged": False, "failure": failure}


def _end_stop(leg: int, length: float) -> str:
    return f"leg {leg} hit its end stop: {length:.3f} mm, {STROKE}"


def test_end_stops_of_one_leg_are_one_cause() -> None:
    lengths = [485.101, 486.250, 485.733, 487.004, 485.512]
    rows = [_row(k, _end_stop(1, q)) for k, q in enumerate(lengths)]
    rows += [_row(10 + k, _end_stop(4, 344.2 - k), "cartesian-ctc", point=k % 2)
             for k in range(3)]
    rows += [_row(20, "not converged: position 0.8 mm > 0.5 mm after 300 steps")]
    rows += [_row(21, "RuntimeError: boom 1.5")]
    groups = failure_groups(rows)
    assert [(g.count, g.cause) for g in groups] == [
        (5, f"leg 1 hit its end stop: 485.101 to 487.004 mm, {STROKE}"),
        (3, f"leg 4 hit its end stop: 342.200 to 344.200 mm, {STROKE}"),
        (1, "RuntimeError: boom 1.5"),
    ]
    assert groups[0].example.endswith(_end_stop(1, 485.101))  # the first in full
    assert groups[1].points == {"circle/p0", "circle/p1"}
    lines = failure_summary(rows)
    assert lines[0] == "9 of 10 trials failed (did not run to their end):"
    assert len(lines) == 4  # one line per kind, not one per length
    section = "\n".join(failures_section(rows))
    assert "one entry per kind of cause" in section
    assert section.count("\n- **") == 3  # one entry per kind
    assert f"**5 trial(s)** (computed-torque: 5; sweep points: circle/p0): leg 1 hit its end " \
           f"stop: 485.101 to 487.004 mm, {STROKE}" in section


def test_kind_keeps_the_integers_that_name_what_failed() -> None:
    assert cause_kind(_end_stop(1, 425.101)) == cause_kind(_end_stop(1, 431.0))
    assert cause_kind(_end_stop(1, 425.101)) != cause_kind(_end_stop(2, 425.101))
    assert cause_kind("controller refused to move: 3 legs") != cause_kind(
        "controller refused to move: 4 legs")
    assert cause_kind("x 1e-3 and 2.5E+02") == "x # and #"


def test_a_missing_failure_read_from_a_table_is_no_failure() -> None:
    """pandas 3 reads an empty ``failure`` column as NaN, and ``bool(nan)`` is true:
    ``reproduce`` marked every converged trial of a study failed ("every trial failed
    (nan)")."""
    import math

    from benchmarks.study.failures import is_failure

    assert not is_failure({"failure": math.nan})
    assert not is_failure({"failure": None}) and not is_failure({})
    assert not is_failure({"failure": "not converged: position 0.8 mm > 0.5 mm"})
    assert is_failure({"failure": "RuntimeError: boom"})
