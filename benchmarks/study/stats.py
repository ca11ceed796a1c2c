"""Statistics of a benchmark: intervals for rates and quantiles, paired tests, Holm.

Every controller of a run meets the same trials (same worlds, same draws), so two
controllers are compared on paired data:

- rates (convergence): Wilson score interval (no continuity correction) at 95 %;
- medians and 95th percentiles: percentile bootstrap, seeded (:data:`SEED`,
  :data:`RESAMPLES` resamples unless told otherwise);
- convergence of two controllers on the same trials: McNemar's exact test, the
  two-sided binomial test on the discordant pairs;
- paired continuous metrics (final error, steps): Wilcoxon's signed-rank test
  (``scipy.stats.wilcoxon``), and the median of the paired differences with a seeded
  percentile-bootstrap interval;
- several comparisons at once: Holm's step-down correction.

References: E. B. Wilson, "Probable inference, the law of succession, and statistical
inference", J. Am. Stat. Assoc. 22, 1927; Q. McNemar, Psychometrika 12, 1947;
F. Wilcoxon, Biometrics Bulletin 1, 1945; S. Holm, Scand. J. Statistics 6, 1979;
B. Efron and R. Tibshirani, "An Introduction to the Bootstrap", 1993.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

#: Confidence level of every interval.
LEVEL = 0.95
#: Seed of every bootstrap (recorded in the report).
SEED = 0
#: Bootstrap resamples (recorded in the report).
RESAMPLES = 2000
#: Resampled values held in memory at once (a chunk of resamples).
_CHUNK_VALUES = 2_000_000


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
        low: Lower end of the difference's bootstrap interval.
        high: Upper end of the difference's bootstrap interval.
        discordant: McNemar: (only ``a`` succeeded, only ``b`` succeeded).
    """

    test: str
    n: int
    statistic: float
    p_value: float
    difference: float
    low: float
    high: float
    discordant: tuple[int, int] | None = None


def wilson_interval(k: int, n: int, level: float = LEVEL) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion ``k / n`` (no continuity correction).

    Args:
        k: Successes.
        n: Trials (0 gives ``(nan, nan)``).
        level: Confidence level.

    Returns:
        ``(low, high)`` as fractions in [0, 1].

    Raises:
        ValueError: ``k`` outside ``[0, n]``.
    """
    if not 0 <= k <= n:
        raise ValueError(f"successes k={k} must lie in [0, n={n}]")
    if n == 0:
        return float("nan"), float("nan")
    from scipy.stats import norm

    z = float(norm.ppf(0.5 + level / 2))
    p = k / n
    denom = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    low = 0.0 if k == 0 else max(0.0, centre - half)
    high = 1.0 if k == n else min(1.0, centre + half)
    return float(low), float(high)


def _finite(values: Sequence[float] | np.ndarray) -> np.ndarray:
    arr = np.asarray([np.nan if v is None else v for v in values], dtype=float)
    return arr[np.isfinite(arr)]


def bootstrap_quantiles(values: Sequence[float] | np.ndarray, quantiles: Sequence[float],
                        resamples: int = RESAMPLES, seed: int = SEED, level: float = LEVEL
                        ) -> list[tuple[float, float]]:
    """Percentile-bootstrap intervals of quantiles of a sample (one resampling for all).

    Each resample draws ``n`` values with replacement; its quantile is that of
    ``numpy.quantile`` (linear interpolation, as the report's medians and p95). The
    interval is the ``(1 - level) / 2`` and ``(1 + level) / 2`` quantiles of the
    resampled statistic. Missing and non-finite values are left out.

    Args:
        values: The sample.
        quantiles: Quantiles in [0, 1] (0.5: median, 0.95: p95).
        resamples: Number of resamples.
        seed: Seed of ``numpy.random.default_rng``.
        level: Confidence level.

    Returns:
        One ``(low, high)`` per quantile (``nan`` for an empty sample).
    """
    x = np.sort(_finite(values))
    n = x.size
    if n == 0:
        return [(float("nan"), float("nan")) for _ in quantiles]
    if n == 1:
        return [(float(x[0]), float(x[0])) for _ in quantiles]
    rng = np.random.default_rng(seed)
    pos = [q * (n - 1) for q in quantiles]
    kth = sorted({min(int(np.floor(p)) + d, n - 1) for p in pos for d in (0, 1)})
    stats = np.empty((resamples, len(quantiles)))
    chunk = max(1, _CHUNK_VALUES // n)
    for start in range(0, resamples, chunk):
        m = min(chunk, resamples - start)
        idx = rng.integers(0, n, size=(m, n))
        # x is sorted, so the order statistics of a resample are x at the order
        # statistics of its indices: a partition instead of a sort
        part = np.partition(idx, kth, axis=1)
        for j, p in enumerate(pos):
            lo = int(np.floor(p))
            hi = min(lo + 1, n - 1)
            frac = p - lo
            a, b = x[part[:, lo]], x[part[:, hi]]
            stats[start:start + m, j] = a + frac * (b - a)
    tail = 100 * (1 - level) / 2
    out = []
    for j in range(len(quantiles)):
        low, high = np.percentile(stats[:, j], [tail, 100 - tail])
        out.append((float(low), float(high)))
    return out


def bootstrap_mean(values: Sequence[float] | np.ndarray, resamples: int = RESAMPLES,
                   seed: int = SEED, level: float = LEVEL) -> tuple[float, float]:
    """Percentile-bootstrap interval of the mean of a sample (non-finite values left out)."""
    x = _finite(values)
    n = x.size
    if n == 0:
        return float("nan"), float("nan")
    rng = np.random.default_rng(seed)
    means = np.empty(resamples)
    chunk = max(1, _CHUNK_VALUES // n)
    for start in range(0, resamples, chunk):
        m = min(chunk, resamples - start)
        means[start:start + m] = x[rng.integers(0, n, size=(m, n))].mean(axis=1)
    tail = 100 * (1 - level) / 2
    low, high = np.percentile(means, [tail, 100 - tail])
    return float(low), float(high)


def _pairs(a: Sequence[float] | np.ndarray, b: Sequence[float] | np.ndarray
           ) -> tuple[np.ndarray, np.ndarray]:
    x = np.asarray([np.nan if v is None else v for v in a], dtype=float)
    y = np.asarray([np.nan if v is None else v for v in b], dtype=float)
    if x.shape != y.shape:
        raise ValueError(f"paired samples differ in length: {x.size} and {y.size}")
    ok = np.isfinite(x) & np.isfinite(y)
    return x[ok], y[ok]


def mcnemar_exact(a: Sequence[bool] | np.ndarray, b: Sequence[bool] | np.ndarray,
                  resamples: int = RESAMPLES, seed: int = SEED, level: float = LEVEL
                  ) -> TestResult:
    """McNemar's exact test of two success indicators on the same trials.

    Only the discordant pairs carry information: under the null hypothesis each is
    equally likely to favour ``a`` or ``b``, so the p-value is that of a two-sided
    binomial test of ``n01`` successes in ``n01 + n10`` draws at 1/2.

    Args:
        a: Success of ``a`` per trial.
        b: Success of ``b`` on the same trials.
        resamples: Bootstrap resamples of the rate difference's interval.
        seed: Bootstrap seed.
        level: Confidence level.

    Returns:
        The test; ``difference`` is ``rate(a) - rate(b)`` with a bootstrap interval of
        the mean paired difference.
    """
    x = np.asarray(a, dtype=bool)
    y = np.asarray(b, dtype=bool)
    if x.shape != y.shape:
        raise ValueError(f"paired samples differ in length: {x.size} and {y.size}")
    only_a = int(np.sum(x & ~y))
    only_b = int(np.sum(~x & y))
    m = only_a + only_b
    if m == 0:
        p = 1.0
    else:
        from scipy.stats import binom

        p = min(1.0, 2.0 * float(binom.cdf(min(only_a, only_b), m, 0.5)))
    d = x.astype(float) - y.astype(float)
    low, high = (0.0, 0.0) if m == 0 else bootstrap_mean(d, resamples, seed, level)
    return TestResult("mcnemar-exact", int(x.size), float(only_a), p,
                      float(d.mean()) if d.size else float("nan"), low, high,
                      (only_a, only_b))


def median_difference(a: Sequence[float] | np.ndarray, b: Sequence[float] | np.ndarray,
                      resamples: int = RESAMPLES, seed: int = SEED, level: float = LEVEL
                      ) -> tuple[float, float, float]:
    """Median of the paired differences ``a - b`` with its bootstrap interval.

    Returns:
        ``(median, low, high)`` (``nan`` without a complete pair).
    """
    x, y = _pairs(a, b)
    d = x - y
    if d.size == 0:
        return float("nan"), float("nan"), float("nan")
    (low, high), = bootstrap_quantiles(d, [0.5], resamples, seed, level)
    return float(np.median(d)), low, high


def wilcoxon_signed_rank(a: Sequence[float] | np.ndarray, b: Sequence[float] | np.ndarray,
                         resamples: int = RESAMPLES, seed: int = SEED, level: float = LEVEL
                         ) -> TestResult:
    """Wilcoxon's signed-rank test of paired values, two-sided (``scipy.stats.wilcoxon``,
    zero differences dropped), with the median paired difference and its interval.

    Pairs with a missing value are left out. Identical samples (every difference zero)
    give ``p = 1``.
    """
    x, y = _pairs(a, b)
    med, low, high = median_difference(x, y, resamples, seed, level)
    d = x - y
    if not np.any(d != 0):
        return TestResult("wilcoxon", int(d.size), 0.0, 1.0, med, low, high)
    from scipy.stats import wilcoxon

    res = wilcoxon(x, y)
    return TestResult("wilcoxon", int(d.size), float(res.statistic), float(res.pvalue),
                      med, low, high)


def holm(p_values: Sequence[float]) -> list[float]:
    """Holm's step-down adjusted p-values (family-wise error), in the input order.

    The ``i``-th smallest of ``m`` p-values is multiplied by ``m - i + 1`` (``i`` from
    1), the running maximum taken and clipped at 1. ``nan`` entries stay ``nan`` and do
    not count in ``m``.
    """
    p = np.asarray(p_values, dtype=float)
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
    return f"{100 * k / n:.1f} % [{100 * low:.1f}, {100 * high:.1f}]"
