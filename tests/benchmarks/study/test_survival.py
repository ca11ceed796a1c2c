"""Time to converge as censored data (Kaplan-Meier, log-rank) and success against the
tolerance, against scipy.stats and cases worked by hand."""

from __future__ import annotations

import itertools
import math
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import scipy.stats as sps

from benchmarks.exceptions import BenchmarkError
from benchmarks.study import stats, survival
from benchmarks.study.report import write_report
from tests.benchmarks.study.helpers_rows import make_rows, write_run


def _rows(done: list[int], censored: int, cap: int = 12, name: str = "c") -> list[dict[str, Any]]:
    steps = np.array(done + [cap] * censored)
    conv = np.arange(steps.size) < len(done)
    return make_rows(name, np.full(steps.size, 0.05), conv, steps)


def test_kaplan_meier_by_hand() -> None:
    """Converged at 3, 5, 5, 8, 10 steps, three trials censored at the run's 12 steps:
    S = 7/8 after 3 (8 at risk), 7/8 * 5/7 = 5/8 after 5 (7 at risk, 2 events), 5/8 * 4/5
    = 1/2 after 8 (5 at risk), 1/2 * 3/4 = 3/8 after 10 (4 at risk): the median, the
    first step where S <= 1/2, is 8 steps."""
    km = survival.time_to_converge(_rows([3, 5, 5, 8, 10], 3))
    assert (km.trials, km.converged, km.cap) == (8, 5, 12.0)
    assert km.median == 8.0
    s = dict(zip(km.steps.tolist(), (1 - km.converged_fraction).tolist(), strict=True))
    assert s[3.0] == pytest.approx(7 / 8)
    assert s[5.0] == pytest.approx(5 / 8)
    assert s[8.0] == pytest.approx(1 / 2)
    assert s[10.0] == pytest.approx(3 / 8)
    ref = sps.ecdf(sps.CensoredData(uncensored=[3, 5, 5, 8, 10], right=[12, 12, 12]))
    assert np.allclose(1 - km.converged_fraction, ref.sf.probabilities)
    assert km.low <= km.median <= km.high


def test_censored_median_is_beyond_the_run() -> None:
    km = survival.time_to_converge(_rows([3, 4, 5], 6))
    assert km.median == math.inf and km.high == math.inf
    km = survival.time_to_converge(_rows([], 4))
    assert (km.converged, km.median, km.low) == (0, math.inf, math.inf)


def test_kaplan_meier_median_interval_covers() -> None:
    """Exponential times (median 100 steps) censored at a run of 150 steps, 40 trials:
    the interval holds the true median in about 95 % of 300 repetitions."""
    rng = np.random.default_rng(5)
    true = 100.0
    hits = 0
    reps = 300
    for _ in range(reps):
        t = np.ceil(rng.exponential(true / math.log(2), 40))
        done = [int(x) for x in t if x < 150]
        km = survival.time_to_converge(_rows(done, 40 - len(done), cap=150))
        hits += km.low <= true <= km.high
    assert hits / reps >= 0.92


def test_every_trial_converged_leaves_the_upper_end_open() -> None:
    """Three trials, all converged (132, 141, 170 steps): scipy's log-log band is 0.945
    and 0.774 at the first two and undefined at the last (S = 0), so its upper curve
    never reaches one half and the median's upper end is inf, as R's survfit gives NA;
    it was closed at 170. The lower end is where scipy's lower curve reaches one half."""
    km = survival.time_to_converge(_rows([132, 141, 170], 0, cap=261))
    ref = sps.ecdf(sps.CensoredData(uncensored=[132, 141, 170]))
    with pytest.warns(RuntimeWarning, match="undefined at some observations"):
        band = ref.sf.confidence_interval(method="log-log")  # (at S = 0: the point)
    assert np.isnan(band.high.probabilities[-1]) and (band.high.probabilities[:-1] > 0.5).all()
    assert km.median == 141.0 and km.high == math.inf
    low = band.low.probabilities
    assert km.low == [132.0, 141.0, 170.0][int(np.flatnonzero(np.nan_to_num(low) <= 0.5)[0])]


def test_small_samples_all_converged_cover_the_median() -> None:
    """Four trials, every one converged (exponential times, median 69.3 steps, no
    censoring): the interval holds the true median in about 95 % of 1,000 repetitions
    (it held it in 89 % when the upper end was closed at the last trial's steps)."""
    rng = np.random.default_rng(11)
    true = 100.0 * math.log(2)
    hits = 0
    for _ in range(1000):
        t = np.ceil(rng.exponential(100.0, 4)).astype(int).tolist()
        km = survival.time_to_converge(_rows(t, 0, cap=10_000))
        hits += km.low <= true <= km.high
    assert hits / 1000 >= 0.93


def test_logrank_matches_scipy_and_identical_groups() -> None:
    a = _rows([3, 5, 5, 8, 10], 3, name="a")
    b = _rows([1, 2, 2, 3, 4, 6], 2, name="b")
    ref = sps.logrank(sps.CensoredData(uncensored=[3, 5, 5, 8, 10], right=[12] * 3),
                      sps.CensoredData(uncensored=[1, 2, 2, 3, 4, 6], right=[12] * 2))
    assert survival.logrank_p(a, b) == pytest.approx(ref.pvalue)
    assert survival.logrank_p(a, a) == pytest.approx(1.0)
    assert math.isnan(survival.logrank_p(_rows([], 2), _rows([], 3)))


def _groups() -> list[tuple[list[int], int, int]]:
    """(converged steps, censored trials, run length) of groups with ties, none censored,
    none converged, one trial, and random ones."""
    rng = np.random.default_rng(11)
    out = [([3, 5, 5, 8, 10], 3, 12), ([1, 2, 2, 3, 4, 6], 0, 12), ([], 4, 12), ([7], 0, 9),
           ([4, 4, 4, 4], 1, 4), ([2, 9, 9, 9], 2, 9)]
    for _ in range(40):
        n = int(rng.integers(1, 60))
        cap = int(rng.integers(20, 400))
        t = rng.integers(1, cap + 1, n)
        conv = rng.random(n) < rng.uniform(0.1, 1.0)
        out.append(([int(x) for x in t[conv]], int(np.sum(~conv)), cap))
    return out


def test_kaplan_meier_band_and_logrank_are_scipy_bit_for_bit() -> None:
    """The curve, its log-log band and the log-rank p-value are those of scipy.stats to
    the last bit (the report's medians, intervals and p-values do not move)."""
    groups = _groups()
    for done, cens, cap in groups:
        data, _, _ = survival.censored_data(_rows(done, cens, cap=cap))
        if data.uncensored.size == 0:
            continue
        ref = sps.ecdf(sps.CensoredData(uncensored=data.uncensored, right=data.right))
        curve = survival.kaplan_meier(data)
        assert np.array_equal(curve.steps, ref.sf.quantiles)
        assert np.array_equal(curve.survival, ref.sf.probabilities)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            band = ref.sf.confidence_interval(0.95, method="log-log")
        low, high = survival.log_log_band(curve, 0.95)
        assert np.array_equal(low, band.low.probabilities, equal_nan=True)
        assert np.array_equal(high, band.high.probabilities, equal_nan=True)
    for (da, ca, capa), (db, cb, capb) in itertools.pairwise(groups):
        a, b = _rows(da, ca, cap=capa), _rows(db, cb, cap=capb)
        if not da and not db:
            continue
        ours = survival.logrank_p(a, b)
        run = stats.run_length(a + b)  # both groups' censored trials at the run's end
        xa, _, _ = survival.censored_data(a, run)
        xb, _, _ = survival.censored_data(b, run)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            ref_p = sps.logrank(sps.CensoredData(uncensored=xa.uncensored, right=xa.right),
                                sps.CensoredData(uncensored=xb.uncensored, right=xb.right)
                                ).pvalue
        assert ours == ref_p or (math.isnan(ours) and math.isnan(ref_p)), (da, db)


def test_failed_trials_are_censored_at_the_run_not_where_they_stopped() -> None:
    rows = _rows([3, 5, 5, 8, 10], 3)
    rows[-1].update(steps=2, failure="leg 1 hit its end stop: 425.1 mm")
    data, k, cap = survival.censored_data(rows)
    assert (k, cap) == (5, 12.0)
    assert sorted(data.right.tolist()) == [12.0, 12.0, 12.0]


def test_success_against_tolerance() -> None:
    err = np.array([0.005, 0.02, 0.04, 0.08, 0.2, 0.6, 2.0, 0.03])
    rows = make_rows("c", err, np.ones(8, bool), np.full(8, 100))
    rows[-1].update(failure="leg 2 hit its end stop: 480.2 mm")  # not within any
    k, n, (lo, hi) = survival.within_tolerance(rows, 0.05)
    assert (k, n) == (3, 8)  # 0.005, 0.02, 0.04; the failed trial's 0.03 does not count
    ci = sps.binomtest(3, 8).proportion_ci(method="wilson")
    assert (lo, hi) == pytest.approx((ci.low, ci.high))
    frac, low, high = survival.tolerance_curve(rows, np.array([0.001, 0.05, 1.0, 10.0]))
    assert frac.tolist() == [0.0, 3 / 8, 6 / 8, 7 / 8]
    assert np.all(low <= frac) and np.all(frac <= high)


@pytest.mark.slow
def test_report_has_time_to_converge_and_tolerance_sections(tmp_path: Path) -> None:
    rng = np.random.default_rng(4)
    conv = np.arange(20) < 8  # 8 of 20 within a run of 500 steps
    rows = (make_rows("slow", rng.lognormal(-2, 0.4, 20), conv,
                      np.where(conv, rng.integers(100, 200, 20), 500))
            + make_rows("fast", rng.lognormal(-3, 0.4, 20), np.ones(20, bool),
                        rng.integers(50, 90, 20)))
    text = write_report(write_run(tmp_path / "run", rows)).read_text()
    assert "### Time to converge" in text and "### Success against tolerance" in text
    slow = next(line for line in text.splitlines() if line.startswith("| - | slow | 20 | 8 |"))
    assert slow.split("|")[5].strip().startswith("> 500 [")  # half never converged
    lr = next(line for line in text.splitlines() if line.startswith("| - | fast | slow |"))
    assert "< 1e-16" not in lr and float(lr.split("|")[4]) < 1e-3
    assert (tmp_path / "run" / "synthetic_time_to_converge.png").is_file()


def test_a_converged_trial_without_steps_is_refused_by_name() -> None:
    rows = _rows([3, 5], 1)
    rows[1]["steps"] = None
    with pytest.raises(BenchmarkError, match=r"controller 'c', trial 1: converged with "
                                             r"steps=None"):
        survival.time_to_converge(rows)


def test_a_controller_that_never_converged_keeps_its_curve(tmp_path: Path,
                                                            monkeypatch: pytest.MonkeyPatch
                                                            ) -> None:
    """Its curve is zero to the end of the run, named in the legend with 0/N (it was left
    out, and a panel of such controllers only drew matplotlib's empty-legend warning)."""
    from benchmarks.study import curves_report

    figures: list[Any] = []
    monkeypatch.setattr(curves_report, "save_figure",
                        lambda fig, *a, **k: figures.append(fig) or "km.png")
    rng = np.random.default_rng(5)
    rows = (make_rows("never", rng.lognormal(-2, 0.4, 10), np.zeros(10, bool),
                      np.full(10, 300))
            + make_rows("some", rng.lognormal(-3, 0.4, 10), np.arange(10) < 4,
                        np.where(np.arange(10) < 4, 120, 300)))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # (no empty legend)
        lines = curves_report.time_to_converge_section(tmp_path, "synthetic", rows, {}, [0])
        lines += curves_report.time_to_converge_section(
            tmp_path, "synthetic", [r for r in rows if r["controller"] == "never"], {}, [0])
    assert lines.count("![time to converge](km.png)") == 2
    for fig, want in zip(figures, (["never (0/10)", "some (4/10)"], ["never (0/10)"]),
                         strict=True):
        ax = fig.axes[0]
        assert [t.get_text() for t in ax.get_legend().get_texts()] == want
        line = next(ln for ln in ax.get_lines() if ln.get_label() == "never (0/10)")
        assert line.get_ydata().max() == 0.0 and line.get_xdata().max() == 300


def test_a_group_that_failed_early_is_censored_at_the_points_run_not_its_own(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Every trial of one controller failed before step 44 where the run is 151 steps
    (another controller's trials ran it): its trials need more than 151 steps, not 43."""
    from benchmarks.study import curves_report, intervals

    monkeypatch.setattr(curves_report, "save_figure", lambda *a, **k: "km.png")
    ran = _rows([20, 35, 60, 90], 4, cap=151, name="ran")
    failed = make_rows("failed", np.full(6, 0.05), np.zeros(6, bool),
                       np.array([12, 20, 31, 40, 43, 43]))
    for r in failed:
        r["failure"] = "leg 3 hit its end stop: 480.2 mm"
    run = 151.0
    steps, cap = intervals.censored_steps(failed, run)
    assert cap == 151.0 and np.isinf(steps).all()
    assert intervals.steps_cell(failed, run).startswith("> 151 [")
    lines = curves_report.time_to_converge_section(tmp_path, "s", ran + failed, {}, [0])
    row = [ln for ln in "\n".join(lines).splitlines() if ln.startswith("| - | failed | 6 |")]
    assert row == ["| - | failed | 6 | 0 | > 151 [> 151, > 151] |"], lines
    # the log-rank test as scipy computes it, the failed trials censored at 151
    ref = sps.logrank(sps.CensoredData(uncensored=[20, 35, 60, 90], right=[151] * 4),
                      sps.CensoredData(right=[151] * 6)).pvalue
    assert survival.logrank_p(ran, failed) == pytest.approx(ref, rel=1e-12)
