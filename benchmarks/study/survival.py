"""Time to converge as censored data, and success against the tolerance as a curve.

A trial that did not converge within its run is not a missing value: it is known only
to need more steps than the run had (right-censored). Dropping it (the steps of the
trials that converged) compares survivors; reading it as ``max_steps`` biases every
figure. The Kaplan-Meier estimate uses each trial for as long as it was observed; its
median is the number of steps by which half the trials converged, with the interval read
off the pointwise log-log ("exponential Greenwood") band (the earliest step where the
band's lower, then its upper, curve falls to one half, as R's ``survfit`` does; an upper
end past the last observed step is ``inf``: "more than the run"). Controllers are
compared by the log-rank test, Holm-corrected over the section's comparisons.

The estimate, its band and the test are the arithmetic of ``scipy.stats.ecdf`` (of a
``scipy.stats.CensoredData``), its ``confidence_interval(method="log-log")`` and
``scipy.stats.logrank``, operation for operation (the tests compare them bit for bit):
``scipy.stats`` takes 0.5-1 s to import, more than the rest of a report's statistics;
only ``scipy.special`` (the normal distribution) is used.

A failed trial (an end stop, a crash) counts as not converged, as in the convergence
rate: censored at the run's length, not at the step it stopped.

References: E. L. Kaplan and P. Meier, J. Am. Stat. Assoc. 53, 1958; N. Mantel, Cancer
Chemotherapy Reports 50, 1966; R. Brookmeyer and J. Crowley, Biometrics 38, 1982;
S. Sawyer, "The Greenwood and Exponential Greenwood Confidence Intervals in Survival
Analysis", 2003.
"""

from __future__ import annotations

import math
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


@dataclass(frozen=True)
class Censored:
    """Right-censored steps to converge of a group of trials.

    Attributes:
        uncensored: Steps of the trials that converged (observed events).
        right: Steps at which the other trials were censored (the run's length).
    """

    uncensored: np.ndarray
    right: np.ndarray


@dataclass(frozen=True)
class Curve:
    """Kaplan-Meier survival curve at the distinct steps of a sample.

    Attributes:
        steps: Distinct event or censoring steps, increasing.
        survival: ``S(t)`` at ``steps``: the fraction not yet converged.
        at_risk: Trials not yet converged nor censored just before each step.
        events: Trials that converged at each step.
    """

    steps: np.ndarray
    survival: np.ndarray
    at_risk: np.ndarray
    events: np.ndarray


def censored_data(rows: list[dict[str, Any]], run: float = math.nan
                  ) -> tuple[Censored, int, float]:
    """The steps to converge of a group's trials as censored data: the converged ones
    observed, the others right-censored at the run's length (``run``, the longest run of
    the sweep point: :func:`benchmarks.study.stats.run_length`; at least the longest run
    of the group).

    Returns:
        ``(data, converged, cap)``.

    Raises:
        BenchmarkError: A converged trial without a finite step count (names the
            scenario, controller and trial).
    """
    done, cens = [], 0
    cap = float(np.nanmax([stats.run_length(rows), run]))
    for r in rows:
        if r.get("converged"):
            s = r.get("steps")
            if s is None or not math.isfinite(s):
                raise BenchmarkError(f"results.jsonl: scenario {r.get('scenario')!r}, "
                                     f"controller {r.get('controller')!r}, trial "
                                     f"{r.get('trial')}: converged with steps={s!r} (a "
                                     "converged trial needs a finite step count)")
            done.append(float(s))
        else:
            cens += 1
    right = [cap] * cens if np.isfinite(cap) else []
    return (Censored(np.array(done, dtype=float), np.array(right, dtype=float)), len(done),
            cap)


def kaplan_meier(data: Censored) -> Curve:
    """The Kaplan-Meier curve of censored steps (``scipy.stats.ecdf(data).sf``, the same
    operations: without censored trials the empirical survival ``1 - k/n``, with them the
    product of ``(n - d) / n`` over the distinct steps)."""
    if data.right.size == 0:
        sample = np.sort(data.uncensored)
        steps, events = np.unique(sample, return_counts=True)
        cumulative = np.cumsum(events)
        n = sample.size
        at_risk = np.concatenate(([n], n - cumulative[:-1]))
        return Curve(steps, 1 - cumulative / n, at_risk, events)
    times = np.concatenate((data.uncensored, data.right))
    died = np.asarray([1] * data.uncensored.size + [0] * data.right.size)
    order = np.argsort(times)
    times, died = times[order], died[order]
    risk = np.arange(times.size, 0, -1)
    unique = np.diff(times, prepend=-np.inf, append=np.inf) > 0
    first, last = unique[:-1], unique[1:]  # first and last instances of each step
    at_risk = risk[first]
    events = np.diff(np.cumsum(died)[last], prepend=0)
    return Curve(times[first], np.cumprod((at_risk - events) / at_risk), at_risk, events)


def log_log_band(curve: Curve, level: float) -> tuple[np.ndarray, np.ndarray]:
    """The pointwise log-log (exponential Greenwood) band of a Kaplan-Meier curve, as
    ``confidence_interval(level, method="log-log")`` of ``scipy.stats.ecdf``'s ``sf``
    computes it (``nan`` where it is undefined, where ``S`` is 0 or 1; clipped to
    [0, 1]).

    Returns:
        ``(low, high)``, arrays like ``curve.survival``.
    """
    from scipy.special import ndtri

    sf, d, n = curve.survival, curve.events, curve.at_risk
    with np.errstate(divide="ignore", invalid="ignore"):
        var = 1 / np.log(sf) ** 2 * np.cumsum(d / (n * (n - d)))
        se = np.sqrt(var)
        z = ndtri(1 / 2 + level / 2)
        lnl_points = np.log(-np.log(sf))
        z_se = z * se
        low = np.exp(-np.exp(lnl_points + z_se))
        high = np.exp(-np.exp(lnl_points - z_se))
    return np.clip(low, 0, 1), np.clip(high, 0, 1)


def time_to_converge(rows: list[dict[str, Any]], level: float = stats.LEVEL,
                     run: float = math.nan) -> TimeToConverge:
    """The Kaplan-Meier curve of a group's steps to converge, its median and interval
    (``run``: the run's length, :func:`censored_data`)."""
    data, k, cap = censored_data(rows, run)
    if k == 0:  # none converged (or no trial): the median is beyond the run, if any
        end = math.inf if rows else math.nan
        return TimeToConverge(len(rows), 0, cap, end, end, end, np.array([]), np.array([]))
    curve = kaplan_meier(data)
    t = np.asarray(curve.steps, float)
    s = np.asarray(curve.survival, float)
    # the band is undefined where S is 0 or 1: there the lower curve is S (it lies below
    # S, so it has reached 0 where S has), the upper one S where S is 1 and undefined
    # where S is 0, as R's survfit has it (NA): an upper curve that is above one half
    # wherever it is defined never reaches it, and the interval's upper end is inf (with
    # every trial converged, reading S = 0 there closed the interval at the last trial's
    # steps: 76 % coverage at 3 trials, 89 % at 4)
    lo_band, hi_band = log_log_band(curve, level)
    lo_band = np.where(np.isnan(lo_band), s, lo_band)
    hi_band = np.where(np.isnan(hi_band) & (s > 0), s, hi_band)

    def first_at_half(curve: np.ndarray) -> float:
        hit = np.flatnonzero(curve <= 0.5 + 1e-12)  # (NaN: not reached)
        return float(t[hit[0]]) if hit.size else math.inf

    return TimeToConverge(len(rows), k, cap, first_at_half(s), first_at_half(lo_band),
                          first_at_half(hi_band), t, 1.0 - s)


def logrank_statistic(a: Censored, b: Censored) -> float:
    """The log-rank statistic of two censored samples, signed (positive: ``a`` converged
    more often than expected under the null hypothesis), as ``scipy.stats.logrank``
    computes it: the square root of the usual chi-squared statistic."""
    pooled = kaplan_meier(Censored(np.concatenate((a.uncensored, b.uncensored)),
                                   np.concatenate((a.right, b.right))))
    idx = pooled.events.astype(bool)  # the steps where some trial converged
    times_xy = pooled.steps[idx]
    at_risk_xy = pooled.at_risk[idx]
    deaths_xy = pooled.events[idx]
    curve_a = kaplan_meier(a)
    at_risk_x = np.append(curve_a.at_risk, 0)[np.searchsorted(curve_a.steps, times_xy)]
    at_risk_y = at_risk_xy - at_risk_x
    num = at_risk_x * at_risk_y * deaths_xy * (at_risk_xy - deaths_xy)
    den = at_risk_xy ** 2 * (at_risk_xy - 1)
    i = at_risk_xy > 1  # one at risk: no variance (the fraction is 0 symbolically)
    sum_var = np.sum(num[i] / den[i])
    sum_exp_deaths_x = np.sum(at_risk_x * (deaths_xy / at_risk_xy))
    with np.errstate(divide="ignore", invalid="ignore"):
        return float((a.uncensored.size - sum_exp_deaths_x) / np.sqrt(sum_var))


def logrank_p(rows_a: list[dict[str, Any]], rows_b: list[dict[str, Any]],
              run: float = math.nan) -> float:
    """Two-sided log-rank p-value of two groups' steps to converge (nan when neither
    group has a converged trial; ``run``: the run's length, at least the longest run of
    the two groups, :func:`censored_data`)."""
    from scipy.special import ndtr

    run = float(np.nanmax([stats.run_length([*rows_a, *rows_b]), run]))
    da, ka, _ = censored_data(rows_a, run)
    db, kb, _ = censored_data(rows_b, run)
    if ka + kb == 0:
        return math.nan
    return float(2 * ndtr(-np.abs(logrank_statistic(da, db))))


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
