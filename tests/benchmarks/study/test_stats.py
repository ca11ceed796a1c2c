"""The statistics module against scipy.stats and hand-computed cases."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy import stats as sps

from benchmarks.study import exact, stats


@pytest.mark.parametrize(("k", "n"), [(0, 10), (1, 10), (94, 100), (100, 100), (10000, 10000),
                                      (3, 7), (41, 100), (5000, 10000)])
def test_wilson_matches_scipy(k: int, n: int) -> None:
    ref = sps.binomtest(k, n).proportion_ci(confidence_level=0.95, method="wilson")
    low, high = stats.wilson_interval(k, n)
    assert low == pytest.approx(ref.low, abs=1e-12)
    assert high == pytest.approx(ref.high, abs=1e-12)


def test_wilson_other_level_and_bad_input() -> None:
    ref = sps.binomtest(17, 40).proportion_ci(confidence_level=0.9, method="wilson")
    assert stats.wilson_interval(17, 40, 0.9) == pytest.approx((ref.low, ref.high), abs=1e-12)
    with pytest.raises(ValueError, match="k=11"):
        stats.wilson_interval(11, 10)
    assert all(np.isnan(stats.wilson_interval(0, 0)))


def test_format_rate_cell() -> None:
    ci = sps.binomtest(94, 100).proportion_ci(method="wilson")
    assert stats.format_rate(94, 100) == f"94.0 % [{100 * ci.low:.1f}, {100 * ci.high:.1f}]"
    assert stats.format_rate(0, 0) == "-"
    # a bound that is not 100 % does not print as 100.0
    low = sps.binomtest(10000, 10000).proportion_ci(method="wilson").low
    assert stats.format_rate(10000, 10000) == f"100.0 % [{100 * low:.2f}, 100.0]"
    assert stats.format_rate(10000, 10000) == "100.0 % [99.96, 100.0]"


def _explicit_bootstrap(x: np.ndarray, q: float, resamples: int, seed: int
                        ) -> tuple[float, float]:
    """The textbook bootstrap: explicit resamples of n values, ``numpy.quantile`` of each."""
    rng = np.random.default_rng(seed)
    v = np.quantile(x[rng.integers(0, x.size, size=(resamples, x.size))], q, axis=1)
    low, high = np.percentile(v, [2.5, 97.5])
    return float(low), float(high)


@pytest.mark.parametrize("q", [0.5, 0.95])
@pytest.mark.parametrize("n", [7, 137])
def test_bootstrap_quantile_close_to_explicit_resampling(q: float, n: int) -> None:
    x = np.random.default_rng(n).lognormal(size=n)
    (low, high), = stats.bootstrap_quantiles(x, [q], resamples=20000, seed=11)
    ref_low, ref_high = _explicit_bootstrap(x, q, 20000, 12)
    # the same distribution drawn two ways: the endpoints agree to Monte Carlo accuracy,
    # measured against the spacing of the sample around the quantile
    scale = np.quantile(x, min(1.0, q + 0.1)) - np.quantile(x, max(0.0, q - 0.1))
    assert abs(low - ref_low) < 0.08 * scale
    assert abs(high - ref_high) < 0.08 * scale


def test_bootstrap_order_statistic_distribution_is_exact() -> None:
    """The sampled median's distribution over a small sample equals the exact one:
    P(median* <= x_(j)) = P(Binomial(n, j/n) >= (n+1)/2) for odd n."""
    n = 9
    x = np.arange(1.0, n + 1)
    draws = 200000
    rng_seed = 3
    rng = np.random.default_rng(rng_seed)
    u = rng.beta(5, n + 1 - 5, size=draws)
    idx = np.minimum((n * u).astype(int), n - 1)
    empirical = np.array([np.mean(x[idx] <= x[j]) for j in range(n)])
    exact = np.array([sps.binom.sf(4, n, (j + 1) / n) for j in range(n)])
    assert np.max(np.abs(empirical - exact)) < 0.005
    # and the module draws the same statistic: its interval is two of those values
    (low, high), = stats.bootstrap_quantiles(x, [0.5], resamples=draws, seed=rng_seed)
    lo_ref, hi_ref = np.percentile(x[idx], [2.5, 97.5])
    assert (low, high) == (lo_ref, hi_ref)


@pytest.mark.parametrize("q", [0.5, 0.95])
def test_bootstrap_quantile_close_to_scipy(q: float) -> None:
    x = np.random.default_rng(5).exponential(size=400)
    (low, high), = stats.bootstrap_quantiles(x, [q], resamples=4000, seed=1)
    ref = sps.bootstrap((x,), lambda s, axis: np.quantile(s, q, axis=axis), n_resamples=4000,
                        method="percentile", random_state=np.random.default_rng(2)
                        ).confidence_interval
    width = ref.high - ref.low
    # two independent Monte Carlo estimates of the same interval
    assert abs(low - ref.low) < 0.1 * width
    assert abs(high - ref.high) < 0.1 * width
    assert low < np.quantile(x, q) < high


def test_bootstrap_seed_recorded_behaviour() -> None:
    x = np.random.default_rng(8).normal(size=50)
    a = stats.bootstrap_quantiles(x, [0.5], resamples=300, seed=4)
    b = stats.bootstrap_quantiles(x, [0.5], resamples=300, seed=4)
    c = stats.bootstrap_quantiles(x, [0.5], resamples=300, seed=5)
    assert a == b
    assert a != c
    assert np.isnan(stats.bootstrap_quantiles([None, float("nan")], [0.5])[0][0])
    assert stats.bootstrap_quantiles([2.0], [0.5, 0.95]) == [(2.0, 2.0), (2.0, 2.0)]


def test_rate_difference_interval_is_newcombes() -> None:
    """McNemar's rate difference carries Newcombe's paired interval of its 2x2 table."""
    rng = np.random.default_rng(6)
    a = rng.random(300) < 0.8
    b = rng.random(300) < 0.6
    res = stats.mcnemar_exact(a, b)
    table = (int(np.sum(a & b)), int(np.sum(a & ~b)), int(np.sum(~a & b)),
             int(np.sum(~a & ~b)))
    assert (res.low, res.high) == exact.newcombe_paired(*table)
    assert res.low < res.difference < res.high


def test_mcnemar_is_a_binomial_test_on_discordant_pairs() -> None:
    rng = np.random.default_rng(12)
    for _ in range(20):
        n = int(rng.integers(5, 300))
        a = rng.random(n) < rng.uniform(0.2, 0.9)
        b = rng.random(n) < rng.uniform(0.2, 0.9)
        res = stats.mcnemar_exact(a, b)
        only_a = int(np.sum(a & ~b))
        only_b = int(np.sum(~a & b))
        assert res.discordant == (only_a, only_b)
        if only_a + only_b:
            ref = sps.binomtest(only_a, only_a + only_b, 0.5).pvalue
            assert res.p_value == pytest.approx(ref, rel=1e-10)
        assert res.difference == pytest.approx(a.mean() - b.mean())


def test_mcnemar_identical_and_one_sided_case() -> None:
    a = np.ones(100, bool)
    assert stats.mcnemar_exact(a, a).p_value == 1.0
    b = a.copy()
    b[:6] = False  # 94 % against 100 %, six discordant pairs all one way
    res = stats.mcnemar_exact(b, a)
    assert res.p_value == pytest.approx(2 * 0.5 ** 6)  # 0.03125
    assert res.difference == pytest.approx(-0.06)
    assert res.low <= -0.06 <= res.high < 0


@pytest.mark.slow
@pytest.mark.parametrize("n", [8, 13, 14, 20, 30, 50, 51, 200, 5000])
@pytest.mark.parametrize("kind", ["continuous", "ties", "zeros"])
def test_wilcoxon_matches_scipy(n: int, kind: str) -> None:
    """Every branch: exact (small, no ties), exact with ties or zeros (at most 13
    non-zero differences), normal approximation with the tie correction."""
    rng = np.random.default_rng(n)
    x = rng.lognormal(size=n)
    y = x * rng.lognormal(0.1, 0.3, size=n)
    if kind == "ties":  # steps: integers, many ties
        x, y = np.round(10 * x), np.round(10 * y)
    elif kind == "zeros":  # identical controllers on part of the trials
        y[: n // 2] = x[: n // 2]
    res = stats.wilcoxon_signed_rank(x, y)
    if not np.any(x != y):
        assert res.p_value == 1.0
        return
    ref = sps.wilcoxon(x, y)
    assert res.statistic == ref.statistic
    assert res.p_value == pytest.approx(ref.pvalue, rel=1e-9, abs=1e-300)
    assert res.difference == pytest.approx(np.median(x - y))


def test_wilcoxon_exact_by_enumerating_signs() -> None:
    """Independent of scipy: the exact null distribution of the signed-rank sum by
    enumerating all 2^n sign assignments."""
    d = np.array([0.3, -1.2, 2.5, 0.7, 1.9, -0.1, 3.3, 1.1, 0.45])
    ranks = sps.rankdata(np.abs(d))
    t_plus = ranks[d > 0].sum()
    t_obs = min(t_plus, ranks.sum() - t_plus)
    sums = np.array([sum(r for r, s in zip(ranks, signs, strict=True) if s)
                     for signs in itertools.product((0, 1), repeat=d.size)])
    p_exact = np.mean(np.minimum(sums, ranks.sum() - sums) <= t_obs)
    res = stats.wilcoxon_signed_rank(d, np.zeros_like(d))
    assert res.statistic == t_obs
    assert res.p_value == pytest.approx(p_exact, rel=1e-12)


def test_wilcoxon_identical_samples_and_missing_values() -> None:
    x = np.arange(20.0)
    res = stats.wilcoxon_signed_rank(x, x)
    assert (res.p_value, res.difference, res.low, res.high) == (1.0, 0.0, 0.0, 0.0)
    y = list(x + 1.0)
    y[3] = None  # a crashed trial: its pair is left out
    res = stats.wilcoxon_signed_rank(list(x), y)
    assert res.n == 19
    assert res.difference == -1.0


def test_median_difference_interval_covers() -> None:
    rng = np.random.default_rng(21)
    x = rng.normal(size=500)
    med, low, high = stats.median_difference(x + 0.5, x + rng.normal(0, 0.1, 500))
    assert low < med < high
    assert low < 0.5 < high


def test_holm_hand_computed() -> None:
    # sorted: 0.01 (x4 = 0.04), 0.02 (x3 = 0.06), 0.03 (x2 = 0.06), 0.04 (x1 = 0.04 -> 0.06)
    p = [0.03, 0.01, 0.04, 0.02]
    assert stats.holm(p) == pytest.approx([0.06, 0.04, 0.06, 0.06])
    # clipping at 1 and nan left out of the family
    assert stats.holm([0.5, float("nan"), 0.4]) == pytest.approx([0.8, np.nan, 0.8],
                                                                nan_ok=True)
    assert stats.holm([0.001]) == [0.001]
    assert stats.holm([]) == []


def test_wilson_intervals_as_arrays_match_scipy() -> None:
    k = np.array([0, 1, 7, 19, 20])
    low, high = stats.wilson_intervals(k, 20)
    for j, lo, hi in zip(k, low, high, strict=True):
        ci = sps.binomtest(int(j), 20).proportion_ci(method="wilson")
        assert (lo, hi) == pytest.approx((ci.low, ci.high))
    assert (low[0], high[-1]) == (0.0, 1.0)


def test_level_or_quantile_in_percent_is_refused_by_name() -> None:
    x = np.arange(20.0)
    percent = r"confidence level 95: must lie in \(0, 1\) \(a fraction, not a percentage\)"
    with pytest.raises(ValueError, match=percent):
        stats.wilson_interval(7, 10, level=95)
    with pytest.raises(ValueError, match=percent):
        stats.wilson_intervals(np.array([7]), 10, level=95)
    with pytest.raises(ValueError, match=percent):
        stats.bootstrap_quantiles(x, [0.5], level=95)
    with pytest.raises(ValueError, match=r"quantile q 50 at index 0: must lie in \[0, 1\] "
                                         r"\(a fraction, not a percentage\)"):
        stats.bootstrap_quantiles(x, [50])
    with pytest.raises(ValueError, match=r"quantile q -0.1 at index 1: must lie in \[0, 1\]$"):
        stats.bootstrap_quantiles([], [0.5, -0.1])
    assert stats.bootstrap_quantiles(x, [0.0, 1.0]) == [(0.0, 3.0), (16.0, 19.0)]  # the ends


def test_wilson_intervals_bad_counts_named() -> None:
    with pytest.raises(ValueError, match=r"successes k 12 at index 1 > n 10: must lie in \[0, n\]"):
        stats.wilson_intervals(np.array([3, 12]), 10)
    with pytest.raises(ValueError, match=r"successes k -1 at index 0: must lie in \[0, n 10\]"):
        stats.wilson_intervals(np.array([-1]), 10)
    with pytest.raises(ValueError, match="trials n 0: must be positive"):
        stats.wilson_intervals(np.array([0]), 0)


def test_holm_refuses_a_p_value_outside_unit_interval() -> None:
    with pytest.raises(ValueError, match=r"p-value 2.0 at index 1: must lie in \[0, 1\]"):
        stats.holm([0.5, 2.0])
    with pytest.raises(ValueError, match=r"p-value -0.1 at index 0: must lie in \[0, 1\]"):
        stats.holm([-0.1])
    assert stats.holm([0.0, 1.0, float("nan")]) == pytest.approx([0.0, 1.0, np.nan], nan_ok=True)
