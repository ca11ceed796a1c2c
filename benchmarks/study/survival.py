"""Time to converge as censored data, and success against the tolerance as a curve.

A trial that did not converge within its run is not a missing value: it is known only
to need more steps than the run had (right-censored). Dropping it (the steps of the
trials that converged) compares survivors; reading it as ``max_steps`` biases every
figure. The Kaplan-Meier estimate (``scipy.stats.ecdf`` of ``scipy.stats.CensoredData``)
uses each trial for as long as it was observed; its median is the number of steps by
which half the trials converged, with the interval read off the pointwise log-log band
(the earliest step where the band's lower, then its upper, curve falls to one half, as
R's ``survfit`` does; an upper end past the last observed step is ``inf``: "more than
the run"). Controllers are compared by the log-rank test (``scipy.stats.logrank``),
Holm-corrected over the section's comparisons.

A failed trial (an end stop, a crash) counts as not converged, as in the convergence
rate: censored at the run's length, not at the step it stopped.

References: E. L. Kaplan and P. Meier, J. Am. Stat. Assoc. 53, 1958; N. Mantel, Cancer
Chemotherapy Reports 50, 1966; R. Brookmeyer and J. Crowley, Biometrics 38, 1982.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

from benchmarks.exceptions import BenchmarkError
from benchmarks.study import stats

#: Tolerances [mm] of the report's success-against-tolerance table.
TOLERANCES_MM = (0.01, 0.05, 0.1, 0.5, 1.0)


@dataclass(frozen=True)
class TimeToConverge:
    """Kaplan-Meier summary of one group of trials.

    Attributes:
        trials: Trials in the group.
        converged: Trials that converged (events).
        cap: The run's length in steps (the censoring time), nan when unknown.
        median: Kaplan-Meier median steps (``inf``: half the trials did not converge).
        low: Lower end of its 95 % interval.
        high: Upper end (``inf``: beyond the run).
        steps: Distinct event/censoring steps of the curve.
        converged_fraction: ``1 - S(t)`` at ``steps``.
    """

    trials: int
    converged: int
    cap: float
    median: float
    low: float
    high: float
    steps: np.ndarray
    converged_fraction: np.ndarray


def censored_data(rows: list[dict[str, Any]]) -> tuple[Any, int, float]:
    """``scipy.stats.CensoredData`` of the steps to converge of a group's trials: the
    converged ones observed, the others right-censored at the run's length (the longest
    run of the group).

    Returns:
        ``(data, converged, cap)``.

    Raises:
        BenchmarkError: A converged trial without a finite step count (names the
            scenario, controller and trial).
    """
    import scipy.stats as sps

    done, cens = [], 0
    runs = [float(r["steps"]) for r in rows
            if r.get("steps") is not None and np.isfinite(r["steps"])]
    cap = max(runs) if runs else math.nan
    for r in rows:
        if r.get("converged"):
            s = r.get("steps")
            if s is None or not np.isfinite(s):
                raise BenchmarkError(f"results.jsonl: scenario {r.get('scenario')!r}, "
                                     f"controller {r.get('controller')!r}, trial "
                                     f"{r.get('trial')}: converged with steps={s!r} (a "
                                     "converged trial needs a finite step count)")
            done.append(float(s))
        else:
            cens += 1
    right = [cap] * cens if np.isfinite(cap) else []
    return sps.CensoredData(uncensored=done, right=right), len(done), cap


def time_to_converge(rows: list[dict[str, Any]], level: float = stats.LEVEL
                     ) -> TimeToConverge:
    """The Kaplan-Meier curve of a group's steps to converge, its median and interval."""
    import scipy.stats as sps

    data, k, cap = censored_data(rows)
    if k == 0:  # none converged (or no trial): the median is beyond the run, if any
        end = math.inf if rows else math.nan
        return TimeToConverge(len(rows), 0, cap, end, end, end, np.array([]), np.array([]))
    res = sps.ecdf(data)
    t = np.asarray(res.sf.quantiles, float)
    s = np.asarray(res.sf.probabilities, float)
    with warnings.catch_warnings():  # undefined where S is 0 or 1: S itself there
        warnings.simplefilter("ignore", RuntimeWarning)
        band = res.sf.confidence_interval(level, method="log-log")
    lo_band = np.asarray(band.low.probabilities, float)
    hi_band = np.asarray(band.high.probabilities, float)
    lo_band = np.where(np.isnan(lo_band), s, lo_band)
    hi_band = np.where(np.isnan(hi_band), s, hi_band)

    def first_at_half(curve: np.ndarray) -> float:
        hit = np.flatnonzero(curve <= 0.5 + 1e-12)
        return float(t[hit[0]]) if hit.size else math.inf

    return TimeToConverge(len(rows), k, cap, first_at_half(s), first_at_half(lo_band),
                          first_at_half(hi_band), t, 1.0 - s)


def logrank_p(rows_a: list[dict[str, Any]], rows_b: list[dict[str, Any]]) -> float:
    """Two-sided log-rank p-value of two groups' steps to converge (nan when neither
    group has a converged trial)."""
    import scipy.stats as sps

    da, ka, _ = censored_data(rows_a)
    db, kb, _ = censored_data(rows_b)
    if ka + kb == 0:
        return math.nan
    return float(sps.logrank(da, db).pvalue)


def within_tolerance(rows: list[dict[str, Any]], tolerance_mm: float
                     ) -> tuple[int, int, tuple[float, float]]:
    """Trials whose final position error is within ``tolerance_mm`` (a failed or crashed
    trial, without a final error, counts as not within).

    Returns:
        ``(within, trials, Wilson interval of the fraction)``.
    """
    k = int(np.sum(_final_errors(rows) <= tolerance_mm))
    return k, len(rows), stats.wilson_interval(k, len(rows))


def _final_errors(rows: list[dict[str, Any]]) -> np.ndarray:
    """Final position errors [mm], ``inf`` for a failed trial or one without an error."""
    from benchmarks.study.failures import is_failure

    e = np.array([np.inf if (r.get("final_position_error_mm") is None or is_failure(r))
                  else r["final_position_error_mm"] for r in rows], dtype=float)
    return np.where(np.isfinite(e), e, np.inf)


def tolerance_curve(rows: list[dict[str, Any]], grid: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fraction of the trials within each tolerance of ``grid`` [mm] and its Wilson band.

    Returns:
        ``(fraction, low, high)``, arrays like ``grid``.
    """
    e = _final_errors(rows)
    n = e.size
    if n == 0:
        nan = np.full(grid.size, np.nan)
        return nan, nan.copy(), nan.copy()
    k = np.searchsorted(np.sort(e), grid, side="right")
    low, high = stats.wilson_intervals(k, n)
    return k / n, low, high
