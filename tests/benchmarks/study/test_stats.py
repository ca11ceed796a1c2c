"""The statistics module against scipy.stats and hand-computed cases."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy import stats as sps

from benchmarks.study import stats


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


def _reference_bootstrap(x: np.ndarray, q: float, resamples: int, seed: int) -> tuple[float,
                                                                                         float]:
    """The textbook bootstrap: explicit resamples drawn as stats.bootstrap_quantiles draws
    them (same generator, same chunks), ``numpy.quantile`` of each."""
    xs = np.sort(x)
    n = xs.size
    rng = np.random.default_rng(seed)
    chunk = max(1, stats._CHUNK_VALUES // n)
    values = []
    for start in range(0, resamples, chunk):
        m = min(chunk, resamples - start)
        values.append(np.quantile(xs[rng.integers(0, n, size=(m, n))], q, axis=1))
    v = np.concatenate(values)
    low, high = np.percentile(v, [2.5, 97.5])
    return float(low), float(high)


@pytest.mark.parametrize("q", [0.5, 0.95])
def test_bootstrap_quantile_equals_explicit_resampling(q: float) -> None:
    x = np.random.default_rng(3).lognormal(size=137)
    (low, high), = stats.bootstrap_quantiles(x, [q], resamples=500, seed=11)
    ref = _reference_bootstrap(x, q, 500, 11)
    assert (low, high) == pytest.approx(ref, rel=1e-12)


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


def test_bootstrap_mean_close_to_scipy() -> None:
    x = np.random.default_rng(6).normal(1.0, 2.0, size=300)
    low, high = stats.bootstrap_mean(x, resamples=4000, seed=3)
    ref = sps.bootstrap((x,), np.mean, n_resamples=4000, method="percentile",
                        random_state=np.random.default_rng(9)).confidence_interval
    width = ref.high - ref.low
    assert abs(low - ref.low) < 0.1 * width
    assert abs(high - ref.high) < 0.1 * width


def test_mcnemar_is_a_binomial_test_on_discordant_pairs() -> None:
    rng = np.random.default_rng(12)
    for _ in range(20):
        n = int(rng.integers(5, 300))
        a = rng.random(n) < rng.uniform(0.2, 0.9)
        b = rng.random(n) < rng.uniform(0.2, 0.9)
        res = stats.mcnemar_exact(a, b, resamples=200)
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


@pytest.mark.parametrize("n", [8, 30, 200])
def test_wilcoxon_matches_scipy(n: int) -> None:
    rng = np.random.default_rng(n)
    x = rng.lognormal(size=n)
    y = x * rng.lognormal(0.2, 0.3, size=n)
    res = stats.wilcoxon_signed_rank(x, y, resamples=300)
    ref = sps.wilcoxon(x, y)
    assert res.statistic == ref.statistic
    assert res.p_value == pytest.approx(ref.pvalue, rel=1e-12)
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
    res = stats.wilcoxon_signed_rank(d, np.zeros_like(d), resamples=100)
    assert res.statistic == t_obs
    assert res.p_value == pytest.approx(p_exact, rel=1e-12)


def test_wilcoxon_identical_samples_and_missing_values() -> None:
    x = np.arange(20.0)
    res = stats.wilcoxon_signed_rank(x, x)
    assert (res.p_value, res.difference, res.low, res.high) == (1.0, 0.0, 0.0, 0.0)
    y = list(x + 1.0)
    y[3] = None  # a crashed trial: its pair is left out
    res = stats.wilcoxon_signed_rank(list(x), y, resamples=200)
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
