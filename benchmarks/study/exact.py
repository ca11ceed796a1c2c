"""Intervals and tests with exact or near-exact coverage at the sample sizes of a benchmark.

- quantiles (medians, 95th percentiles): the distribution-free order-statistic interval
  (the ranks from the binomial distribution of the number of values below the
  quantile; as ``scipy.stats.quantile_test(...).confidence_interval()``), which also
  holds for values censored at a cap (a step count of a trial that did not converge is
  only known to exceed the run's length: it sorts last);
- the difference of two paired success rates: Newcombe's hybrid score interval
  (method 10 of R. G. Newcombe, "Improved confidence intervals for the difference
  between binomial proportions based on paired data", Statistics in Medicine 17,
  2635-2650, 1998): Wilson score intervals of both rates, combined with the
  correlation of the pairs;
- the sign test (exact binomial at 1/2) and the two one-sided tests of equivalence
  (TOST) of paired values or of a paired rate difference within a margin.

The module does its own binomial arithmetic (integers for the sign test, log-space
floats for the order-statistic ranks) to keep ``scipy.stats`` out of
``hexapod-bench compare``; the tests check it against ``scipy.stats``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from fractions import Fraction
from statistics import NormalDist

import numpy as np

#: Confidence level of every interval (as :data:`benchmarks.study.stats.LEVEL`).
LEVEL = 0.95


def _binomial_cdf(n: int, p: float) -> np.ndarray:
    """``P(X <= k)`` for ``k = 0..n``, ``X ~ Binomial(n, p)`` (log-space pmf, summed)."""
    k = np.arange(n + 1)
    log_fact = np.concatenate([[0.0], np.cumsum(np.log(np.arange(1, n + 1)))])
    log_pmf = (log_fact[n] - log_fact[k] - log_fact[n - k] + k * math.log(p)
               + (n - k) * math.log1p(-p))
    return np.cumsum(np.exp(log_pmf))


def order_statistic_ranks(n: int, q: float, level: float = LEVEL) -> tuple[int | None, int | None]:
    """0-based indices into the sorted sample of the ends of the distribution-free
    interval of the ``q``-quantile (None: the end lies outside the sample, the interval
    is open on that side).

    With ``B ~ Binomial(n, q)`` the number of values below the quantile, the low index
    is ``ppf(alpha / 2) - 1`` and the high index ``isf(alpha / 2)`` (``alpha = 1 -
    level``): the convention of ``scipy.stats.quantile_test``. The coverage is at least
    ``level`` for any continuous distribution.

    Raises:
        ValueError: ``q`` outside (0, 1) or ``level`` outside (0, 1).
    """
    if not 0 < q < 1:
        raise ValueError(f"quantile q={q} must lie in (0, 1)")
    if not 0 < level < 1:
        raise ValueError(f"confidence level {level} must lie in (0, 1)")
    if n == 0:
        return None, None
    tail = (1 - level) / 2
    cdf = _binomial_cdf(n, q)
    # ppf: the smallest k with cdf(k) >= tail; isf: the smallest k with sf(k) <= tail
    low = int(np.searchsorted(cdf, tail * (1 - 1e-12), side="left")) - 1
    high = int(np.searchsorted(cdf, (1 - tail) * (1 - 1e-12), side="left"))
    return (low if low >= 0 else None), (high if high < n else None)


def quantile_interval(values: Sequence[float] | np.ndarray, q: float, level: float = LEVEL
                      ) -> tuple[float, float]:
    """Distribution-free interval of the ``q``-quantile from the order statistics.

    Missing values (None, NaN) are left out; ``+inf`` stands for a value censored above
    (known only to exceed a cap) and sorts last, so an end that lands on it is ``inf``.

    Returns:
        ``(low, high)``; an end outside the sample is ``-inf`` (low) or ``inf`` (high);
        ``(nan, nan)`` for an empty sample.
    """
    x = np.asarray([np.nan if v is None else v for v in values], dtype=float)
    x = np.sort(x[~np.isnan(x)])
    if x.size == 0:
        return float("nan"), float("nan")
    lo, hi = order_statistic_ranks(int(x.size), q, level)
    return (float(x[lo]) if lo is not None else -math.inf,
            float(x[hi]) if hi is not None else math.inf)


def censored_quantile(values: Sequence[float] | np.ndarray, q: float) -> float:
    """``numpy.quantile`` (linear interpolation) of a sample whose censored values are
    ``+inf`` (or, for paired differences, ``-inf`` too): ``inf`` (``-inf``) when an order
    statistic it needs is censored above (below): the quantile is then only known to lie
    beyond the finite values; ``nan`` when it needs one of each (unknown) and for an empty
    sample. (``numpy.quantile`` gives ``nan`` between 432 and ``inf``, even for an odd
    sample whose median is the finite 432.)"""
    x = np.asarray([np.nan if v is None else v for v in values], dtype=float)
    x = np.sort(x[~np.isnan(x)])
    if x.size == 0:
        return float("nan")
    pos = q * (x.size - 1)
    lo = math.floor(pos)
    hi = min(lo + 1, x.size - 1)
    if pos == lo or hi == lo:  # an order statistic itself (another one is not used)
        return float(x[lo])
    a, b = float(x[lo]), float(x[hi])
    if a == -math.inf or b == math.inf:
        return math.nan if a == -math.inf and b == math.inf else (a if a == -math.inf else b)
    return a + (pos - lo) * (b - a)


def _wilson(k: int, n: int, z: float) -> tuple[float, float]:
    p = k / n
    denom = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return (0.0 if k == 0 else max(0.0, centre - half),
            1.0 if k == n else min(1.0, centre + half))


def _newcombe_z(both: int, only_a: int, only_b: int, neither: int, z: float
                ) -> tuple[float, float]:
    n = both + only_a + only_b + neither
    p1, p2 = (both + only_a) / n, (both + only_b) / n
    l1, u1 = _wilson(both + only_a, n, z)
    l2, u2 = _wilson(both + only_b, n, z)
    margins = ((both + only_a) * (only_b + neither) * (both + only_b) * (only_a + neither))
    phi = 0.0
    if margins > 0:
        cross = both * neither - only_a * only_b
        if cross > n / 2:
            phi = (cross - n / 2) / math.sqrt(margins)
        elif cross < 0:
            phi = cross / math.sqrt(margins)
    d = p1 - p2
    low = d - math.sqrt(max(0.0, (p1 - l1) ** 2 - 2 * phi * (p1 - l1) * (u2 - p2)
                            + (u2 - p2) ** 2))
    high = d + math.sqrt(max(0.0, (p2 - l2) ** 2 - 2 * phi * (p2 - l2) * (u1 - p1)
                             + (u1 - p1) ** 2))
    return max(-1.0, low), min(1.0, high)


def newcombe_paired(both: int, only_a: int, only_b: int, neither: int,
                    level: float = LEVEL) -> tuple[float, float]:
    """Newcombe's interval (1998, method 10) of ``rate(a) - rate(b)`` on paired trials.

    ``rate(a) = (both + only_a) / n``; the Wilson score intervals ``(l1, u1)`` and
    ``(l2, u2)`` of the two rates are combined as
    ``d - sqrt((p1 - l1)^2 - 2 phi (p1 - l1)(u2 - p2) + (u2 - p2)^2)`` (low) and
    ``d + sqrt((p2 - l2)^2 - 2 phi (p2 - l2)(u1 - p1) + (u1 - p1)^2)`` (high), with
    ``phi`` the correlation of the 2x2 table, ``(both * neither - only_a * only_b)``
    over the root of the product of the margins, continuity-corrected by ``n / 2``
    when positive and 0 when a margin is empty. Unlike a bootstrap it does not collapse
    to a point when one controller converges on every trial.

    Args:
        both: Trials where both succeeded.
        only_a: Trials where only ``a`` succeeded.
        only_b: Trials where only ``b`` succeeded.
        neither: Trials where neither did.
        level: Confidence level.

    Returns:
        ``(low, high)`` as differences of fractions, in [-1, 1] (``nan`` for no trial).

    Raises:
        ValueError: A negative count.
    """
    if min(both, only_a, only_b, neither) < 0:
        raise ValueError(f"counts must be >= 0: both={both}, only_a={only_a}, "
                         f"only_b={only_b}, neither={neither}")
    if both + only_a + only_b + neither == 0:
        return float("nan"), float("nan")
    return _newcombe_z(both, only_a, only_b, neither, NormalDist().inv_cdf(0.5 + level / 2))


def binomial_upper_tail_half(k: int, m: int) -> float:
    """``P(X >= k)`` for ``X ~ Binomial(m, 1/2)``, in exact integer arithmetic."""
    if k <= 0:
        return 1.0
    if k > m:
        return 0.0
    term, total = 1, 1  # C(m, m) = 1, then C(m, m - 1)...: sum_{i >= k} C(m, i)
    for i in range(m - 1, k - 1, -1):
        term = term * (i + 1) // (m - i)
        total += term
    return float(Fraction(total, 2 ** m))


def sign_test(d: Sequence[float] | np.ndarray) -> tuple[int, int, float]:
    """Two-sided exact sign test of paired differences (zeros and NaN dropped; ``+-inf``
    allowed: a difference whose sign is known but not its size).

    Returns:
        ``(positive, negative, p)``: the counts and ``min(1, 2 P(X >= max))`` with
        ``X ~ Binomial(positive + negative, 1/2)``.
    """
    x = np.asarray(d, dtype=float)
    x = x[~np.isnan(x)]
    pos, neg = int(np.sum(x > 0)), int(np.sum(x < 0))
    return pos, neg, min(1.0, 2 * binomial_upper_tail_half(max(pos, neg), pos + neg))


def tost_paired(d: Sequence[float] | np.ndarray, margin: float) -> float:
    """Two one-sided sign tests of equivalence of paired differences within ``+-margin``.

    H0: the median difference is ``<= -margin`` or ``>= margin``; each side is an exact
    one-sided sign test on the differences shifted by the margin (those equal to the
    shifted value dropped); the p-value is the larger of the two. A small p-value says
    the median paired difference lies within the margin.

    Raises:
        ValueError: ``margin`` not positive and finite.
    """
    if not (np.isfinite(margin) and margin > 0):
        raise ValueError(f"equivalence margin {margin} must be positive and finite")
    x = np.asarray(d, dtype=float)
    x = x[~np.isnan(x)]
    above, below = int(np.sum(x > -margin)), int(np.sum(x < -margin))
    p_low = binomial_upper_tail_half(above, above + below)
    above, below = int(np.sum(x > margin)), int(np.sum(x < margin))
    p_high = binomial_upper_tail_half(below, above + below)
    return max(p_low, p_high)


def tost_rate(both: int, only_a: int, only_b: int, neither: int, margin: float) -> float:
    """TOST p-value of a paired rate difference within ``+-margin`` (a fraction): the
    smallest ``alpha`` whose ``1 - 2 alpha`` Newcombe interval lies inside
    ``(-margin, margin)`` (the interval-inclusion form of the two one-sided tests),
    found by bisection on ``log10(alpha)``; 1 when even the point estimate is outside.

    Raises:
        ValueError: ``margin`` outside (0, 1].
    """
    if not 0 < margin <= 1:
        raise ValueError(f"equivalence margin {margin} of a rate difference must lie in "
                         "(0, 1]")
    n = both + only_a + only_b + neither
    if n == 0 or abs(only_a - only_b) / n >= margin:
        return 1.0

    def inside(log_alpha: float) -> bool:
        z = -NormalDist().inv_cdf(10.0 ** log_alpha)
        low, high = _newcombe_z(both, only_a, only_b, neither, z)
        return -margin < low and high < margin

    lo, hi = -300.0, math.log10(0.5)
    if inside(lo):
        return 10.0 ** lo
    for _ in range(60):
        mid = (lo + hi) / 2
        if inside(mid):
            hi = mid
        else:
            lo = mid
    return min(1.0, 10.0 ** hi)


def format_p(p: float) -> str:
    """A p-value for people: three significant digits, ``< 1e-16`` below 1e-16 (where
    double precision and the tests' approximations stop meaning anything), ``-`` for
    none."""
    if p is None or not np.isfinite(p):
        return "-"
    if p < 1e-16:
        return "< 1e-16"
    return f"{p:.3g}"
