"""The verdicts of paired comparisons: Holm's correction, equivalence margins, words.

A comparison is *different* when its test's Holm-adjusted p-value is below
:data:`ALPHA` and the interval of the difference does not contradict the test's
direction (:func:`benchmarks.study.stats.interval_contradicts`; else *unclear*: the
pairs differ, but not shown on which side the typical one lies); *equivalent within M*
when it is not and the two one-sided tests of a
difference of M or more (TOST, Holm-adjusted over the metric's comparisons) both
reject; otherwise *not shown equivalent*: the data say neither. A missing difference is
never read as "no difference".
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from benchmarks.exceptions import BenchmarkError
from benchmarks.study import exact, stats
from hexapod.config import suggest

if TYPE_CHECKING:
    from benchmarks.study.compare import Comparison

#: Significance level of the verdicts (after Holm's correction).
ALPHA = 0.05

#: Default equivalence margins (the metric's unit; ``converged``: a fraction of the
#: trials, 0.05 = 5 percentage points): a paired difference smaller than this is of no
#: practical weight in a benchmark of 0.1 mm tolerances. ``--margin NAME=VALUE``.
MARGINS: dict[str, float] = {
    "converged": 0.05, "final_error": 0.01, "orientation_error": 0.001, "steps": 10.0,
    "tracking_rms": 0.01, "tracking_max": 0.02, "settling": 0.05, "saturation": 0.05,
}
def resolve_margins(margins: dict[str, float] | None,
                    compared: Sequence[str] | None = None) -> dict[str, float]:
    """:data:`MARGINS` updated with ``margins``.

    Args:
        margins: The user's margins by metric name.
        compared: The metrics of the comparison (a margin of another is refused: a
            typo would otherwise leave the default margin in place unsaid).

    Raises:
        BenchmarkError: A margin that is not positive and finite, a ``converged``
            margin above 1 (a fraction of the trials), or one of a metric not compared.
    """
    out = dict(MARGINS)
    for name, value in (margins or {}).items():
        if compared is not None and name not in compared:
            hint = suggest(name, compared)
            raise BenchmarkError(
                f"--margin {name}={value}: {name!r} is not a metric of this comparison "
                f"({', '.join(compared)})" + (f"; did you mean {hint!r}?" if hint else ""))
        if not (np.isfinite(value) and value > 0):
            raise BenchmarkError(f"--margin {name}={value}: an equivalence margin must be "
                                 "positive and finite")
        if name == "converged" and value > 1:
            raise BenchmarkError(f"--margin converged={value}: a fraction of the trials, "
                                 "in (0, 1]")
        out[name] = float(value)
    return out


def margin_text(c: Comparison) -> str:
    """``+-0.01 mm`` (``+-5 points`` for convergence)."""
    if c.margin is None:
        return "-"
    if c.metric == "converged":
        return f"+-{100 * c.margin:.3g} points"
    return f"+-{c.margin:.3g}" + (f" {c.unit}" if c.unit else "")


def holm_and_verdicts(family: list[Comparison], metric: str, higher_better: bool) -> None:
    """Holm's correction over one metric's comparisons, for the difference tests and for
    the equivalence tests apart, then each comparison's outcome and verdict in words:
    *different* (who is better), *equivalent* within the margin, or *not shown
    equivalent* (neither shown different nor shown equivalent)."""
    for c in family:
        if c.n == 0:  # no pairs, no test: its p of 1 counted in Holm's m made the
            c.p_value = c.p_equivalence = float("nan")  # others' correction stricter
    adjusted = stats.holm([c.p_value for c in family])
    adjusted_eq = stats.holm([c.p_equivalence for c in family])
    for c, p, p_eq in zip(family, adjusted, adjusted_eq, strict=True):
        c.p_holm = p
        c.p_equivalence_holm = p_eq
        equivalent = bool(np.isfinite(p_eq) and p_eq < ALPHA)
        eq = (f"TOST Holm p = {exact.format_p(p_eq)} for {margin_text(c)}"
              if c.margin is not None else "no equivalence margin: --margin "
              f"{metric}=VALUE")
        if not np.isfinite(p) or c.n == 0:
            c.verdict = f"{metric}: no pairs to compare"
            c.outcome = "not shown equivalent"
            continue
        if p >= ALPHA or c.direction == 0:
            if equivalent:
                c.outcome = "equivalent"
                c.verdict = (f"{metric}: {c.a} and {c.b} are equivalent within "
                             f"{margin_text(c)} ({_effect(c)}; {eq}, {c.n} pairs)")
            else:
                c.outcome = "not shown equivalent"
                c.verdict = (f"{metric}: {c.a} and {c.b} not shown different, not shown "
                             f"equivalent within {margin_text(c)} (Holm p = "
                             f"{exact.format_p(p)}; {eq}, {c.n} pairs)")
            continue
        if stats.interval_contradicts(c.direction, *c.interval):
            c.outcome = "unclear"
            higher = c.a if c.direction > 0 else c.b
            c.verdict = (f"{metric}: {c.a} and {c.b} differ by the {c.test} test (Holm p = "
                         f"{exact.format_p(p)}, {higher} higher) but the interval of the "
                         f"difference does not say on which side the typical pair lies "
                         f"({_effect(c)}; {c.n} pairs): not shown better")
            continue
        c.outcome = "different"
        a_better = (c.direction > 0) == higher_better
        c.better = c.a if a_better else c.b
        worse = c.b if a_better else c.a
        also = (f"; yet equivalent within {margin_text(c)}, {eq}" if equivalent else "")
        c.verdict = f"{metric}: {c.better} is better than {worse} ({_effect(c)}, " \
                    f"Holm p = {exact.format_p(p)}{also}, {c.n} pairs)"


def _num(x: float, spec: str) -> str:
    """A value of a comparison: ``censored`` for an infinite median or end (steps of
    trials that did not converge), ``-`` for none."""
    if x is None or np.isnan(x):
        return "-"
    if np.isinf(x):
        return "censored" if x > 0 else "-censored"
    return format(x, spec)


def _end(x: float, spec: str) -> str:
    """An interval's end: ``-inf``/``inf`` where it has no finite bound (outside the
    sample, or on a censored pair)."""
    if x is not None and np.isinf(x):
        return "inf" if x > 0 else "-inf"
    return _num(x, spec)


def _effect(c: Comparison) -> str:
    lo, hi = c.interval
    if c.metric == "converged":
        return (f"{c.a} {100 * c.a_value:.1f} % against {c.b} {100 * c.b_value:.1f} %, "
                f"difference {100 * c.difference:+.1f} points [{100 * lo:+.1f}, "
                f"{100 * hi:+.1f}]")
    unit = f" {c.unit}" if c.unit else ""
    up, down = c.discordant or (0, 0)
    return (f"median paired difference {_num(c.difference, '+.4g')}{unit} "
            f"[{_end(lo, '+.4g')}, {_end(hi, '+.4g')}] ({c.a} - {c.b}), medians {c.a} "
            f"{_num(c.a_value, '.4g')} and {c.b} {_num(c.b_value, '.4g')}{unit}; {c.a} "
            f"higher in {up} and lower in {down} of the pairs")


