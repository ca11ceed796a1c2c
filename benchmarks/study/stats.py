"""Statistics of a benchmark: intervals for rates and quantiles, paired tests, Holm.

Every controller of a run meets the same trials (same worlds, same draws), so two
controllers are compared on paired data:

- rates (convergence): Wilson score interval (no continuity correction) at 95 %;
- medians and 95th percentiles: the distribution-free order-statistic interval
  (:mod:`benchmarks.study.exact`); the seeded percentile bootstrap
  (:func:`bootstrap_quantiles`, :data:`SEED`, :data:`RESAMPLES`) stays available, no
  table uses it;
- convergence of two controllers on the same trials: McNemar's exact test, the
  two-sided binomial test on the discordant pairs, and Newcombe's paired interval of
  the rate difference;
- paired continuous metrics (final error): Wilcoxon's signed-rank test (as
  ``scipy.stats.wilcoxon`` computes it), and the median of the paired differences
  with its order-statistic interval;
- several comparisons at once: Holm's step-down correction.

References: E. B. Wilson, "Probable inference, the law of succession, and statistical
inference", J. Am. Stat. Assoc. 22, 1927; Q. McNemar, Psychometrika 12, 1947;
F. Wilcoxon, Biometrics Bulletin 1, 1945; S. Holm, Scand. J. Statistics 6, 1979;
B. Efron and R. Tibshirani, "An Introduction to the Bootstrap", 1993; R. G. Newcombe,
Statistics in Medicine 17, 2635-2650, 1998.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from fractions import Fraction
from statistics import NormalDist
from typing import Any

import numpy as np

from benchmarks.study import exact

#: Confidence level of every interval.
LEVEL = 0.95
#: Seed of :func:`bootstrap_quantiles` (kept for users' scripts; no report uses it).
SEED = 0
#: Resamples of :func:`bootstrap_quantiles`.
RESAMPLES = 2000


@dataclass(frozen=True)
class TestResult:
    """A paired comparison of ``a`` and ``b`` (difference: ``a - b``).

    Attributes:
        test: ``"mcnemar-exact"`` or ``"wilcoxon"``.
        n: Pairs used (both values present).
        statistic: McNemar: pairs where only ``a`` succeeded; Wilcoxon: the smaller of
            the signed-rank sums (scipy's two-sided statistic).
        p_value: Two-sided p-value.
        difference: McNemar: difference of the success rates; Wilcoxon: median of the
            paired differences.
        low: Lower end of the difference's 95 % interval (McNemar: Newcombe's paired
            interval; Wilcoxon: the order-statistic interval of the median difference,
            the sign test's).
        high: Upper end of that interval.
        discordant: McNemar: (only ``a`` succeeded, only ``b`` succeeded); Wilcoxon:
            (pairs with ``a > b``, pairs with ``a < b``).
        direction: +1 when ``a`` tends to exceed ``b`` (more successes; a larger
            positive rank sum), -1 the other way, 0 for a tie: the side the test's
            evidence points to, which the median difference can hide (steps: a median
            difference of 0 with most of the non-zero differences on one side).
    """

    test: str
    n: int
    statistic: float
    p_value: float
    difference: float
    low: float
    high: float
    discordant: tuple[int, int] | None = None
    direction: int = 0

    @property
    def interval_disagrees(self) -> bool:
        """:func:`interval_contradicts` of this test's direction and interval."""
        return interval_contradicts(self.direction, self.low, self.high)


def interval_contradicts(direction: int, low: float, high: float) -> bool:
    """Whether a difference's interval ``[low, high]`` contradicts a test's ``direction``
    (+1: ``a`` above ``b``): 0 strictly inside it, or the interval on the other side. A
    significant test with such an interval shows that the pairs differ (their ranks,
    their signs) but not on which side the typical difference lies: a verdict of
    *better* would say more than the numbers (0 at an end, as with many tied pairs, does
    not contradict)."""
    if direction == 0 or math.isnan(low) or math.isnan(high):
        return False
    return low < 0 < high or (high < 0 if direction > 0 else low > 0)


def _check_level(level: float) -> None:
    """Refuse a confidence level outside (0, 1) (95 given for 0.95, most often).

    Raises:
        ValueError: ``level`` outside (0, 1), or NaN.
    """
    if not 0 < level < 1:
        hint = " (a fraction, not a percentage)" if 1 < level <= 100 else ""
        raise ValueError(f"confidence level {level}: must lie in (0, 1){hint}")


def wilson_interval(k: int, n: int, level: float = LEVEL) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion ``k / n`` (no continuity correction).

    Args:
        k: Successes.
        n: Trials (0 gives ``(nan, nan)``).
        level: Confidence level.

    Returns:
        ``(low, high)`` as fractions in [0, 1].

    Raises:
        ValueError: ``k`` outside ``[0, n]``, or ``level`` outside (0, 1).
    """
    if not 0 <= k <= n:
        raise ValueError(f"successes k={k} must lie in [0, n={n}]")
    _check_level(level)
    if n == 0:
        return float("nan"), float("nan")
    low, high = wilson_intervals(np.array([k]), n, level)
    return float(low[0]), float(high[0])


def wilson_intervals(k: np.ndarray, n: int, level: float = LEVEL
                     ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`wilson_interval` of many success counts out of the same ``n`` at once (a
    curve's pointwise band), as arrays (``n`` must be positive; ``k`` in ``[0, n]``).

    Raises:
        ValueError: ``n`` not positive, a ``k`` outside ``[0, n]``, or ``level`` outside
            (0, 1).
    """
    k = np.asarray(k, dtype=float)
    if not n > 0:
        raise ValueError(f"trials n {n}: must be positive")
    _check_level(level)
    bad = np.flatnonzero(~((k >= 0) & (k <= n)))
    if bad.size:
        i = int(bad[0])
        value = float(k.flat[i])
        where = f" at index {i}" if k.ndim else ""
        if value > n:
            raise ValueError(f"successes k {value:g}{where} > n {n}: must lie in [0, n]")
        raise ValueError(f"successes k {value:g}{where}: must lie in [0, n {n}]")
    z = NormalDist().inv_cdf(0.5 + level / 2)
    p = k / n
    denom = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    low = np.where(k == 0, 0.0, np.maximum(0.0, centre - half))
    high = np.where(k == n, 1.0, np.minimum(1.0, centre + half))
    return low, high


def finite_values(values: Sequence[float | None] | np.ndarray) -> np.ndarray:
    """The finite values, as floats in their order (None, NaN and infinities left out;
    one test over the array, not one NumPy call per value)."""
    arr = np.asarray([np.nan if v is None else v for v in values], dtype=float)
    return arr[np.isfinite(arr)]


def run_length(rows: Sequence[dict[str, Any]]) -> float:
    """The run's length [steps] seen in ``rows``: their longest run (NaN for none). Give
    it every trial of a sweep point, all controllers: a group whose every trial failed
    early has not seen the run's end, and its censored trials go at the run's end."""
    runs = finite_values([r.get("steps") for r in rows])
    return float(runs.max()) if runs.size else math.nan


def bootstrap_quantiles(values: Sequence[float] | np.ndarray, quantiles: Sequence[float],
                        resamples: int = RESAMPLES, seed: int = SEED, level: float = LEVEL
                        ) -> list[tuple[float, float]]:
    """Percentile-bootstrap intervals of quantiles of a sample (one resampling for all).

    Each resample draws ``n`` values with replacement; its quantile is that of
    ``numpy.quantile`` (linear interpolation between two order statistics, as the
    report's medians and p95). The interval is the ``(1 - level) / 2`` and
    ``(1 + level) / 2`` quantiles of the resampled statistic. Missing and non-finite
    values are left out.

    A resample's quantile only needs a few of its order statistics, so they are drawn
    directly instead of the ``n`` values: a draw with replacement is
    ``floor(n * U)`` with ``U`` uniform, ``floor`` keeps the order, and the ``k``-th
    smallest of ``n`` uniforms is ``Beta(k, n + 1 - k)``; given it, the ``k'``-th
    (``k' > k``) is it plus ``(1 - it) * Beta(k' - k, n + 1 - k')``. The statistic
    then has exactly the distribution of explicit resampling, at a cost independent
    of ``n`` (``tests/benchmarks/study/test_stats.py`` checks it against explicit
    resampling and ``scipy.stats.bootstrap``).

    Args:
        values: The sample.
        quantiles: Quantiles in [0, 1] (0.5: median, 0.95: p95).
        resamples: Number of resamples.
        seed: Seed of ``numpy.random.default_rng``.
        level: Confidence level.

    Returns:
        One ``(low, high)`` per quantile (``nan`` for an empty sample).

    Raises:
        ValueError: A quantile outside [0, 1] (50 given for 0.5), or ``level`` outside
            (0, 1).
    """
    _check_level(level)
    for i, q in enumerate(quantiles):
        if not 0 <= q <= 1:
            hint = " (a fraction, not a percentage)" if 1 < q <= 100 else ""
            raise ValueError(f"quantile q {q} at index {i}: must lie in [0, 1]{hint}")
    x = np.sort(finite_values(values))
    n = x.size
    if n == 0:
        return [(float("nan"), float("nan")) for _ in quantiles]
    if n == 1:
        return [(float(x[0]), float(x[0])) for _ in quantiles]
    rng = np.random.default_rng(seed)
    pos = [q * (n - 1) for q in quantiles]
    # 1-based ranks of the order statistics needed, increasing
    ranks = sorted({min(int(np.floor(p)) + d, n - 1) + 1 for p in pos for d in (0, 1)})
    u = np.zeros(resamples)
    order: dict[int, np.ndarray] = {}
    prev = 0
    for k in ranks:
        u = u + (1.0 - u) * rng.beta(k - prev, n + 1 - k, size=resamples)
        order[k] = np.minimum((n * u).astype(np.int64), n - 1)
        prev = k
    tail = 100 * (1 - level) / 2
    out = []
    for p in pos:
        lo = int(np.floor(p))
        hi = min(lo + 1, n - 1)
        a, b = x[order[lo + 1]], x[order[hi + 1]]
        stat = a + (p - lo) * (b - a)
        low, high = np.percentile(stat, [tail, 100 - tail])
        out.append((float(low), float(high)))
    return out


def _pairs(a: Sequence[float] | np.ndarray, b: Sequence[float] | np.ndarray
           ) -> tuple[np.ndarray, np.ndarray]:
    x = np.asarray([np.nan if v is None else v for v in a], dtype=float)
    y = np.asarray([np.nan if v is None else v for v in b], dtype=float)
    if x.shape != y.shape:
        raise ValueError(f"paired samples differ in length: {x.size} and {y.size}")
    ok = np.isfinite(x) & np.isfinite(y)
    return x[ok], y[ok]


def mcnemar_exact(a: Sequence[bool] | np.ndarray, b: Sequence[bool] | np.ndarray,
                  level: float = LEVEL) -> TestResult:
    """McNemar's exact test of two success indicators on the same trials.

    Only the discordant pairs carry information: under the null hypothesis each is
    equally likely to favour ``a`` or ``b``, so the p-value is that of a two-sided
    binomial test of ``n01`` successes in ``n01 + n10`` draws at 1/2.

    Args:
        a: Success of ``a`` per trial.
        b: Success of ``b`` on the same trials.
        level: Confidence level.

    Returns:
        The test; ``difference`` is ``rate(a) - rate(b)`` with Newcombe's paired
        interval (:func:`benchmarks.study.exact.newcombe_paired`), which keeps its width
        when one controller succeeds on every trial (20 of 20 against 0 of 20:
        ``[+0.77, +1.0]``, not a bootstrap's ``[+1.0, +1.0]``).
    """
    x = np.asarray(a, dtype=bool)
    y = np.asarray(b, dtype=bool)
    if x.shape != y.shape:
        raise ValueError(f"paired samples differ in length: {x.size} and {y.size}")
    only_a = int(np.sum(x & ~y))
    only_b = int(np.sum(~x & y))
    both = int(np.sum(x & y))
    m = only_a + only_b
    p = _binomial_two_sided_half(min(only_a, only_b), m)
    low, high = exact.newcombe_paired(both, only_a, only_b, int(x.size) - both - m, level)
    diff = (only_a - only_b) / x.size if x.size else float("nan")
    return TestResult("mcnemar-exact", int(x.size), float(only_a), p, diff, low, high,
                      (only_a, only_b), int(np.sign(only_a - only_b)))


def median_difference(a: Sequence[float] | np.ndarray, b: Sequence[float] | np.ndarray,
                      level: float = LEVEL) -> tuple[float, float, float]:
    """Median of the paired differences ``a - b`` with its distribution-free
    order-statistic interval (:func:`benchmarks.study.exact.quantile_interval`, the
    interval of the sign test).

    Returns:
        ``(median, low, high)`` (``nan`` without a complete pair; an end outside the
        sample, below 6 pairs at 95 %, is infinite).
    """
    x, y = _pairs(a, b)
    d = x - y
    if d.size == 0:
        return float("nan"), float("nan"), float("nan")
    low, high = exact.quantile_interval(d, 0.5, level)
    return float(np.median(d)), low, high


def _binomial_two_sided_half(k: int, m: int) -> float:
    """Two-sided p-value of ``k <= m / 2`` successes in ``m`` fair draws, in exact
    integer arithmetic: ``min(1, 2 * sum_{i <= k} C(m, i) / 2^m)``."""
    if m == 0:
        return 1.0
    term, total = 1, 1
    for i in range(1, k + 1):
        term = term * (m - i + 1) // i
        total += term
    return min(1.0, float(Fraction(2 * total, 2 ** m)))


def _average_ranks(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ranks (1-based, ties get their average rank) and the size of every tie group."""
    order = np.argsort(a, kind="mergesort")
    s = a[order]
    starts = np.flatnonzero(np.r_[True, s[1:] != s[:-1]])
    sizes = np.diff(np.r_[starts, s.size])
    avg = starts + (sizes + 1) / 2.0
    ranks = np.empty(a.size)
    ranks[order] = np.repeat(avg, sizes)
    return ranks, sizes


def _signed_rank_exact(ranks: np.ndarray, r_plus: float) -> float:
    """Two-sided p-value of the positive rank sum under random signs, by enumerating the
    distribution (integer ranks: subset-sum counts; tied half ranks: all sign vectors)."""
    n = ranks.size
    if np.all(ranks == np.round(ranks)):
        total = int(ranks.sum())
        counts = np.zeros(total + 1)
        counts[0] = 1.0
        for r in ranks.astype(int):
            counts[r:] = counts[r:] + counts[:total + 1 - r].copy()
        prob = counts / counts.sum()
        le = float(prob[:int(np.ceil(r_plus)) + 1].sum())
        ge = float(prob[int(np.floor(r_plus)):].sum())
    else:
        sums = np.array([float(np.dot(ranks, signs))
                         for signs in itertools.product((0, 1), repeat=n)])
        le = float(np.mean(sums <= r_plus + 1e-9))
        ge = float(np.mean(sums >= r_plus - 1e-9))
    return min(1.0, 2.0 * min(le, ge))


def wilcoxon_signed_rank(a: Sequence[float] | np.ndarray, b: Sequence[float] | np.ndarray,
                         level: float = LEVEL) -> TestResult:
    """Wilcoxon's signed-rank test of paired values, two-sided, with the median paired
    difference and its interval.

    Zero differences are dropped (Wilcoxon's method), tied ranks averaged. The p-value
    is exact for small samples (at most 50 pairs without ties or zeros; at most 13
    pairs otherwise) and from the normal approximation with the tie
    correction and no continuity correction beyond: the choices of
    ``scipy.stats.wilcoxon`` with its defaults, which the tests compare against (the
    module does its own arithmetic to keep ``scipy.stats``, 1-3 s to import, out of
    ``hexapod-bench compare``). Pairs with a missing value are left out; identical
    samples give ``p = 1``.

    Returns:
        The test; ``statistic`` is the smaller of the positive and negative rank sums.
    """
    x, y = _pairs(a, b)
    med, low, high = median_difference(x, y, level)
    d = x - y
    nz = d[d != 0]
    count = nz.size
    if count == 0:
        return TestResult("wilcoxon", int(d.size), 0.0, 1.0, med, low, high)
    ranks, ties = _average_ranks(np.abs(nz))
    r_plus = float(ranks[nz > 0].sum())
    r_minus = float(ranks[nz < 0].sum())
    has_ties = bool(np.any(ties > 1))
    small = d.size <= 50 and not has_ties and count == d.size
    if small or d.size <= 13:  # exact (enumeration of the sign vectors with ties, zeros)
        p = _signed_rank_exact(ranks, r_plus)
    else:
        mean = count * (count + 1) / 4.0
        var = (count * (count + 1) * (2 * count + 1) - np.sum(ties ** 3 - ties) / 2) / 24.0
        z = (r_plus - mean) / math.sqrt(var) if var > 0 else 0.0
        p = min(1.0, math.erfc(abs(z) / math.sqrt(2)))
    return TestResult("wilcoxon", int(d.size), min(r_plus, r_minus), p, med, low, high,
                      (int(np.sum(nz > 0)), int(np.sum(nz < 0))), int(np.sign(r_plus - r_minus)))


def holm(p_values: Sequence[float]) -> list[float]:
    """Holm's step-down adjusted p-values (family-wise error), in the input order.

    The ``i``-th smallest of ``m`` p-values is multiplied by ``m - i + 1`` (``i`` from
    1), the running maximum taken and clipped at 1. ``nan`` entries stay ``nan`` and do
    not count in ``m``.

    Raises:
        ValueError: A p-value (other than ``nan``) outside [0, 1].
    """
    p = np.asarray(p_values, dtype=float)
    bad = np.flatnonzero((p < 0) | (p > 1))
    if bad.size:
        i = int(bad[0])
        raise ValueError(f"p-value {p.flat[i]} at index {i}: must lie in [0, 1]")
    out = np.full(p.shape, np.nan)
    ok = np.flatnonzero(np.isfinite(p))
    m = ok.size
    if m == 0:
        return out.tolist()
    order = ok[np.argsort(p[ok], kind="stable")]
    running = 0.0
    for i, j in enumerate(order):
        running = max(running, min(1.0, (m - i) * float(p[j])))
        out[j] = running
    return out.tolist()


def format_rate(k: int, n: int, level: float = LEVEL) -> str:
    """``94.0 % [87.4, 97.8]``: a rate in percent with its Wilson interval."""
    if n == 0:
        return "-"
    low, high = wilson_interval(k, n, level)
    return f"{100 * k / n:.1f} % [{percent_bound(low)}, {percent_bound(high)}]"


def percent_bound(x: float) -> str:
    """A bound in percent with one decimal, or as many (up to 3) as keep a bound that is
    not 0 or 100 % from printing as one (10000 of 10000: ``[99.96, 100.0]``)."""
    for digits in (1, 2, 3):
        text = f"{100 * x:.{digits}f}"
        if (0 < x < 1) and float(text) in (0.0, 100.0):
            continue
        return text
    return f"{100 * x:.3f}"
