"""Order-statistic intervals, Newcombe's paired interval, the sign test and TOST, against
``scipy.stats`` and cases worked by hand or published."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.stats as sps

from benchmarks.study import exact


@pytest.mark.parametrize("q", [0.5, 0.95, 0.1])
@pytest.mark.parametrize("level", [0.95, 0.9])
def test_quantile_interval_matches_scipy_quantile_test(q: float, level: float) -> None:
    rng = np.random.default_rng(1)
    for n in [*range(1, 60), 100, 501, 2000, 20000]:
        x = rng.lognormal(size=n)
        ref = sps.quantile_test(x, p=q).confidence_interval(level)
        low, high = exact.quantile_interval(x, q, level)
        # scipy gives nan for an end outside the sample; ours says -inf / inf
        assert (low if np.isfinite(low) else np.nan) == pytest.approx(ref.low, nan_ok=True)
        assert (high if np.isfinite(high) else np.nan) == pytest.approx(ref.high, nan_ok=True)


def test_median_interval_of_ten_by_hand() -> None:
    """n = 10: P(B <= 1) = 11/1024 < 0.025 <= P(B <= 2) = 56/1024, so the interval runs
    from the 2nd to the 9th smallest value (coverage 1 - 2 * 11/1024 = 0.9785)."""
    x = np.array([7.0, 3.0, 9.0, 1.0, 4.0, 10.0, 2.0, 8.0, 6.0, 5.0])
    assert exact.quantile_interval(x, 0.5) == (2.0, 9.0)
    assert exact.order_statistic_ranks(10, 0.5) == (1, 8)
    # five values: even the extremes cover only 1 - 2/32 = 0.9375 < 0.95
    assert exact.quantile_interval(x[:5], 0.5) == (-math.inf, math.inf)


def test_censored_values_sort_last_and_reach_the_cap() -> None:
    steps = np.array([100, 120, 130, 150, 160, 170, 180, 190, np.inf, np.inf])
    low, high = exact.quantile_interval(steps, 0.5)
    assert low == 120.0
    assert high == math.inf  # the 9th smallest is censored: "> cap"
    assert exact.censored_quantile(steps, 0.5) == pytest.approx(165.0)
    assert exact.censored_quantile(np.r_[steps[:4], [np.inf] * 6], 0.5) == math.inf
    assert np.isnan(exact.censored_quantile([None, float("nan")], 0.5))
    # an odd sample whose median is the last uncensored value: that value (numpy.quantile's
    # on the values with the censored ones at any larger number), not 0 x inf
    for tail in ([np.inf], [np.inf, np.inf]):
        x = np.r_[[3.0, 1.0, 2.0][:len(tail) + 1], tail]
        finite = np.where(np.isinf(x), 1e9, x)
        assert exact.censored_quantile(x, 0.5) == np.quantile(finite, 0.5)
    assert exact.censored_quantile([1.0, 2.0, np.inf, np.inf], 0.5) == math.inf  # between
    rng = np.random.default_rng(0)  # uncensored samples: numpy's quantile (its own lerp)
    for n in (1, 2, 5, 10, 11):
        x = rng.uniform(0, 100, n)
        for q in (0.0, 0.25, 0.5, 0.95, 1.0):
            assert exact.censored_quantile(x, q) == pytest.approx(np.quantile(x, q),
                                                                  rel=1e-14)


def test_newcombe_published_example() -> None:
    """Fagerland, Lydersen and Laake, "Statistical Analysis of Contingency Tables" (2017),
    chapter 8, complete response before and after consolidation therapy (Cavo et al.
    2012): the table [[59, 6], [16, 80]], the Newcombe square-and-add interval
    -0.0621 (95 % CI -0.1186 to -0.0046)."""
    low, high = exact.newcombe_paired(59, 6, 16, 80)
    assert round(low, 4) == -0.1186
    assert round(high, 4) == -0.0046
    # the difference of the rates goes the other way when a and b swap
    low2, high2 = exact.newcombe_paired(59, 16, 6, 80)
    assert (low2, high2) == pytest.approx((-high, -low))


def _newcombe_method_10(a: int, b: int, c: int, d: int, level: float = 0.95
                        ) -> tuple[float, float, float]:
    """Newcombe (1998, Statistics in Medicine 17:2635) method 10, from the paper's
    equations and scipy's Wilson score limits (not from :mod:`benchmarks.study.exact`).

    The paired table has ``a`` (both succeed), ``b`` (only the first), ``c`` (only the
    second), ``d`` (neither), ``n = a + b + c + d`` and the margins ``e = a + b``,
    ``f = c + d``, ``g = a + c``, ``h = b + d``. With ``A = e / n``, ``B = g / n``,
    ``theta = A - B = (b - c) / n`` and ``(l2, u2)``, ``(l3, u3)`` the Wilson limits of
    ``A`` and ``B``::

        L = theta - sqrt((A - l2)^2 - 2 phi (A - l2)(u3 - B) + (u3 - B)^2)
        U = theta + sqrt((u2 - A)^2 - 2 phi (u2 - A)(B - l3) + (B - l3)^2)

    where ``phi`` is the correlation of the table, continuity-corrected when positive::

        phi = max(ad - bc - n/2, 0) / sqrt(efgh)   if ad > bc
        phi = (ad - bc) / sqrt(efgh)               if ad <= bc
        phi = 0                                     if efgh = 0

    Returns:
        ``(L, U, phi)``.
    """
    n = a + b + c + d
    big_a, big_b = (a + b) / n, (a + c) / n
    first = sps.binomtest(a + b, n).proportion_ci(confidence_level=level, method="wilson")
    second = sps.binomtest(a + c, n).proportion_ci(confidence_level=level, method="wilson")
    l2, u2, l3, u3 = first.low, first.high, second.low, second.high
    efgh = (a + b) * (c + d) * (a + c) * (b + d)
    ad_bc = a * d - b * c
    if efgh == 0:
        phi = 0.0
    elif ad_bc > 0:
        phi = max(ad_bc - n / 2, 0.0) / math.sqrt(efgh)
    else:
        phi = ad_bc / math.sqrt(efgh)
    theta = (b - c) / n
    low = theta - math.sqrt((big_a - l2) ** 2 - 2 * phi * (big_a - l2) * (u3 - big_b)
                            + (u3 - big_b) ** 2)
    high = theta + math.sqrt((u2 - big_a) ** 2 - 2 * phi * (u2 - big_a) * (big_b - l3)
                             + (big_b - l3) ** 2)
    return low, high, phi


@pytest.mark.parametrize(("table", "ad_bc", "phi", "interval"), [
    # ad < bc, phi = -60 / sqrt(12 * 8 * 10 * 10) = -0.6124 (phi = 0: -0.1930, 0.3704)
    ((3, 9, 7, 1), -60, -0.6124, (-0.2719, 0.4430)),
    # ad < bc, phi = -24 / sqrt(48 * 2 * 38 * 12) = -0.1147 (phi = 0: 0.0645, 0.3372)
    ((36, 12, 2, 0), -24, -0.1147, (0.0569, 0.3404)),
    # n/2 = 10 < ad - bc = 17 <= n: phi = (17 - 10) / sqrt(9 * 11 * 7 * 13) = 0.0737
    # (phi = 0: -0.1897, 0.3678)
    ((4, 5, 3, 8), 17, 0.0737, (-0.1789, 0.3580)),
    # 0 < ad - bc = 1 <= n/2 = 8: the corrected correlation is 0
    ((4, 5, 3, 4), 1, 0.0, (-0.2013, 0.4171)),
])
def test_newcombe_matches_method_10_worked_from_the_paper(
        table: tuple[int, int, int, int], ad_bc: int, phi: float,
        interval: tuple[float, float]) -> None:
    """The branches of the correlation the published example (ad - bc > n) does not
    reach: negative correlation, and a positive one corrected by n/2 to a smaller
    value or to 0. The reference is :func:`_newcombe_method_10` (the paper's equations
    on scipy's Wilson limits); each case pins its branch (ad - bc), its phi and its
    interval to 4 decimals. Where phi is not 0, the comment gives the interval with
    phi = 0, which differs in the second or third decimal."""
    a, b, c, d = table
    assert a * d - b * c == ad_bc
    low_ref, high_ref, phi_ref = _newcombe_method_10(a, b, c, d)
    assert round(phi_ref, 4) == phi
    assert (round(low_ref, 4), round(high_ref, 4)) == interval
    low, high = exact.newcombe_paired(a, b, c, d)
    assert low == pytest.approx(low_ref, abs=1e-12)
    assert high == pytest.approx(high_ref, abs=1e-12)


def test_newcombe_does_not_collapse_at_all_or_nothing() -> None:
    """20 of 20 against 0 of 20 (the bootstrap said [+100, +100] points): the interval
    keeps the uncertainty of 20 trials and still contains the observed +1."""
    low, high = exact.newcombe_paired(0, 20, 0, 0)
    assert 0.6 < low < 0.9
    assert high == 1.0
    assert exact.newcombe_paired(20, 0, 0, 0)[0] < 0 < exact.newcombe_paired(20, 0, 0, 0)[1]
    with pytest.raises(ValueError, match="only_b=-1"):
        exact.newcombe_paired(1, 2, -1, 0)


@pytest.mark.parametrize("p11, p10, p01", [(0.5, 0.2, 0.1), (0.9, 0.05, 0.0),
                                           (0.45, 0.05, 0.05), (0.0, 0.5, 0.0)])
def test_newcombe_coverage_at_twenty_pairs(p11: float, p10: float, p01: float) -> None:
    """The exact coverage at n = 20, summed over every possible 2x2 table (multinomial
    probabilities from scipy), is at least the nominal 95 % on these settings (Newcombe
    reports a mean coverage near 0.95 for method 10)."""
    n = 20
    p00 = 1 - p11 - p10 - p01
    truth = p10 - p01
    covered = 0.0
    for a in range(n + 1):
        for b in range(n + 1 - a):
            for c in range(n + 1 - a - b):
                d = n - a - b - c
                low, high = exact.newcombe_paired(a, b, c, d)
                if low <= truth <= high:
                    covered += sps.multinomial.pmf([a, b, c, d], n, [p11, p10, p01, p00])
    assert covered >= 0.95


def test_sign_test_and_binomial_tail_match_scipy() -> None:
    for k, m in [(0, 0), (3, 10), (7, 7), (40, 100), (5100, 10000)]:
        assert exact.binomial_upper_tail_half(k, m) == pytest.approx(
            sps.binom.sf(k - 1, m, 0.5), rel=1e-9, abs=1e-300)
    d = np.array([1.0, 2.0, -1.0, np.inf, 3.0, 0.0, np.nan, -np.inf, 5.0])
    pos, neg, p = exact.sign_test(d)
    assert (pos, neg) == (5, 2)
    assert p == pytest.approx(sps.binomtest(5, 7, 0.5).pvalue)


def test_tost_paired_is_two_one_sided_sign_tests() -> None:
    rng = np.random.default_rng(3)
    d = rng.normal(0.002, 0.01, 60)
    m = 0.01
    p = exact.tost_paired(d, m)
    lower = sps.binomtest(int(np.sum(d > -m)), int(np.sum(d != -m)), 0.5,
                          alternative="greater").pvalue
    upper = sps.binomtest(int(np.sum(d < m)), int(np.sum(d != m)), 0.5,
                          alternative="greater").pvalue
    assert p == pytest.approx(max(lower, upper))
    assert p < 0.05  # the differences lie well within +-0.01
    assert exact.tost_paired(d + 0.02, m) > 0.5  # shifted out of the margin
    with pytest.raises(ValueError, match="margin"):
        exact.tost_paired(d, 0.0)


def test_tost_rate_is_the_interval_inclusion_level() -> None:
    """p is the alpha whose 1 - 2 alpha Newcombe interval just touches the margin."""
    both, only_a, only_b, neither = 180, 3, 2, 15
    margin = 0.05
    p = exact.tost_rate(both, only_a, only_b, neither, margin)
    assert 0 < p < 0.05
    low, high = exact.newcombe_paired(both, only_a, only_b, neither, 1 - 2 * p)
    assert max(-low, high) == pytest.approx(margin, abs=1e-6)
    low90, high90 = exact.newcombe_paired(both, only_a, only_b, neither, 0.9)
    assert -margin < low90 and high90 < margin
    # 20 trials cannot show equivalence within 5 points
    assert exact.tost_rate(18, 1, 1, 0, margin) > 0.05
    assert exact.tost_rate(10, 5, 0, 5, margin) == 1.0  # the estimate itself is outside


def test_format_p() -> None:
    assert exact.format_p(1e-34) == "< 1e-16"
    assert exact.format_p(0.0) == "< 1e-16"
    assert exact.format_p(0.01234) == "0.0123"
    assert exact.format_p(float("nan")) == "-"
