"""hexapod-bench compare: paired tests within a run and between two runs."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy import stats as sps

from benchmarks.cli import main as cli_main
from benchmarks.exceptions import BenchmarkError
from benchmarks.study import exact, load
from benchmarks.study.compare import compare_controllers, compare_runs
from tests.benchmarks.study.helpers_rows import make_rows, two_controllers, write_run

#: Two leg-edge laws on the same trials, the second with a fifth of the gain: made
#: slower on purpose. No noise, so both reach the goal.
SCENARIO = """
name = "compare-test"
seed = 7
trials = 12
controllers = ["leg-edge",
               {name = "leg-edge", label = "edge-slow", adaptive_gain = [1.0, 0.2, 6.0]}]

[controller_options]
adaptive_gain = [5.0, 1.0, 30.0]

[robot]
preset = "deltalab"
dt = 0.02

[camera]
preset = "front"

[noise]
model = "none"

[task]
kind = "random-pairs"
max_steps = 1500
position_tolerance_mm = 0.5
orientation_tolerance_deg = 0.05
"""

REQUIRED = {"a", "b", "metric", "test", "n", "statistic", "p_value", "p_holm", "difference",
            "interval"}


@pytest.fixture(scope="module")
def two_real_runs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    tmp = tmp_path_factory.mktemp("cmp")
    scen = tmp / "compare-test.toml"
    scen.write_text(SCENARIO)
    dirs = []
    for name in ("a", "b"):
        out = tmp / name
        assert cli_main(["run", str(scen), "--out", str(out), "--no-progress",
                         "--record", "0"]) == 0
        dirs.append(out)
    return dirs[0], dirs[1]


@pytest.mark.slow
def test_identical_runs_no_difference_no_determinism_failure(
        two_real_runs: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    a, b = two_real_runs
    js = tmp_path / "c.json"
    assert cli_main(["compare", str(a), str(b), "--json", str(js), "--check"]) == 0
    out = capsys.readouterr().out
    assert "Regressions (B significantly worse than A): 0" in out
    assert "Determinism check: 0 of 24 matched trials differ" in out
    marked = json.loads(js.read_text())
    assert marked["generator"] == "hexapod-vs"
    doc = marked["comparisons"]
    assert all(set(d) >= REQUIRED for d in doc)
    tests = [d for d in doc if d["test"] != "determinism"]
    assert {d["metric"] for d in tests} == {"converged", "final_error", "steps"}
    assert all(d["p_value"] == 1.0 and d["difference"] == 0 for d in tests)
    det = next(d for d in doc if d["test"] == "determinism")
    assert det["statistic"] == 0 and det["n"] == 24


@pytest.mark.slow
def test_slower_controller_is_found(two_real_runs: tuple[Path, Path],
                                    capsys: pytest.CaptureFixture[str]) -> None:
    a, _ = two_real_runs
    df = load(a)
    res = {c.metric: c for c in compare_controllers(df)}
    steps = res["steps"]
    assert (steps.a, steps.b) == ("edge-slow", "leg-edge")
    slow = df[df.controller == "edge-slow"].set_index("trial")
    fast = df[df.controller == "leg-edge"].set_index("trial")
    assert bool(slow.converged.all() and fast.converged.all())
    d = (slow.steps - fast.steps).to_numpy()
    assert np.all(d > 0)  # slower in every trial...
    assert steps.p_value == pytest.approx(2 * 0.5 ** 12)  # ...so the exact p is 2 / 2^12
    assert steps.better == "leg-edge"
    assert steps.difference == np.median(d)
    assert steps.interval[0] > 0
    assert cli_main(["compare", str(a), "--baseline", "leg-edge"]) == 0
    out = capsys.readouterr().out
    assert "steps: leg-edge is better than edge-slow" in out


def test_worse_controller_found_between_runs(tmp_path: Path) -> None:
    """Run B's controller fails 15 more trials of 200 and has 30 % larger errors."""
    good = [r for r in two_controllers(200) if r["controller"] == "good"]
    worse = [dict(r, controller="good") for r in two_controllers(200, worse_by=1.3,
                                                                  worse_fails=15)
             if r["controller"] == "bad"]
    a = write_run(tmp_path / "a", good)
    b = write_run(tmp_path / "b", worse)
    comps, different, matched = compare_runs(load(a), load(b))
    by = {c.metric: c for c in comps}
    assert matched == 200
    assert by["converged"].verdict.startswith("REGRESSION")
    assert by["converged"].p_value == pytest.approx(2 * 0.5 ** 15)
    assert by["final_error"].verdict.startswith("REGRESSION")
    assert by["final_error"].difference > 0
    assert set(different["column"]) >= {"converged", "final_position_error_mm"}
    assert cli_main(["compare", str(a), str(b), "--check"]) == 1


def test_within_run_holm_and_no_false_alarm(tmp_path: Path) -> None:
    rows = two_controllers(300, worse_by=1.0)  # identical controllers
    rng = np.random.default_rng(2)
    for r in rows:  # a third with independent noise only
        if r["controller"] == "bad":
            r["final_position_error_mm"] *= float(rng.uniform(0.999, 1.001))
    comps = compare_controllers(load(write_run(tmp_path / "r", rows)))
    assert all(c.better is None for c in comps)
    assert all(c.p_holm >= c.p_value for c in comps)


def test_compare_errors(tmp_path: Path) -> None:
    rows = [r for r in two_controllers(10) if r["controller"] == "good"]
    df = load(write_run(tmp_path / "one", rows))
    with pytest.raises(BenchmarkError, match="one controller"):
        compare_controllers(df)
    df2 = load(write_run(tmp_path / "two", two_controllers(10)))
    with pytest.raises(BenchmarkError, match=r"--baseline 'nope'.*bad, good"):
        compare_controllers(df2, baseline="nope")
    with pytest.raises(BenchmarkError, match="--metric 'bogus'"):
        compare_controllers(df2, metrics=("bogus",))


def test_two_runs_count_the_unmatched_trials_and_head_columns_with_the_runs(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """40 trials against 160 of the same study: 40 matched, 0 and 120 unmatched; the
    value columns are headed with each run's name (not "a" for run B)."""
    rows = [r for r in two_controllers(160) if r["controller"] == "good"]
    a = write_run(tmp_path / "before", rows[:40])
    b = write_run(tmp_path / "after", rows)
    assert cli_main(["compare", str(a), str(b)]) == 0
    out = capsys.readouterr().out
    assert (f"Trials matched by scenario, sweep point, controller and trial: 40 compared; "
            f"unmatched, left out: 0 of the 40 of run A ({a}), 120 of the 160 of run B "
            f"({b})") in out
    head = next(line for line in out.splitlines() if "metric" in line)
    cols = [c.strip() for c in head.strip("┃").split("┃")]
    # scenario and controller are the same in every row: they went to the title
    assert cols[:5] == ["metric", "n", "B (after)", "A (before)",
                        "B (after) - A (before) [95 % CI]"]
    assert "scenario: synthetic, controller: good" in " ".join(out.split())
    comps, _, matched = compare_runs(load(a), load(b))
    assert matched == 40 and all(c.n == 40 for c in comps if c.metric != "steps")
    js = tmp_path / "c.json"
    assert cli_main(["compare", str(a), str(b), "--json", str(js)]) == 0
    det = next(d for d in json.loads(js.read_text())["comparisons"]
               if d["test"] == "determinism")
    assert det["n"] == 40 and det["unmatched"] == {"A": 0, "B": 120}


def test_failed_trials_are_left_out_of_all_but_convergence(tmp_path: Path) -> None:
    rows = two_controllers(30)
    for r in rows[:5]:  # five trials of "good" end at an end stop, with a large error
        r.update(converged=False, failure="leg 1 hit its end stop: 425.101 mm",
                 final_position_error_mm=27.0)
    by = {c.metric: c for c in compare_controllers(load(write_run(tmp_path / "r", rows)))}
    assert by["converged"].n == 30 and by["converged"].discordant == (5, 0)  # a: bad
    assert by["final_error"].n == 25  # the failed trials' 27 mm not compared
    assert by["final_error"].p_value == 1.0


def _censored_pair(tmp_path: Path, fast_converges: int) -> list:
    """``fast`` converges in 100 steps on its first ``fast_converges`` of 20 trials and
    not at all on the others (500 steps run); ``sure`` converges on all 20 in 200."""
    n = 20
    err = np.full(n, 0.05)
    conv = np.arange(n) < fast_converges
    fast = make_rows("fast", err, conv, np.where(conv, 100, 500))
    sure = make_rows("sure", err, np.ones(n, bool), np.full(n, 200))
    return compare_controllers(load(write_run(tmp_path / f"c{fast_converges}", fast + sure)),
                               metrics=("steps",))


def test_steps_are_compared_with_censoring_not_on_the_survivors(tmp_path: Path) -> None:
    """On the trials both converged ``fast`` wins every pair (the survivorship view); with
    the trials it never converged counted as slower, ``sure`` is faster on 17 of 20."""
    (c,) = _censored_pair(tmp_path, 3)
    assert c.test == "sign-censored"
    assert c.discordant == (17, 3)  # fast (a) higher, i.e. slower, in 17 pairs
    assert c.p_value == pytest.approx(sps.binomtest(17, 20, 0.5).pvalue)
    assert c.better == "sure"
    assert c.a_value == np.inf  # fast's median is censored: it converged on 3 of 20
    assert c.interval[1] == np.inf
    (c,) = _censored_pair(tmp_path, 12)  # 12 faster, 8 censored: no conclusion
    assert c.discordant == (8, 12) and c.better is None
    assert c.outcome == "not shown equivalent"


def test_json_keeps_the_sign_of_an_infinite_value(tmp_path: Path) -> None:
    """A censored median (+inf) and an interval's censored end are written as ``"inf"``
    (JSON has no infinity; ``null`` would lose the sign) and read back by ``float``;
    a value that is not a number stays ``null``."""
    n = 20
    err = np.full(n, 0.05)
    conv = np.arange(n) < 3
    rows = (make_rows("fast", err, conv, np.where(conv, 100, 500))
            + make_rows("sure", err, np.ones(n, bool), np.full(n, 200)))
    js = tmp_path / "c.json"
    assert cli_main(["compare", str(write_run(tmp_path / "r", rows)), "--metric", "steps",
                     "--json", str(js)]) == 0
    (d,) = json.loads(js.read_text())["comparisons"]
    assert d["a_value"] == "inf" and float(d["a_value"]) == math.inf
    assert d["interval"][1] == "inf" and d["b_value"] == 200.0
    (c,) = compare_controllers(load(tmp_path / "r"), metrics=("steps",))
    assert dataclasses.replace(c, p_equivalence=math.nan).to_json()["p_equivalence"] is None


def test_equivalence_needs_tost_not_a_missing_difference(tmp_path: Path,
                                                         capsys: pytest.CaptureFixture[str]
                                                         ) -> None:
    """Two controllers whose final errors differ by at most 0.1 %: equivalent within
    0.01 mm on 300 pairs; on 8 pairs, the same differences are not shown equivalent (the
    one-sided sign tests cannot go below 1/16 with 4 pairs), and not different."""
    rows = two_controllers(300)
    rng = np.random.default_rng(2)
    for r in rows:
        if r["controller"] == "bad":
            r["final_position_error_mm"] *= float(rng.uniform(0.999, 1.001))
    comps = {c.metric: c for c in compare_controllers(load(write_run(tmp_path / "r", rows)))}
    fe = comps["final_error"]
    assert fe.better is None and fe.outcome == "equivalent"
    assert fe.p_equivalence_holm < 0.05 and fe.margin == 0.01
    assert "equivalent within +-0.01 mm" in fe.verdict
    assert "no significant difference" not in fe.verdict
    few = [r for r in rows if r["trial"] < 4]
    small = {c.metric: c for c in compare_controllers(load(write_run(tmp_path / "s", few)))}
    assert small["final_error"].outcome == "not shown equivalent"
    assert small["final_error"].p_equivalence == pytest.approx(0.5 ** 4)
    assert "not shown different, not shown equivalent within +-0.01 mm" in \
        small["final_error"].verdict
    assert cli_main(["compare", str(tmp_path / "r"), "--margin", "final_error=0.00001"]) == 0
    out = capsys.readouterr().out
    assert "Equivalent within their margins" in out
    assert cli_main(["compare", str(tmp_path / "r"), "--margin", "final_error"]) != 0
    assert "--margin 'final_error': expected NAME=NUMBER" in capsys.readouterr().err
    with pytest.raises(BenchmarkError, match="positive"):
        compare_controllers(load(tmp_path / "r"), margins={"steps": -1.0})
    # a margin of a metric not compared (a typo) is refused, not left unused
    assert cli_main(["compare", str(tmp_path / "r"), "--margin", "final_eror=1"]) != 0
    err = capsys.readouterr().err
    assert "--margin final_eror=1.0: 'final_eror' is not a metric of this comparison " \
           "(converged, final_error, steps); did you mean 'final_error'?" in " ".join(err.split())


def test_rate_difference_has_newcombes_interval_and_tiny_p_is_bounded(tmp_path: Path
                                                                       ) -> None:
    """20 of 20 against 0 of 20: the interval is Newcombe's, not the bootstrap's
    [+100, +100]; a p-value below 1e-16 is printed as such."""
    n = 20
    err = np.full(n, 0.05)
    rows = (make_rows("all", err, np.ones(n, bool), np.full(n, 100))
            + make_rows("none", err, np.zeros(n, bool), np.full(n, 500)))
    c = next(c for c in compare_controllers(load(write_run(tmp_path / "r", rows)))
             if c.metric == "converged")
    assert c.interval == exact.newcombe_paired(0, 20, 0, 0)
    assert c.interval[0] < 0.9
    assert "difference +100.0 points [+77.2, +100.0]" in c.verdict
    # each figure named by its controller: the sentence names the better one first, the
    # figures came in (a, b) order unnamed and read as the other way round
    assert f"({c.a} {100 * c.a_value:.1f} % against {c.b} {100 * c.b_value:.1f} %" \
        in c.verdict, c.verdict
    rows = two_controllers(3000, worse_by=1.5)
    fe = next(c for c in compare_controllers(load(write_run(tmp_path / "big", rows)))
              if c.metric == "final_error")
    assert fe.p_holm < 1e-16 and "Holm p = < 1e-16" in fe.verdict


def test_settling_is_compared_with_censoring(tmp_path: Path) -> None:
    """A trajectory task: ``quick`` settles in 0.1 s on 4 of 12 trials and never on the
    others; ``steady`` settles in 0.3 s on all 12. On the trials both settled ``quick``
    wins; counted with the unsettled ones, ``steady`` is faster on 8 of 12 pairs."""
    rows = []
    for ctrl, times in (("quick", [0.1] * 4 + [None] * 8), ("steady", [0.3] * 12)):
        r = make_rows(ctrl, np.full(12, 0.05), np.array([t is not None for t in times]),
                      np.full(12, 100))
        for row, t in zip(r, times, strict=True):
            row.update(tracking_rms_position_mm=0.1, tracking_max_position_mm=0.2,
                       settling_time_s=t)
        rows += r
    comps = compare_controllers(load(write_run(tmp_path / "t", rows)), metrics=("settling",))
    (c,) = comps
    assert c.test == "sign-censored"
    assert c.discordant == (8, 4)
    assert c.p_value == pytest.approx(sps.binomtest(8, 12, 0.5).pvalue)


def test_margin_option_in_points_and_json_fields(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``--margin converged=10`` is 10 points (0.1 of the trials) in the JSON, which
    carries each comparison's outcome and equivalence p-values."""
    run = write_run(tmp_path / "r", two_controllers(60))
    js = tmp_path / "c.json"
    assert cli_main(["compare", str(run), "--margin", "converged=10", "--json", str(js)]) == 0
    doc = {d["metric"]: d for d in json.loads(js.read_text())["comparisons"]}
    assert doc["converged"]["margin"] == pytest.approx(0.1)
    assert doc["final_error"]["margin"] == pytest.approx(0.01)
    assert doc["converged"]["outcome"] == "equivalent"  # 60 of 60 each: [-6.0, +6.0] pts
    assert doc["converged"]["p_equivalence_holm"] < 0.05
    assert {d["outcome"] for d in doc.values()} <= {"different", "equivalent",
                                                    "not shown equivalent"}
    capsys.readouterr()
    assert cli_main(["compare", str(run), "--margin", "converged=150"]) == 2
    assert "--margin converged=150: converged's margin is in percentage points, in (0, " \
        "100]" in capsys.readouterr().err  # (it quoted the fraction, 1.5)


@pytest.mark.slow
def test_compare_states_the_goal_setting_and_warns_when_two_runs_differ(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Rows without a ``goal`` column are the legacy setting (``mixed``); two runs whose
    rows used different settings are compared with a warning naming the points, and the
    JSON says which settings were compared."""
    from benchmarks.study.compare import goal_mismatches, goal_settings

    rows = [r for r in two_controllers(20) if r["controller"] == "good"]
    a = write_run(tmp_path / "legacy", rows)  # written before the setting existed
    b = write_run(tmp_path / "taught", [dict(r, goal="taught") for r in rows])
    c = write_run(tmp_path / "mixed", [dict(r, goal="mixed") for r in rows])
    assert goal_settings(load(a)) == "mixed" and goal_settings(load(b)) == "taught"
    assert goal_mismatches(load(a), load(c)) == []
    assert goal_mismatches(load(a), load(b)) == ["synthetic point 0: A mixed, B taught"]
    js = tmp_path / "c.json"
    assert cli_main(["compare", str(a), str(b), "--json", str(js)]) == 0
    captured = capsys.readouterr()
    assert "goal setting A mixed, B taught" in " ".join(captured.out.split())
    assert "the goal setting ([task] goal) differs between the runs in 1 scenario" \
        in captured.err
    assert "synthetic point 0: A mixed, B taught" in captured.err
    det = next(d for d in json.loads(js.read_text())["comparisons"]
               if d["test"] == "determinism")
    assert det["goal"] == {"A": "mixed", "B": "taught",
                           "differs": ["synthetic point 0: A mixed, B taught"]}
    assert cli_main(["compare", str(a), str(c)]) == 0
    assert "differs between the runs" not in capsys.readouterr().err
    both = write_run(tmp_path / "both", rows + [dict(r, controller="bad", goal="taught")
                                                for r in rows])
    assert goal_settings(load(both)) == "mixed, taught"


def test_a_rank_test_whose_median_interval_holds_zero_is_not_a_better(tmp_path: Path) -> None:
    """48 pairs where ``a`` ends a little worse, 32 where it ends much better: Wilcoxon's
    rank sums favour ``a`` (scipy's p = 0.03) while the median paired difference is
    positive and its interval holds 0 (the sign test: p = 0.09). A verdict of *better*
    would say more than the numbers: the outcome is *unclear*, with both reported."""
    rng = np.random.default_rng(7)
    base = rng.uniform(1.0, 2.0, 80)
    d = np.concatenate([rng.uniform(0.01, 0.05, 48), -rng.uniform(1.0, 2.0, 32)])
    conv = np.ones(80, bool)
    rows = (make_rows("a", base + d, conv, np.full(80, 100))
            + make_rows("b", base, conv, np.full(80, 100)))
    comps = compare_controllers(load(write_run(tmp_path / "r", rows)),
                                metrics=("final_error",))
    (c,) = comps
    ref = sps.wilcoxon(base + d, base)
    assert ref.pvalue < 0.05 and c.p_value == pytest.approx(ref.pvalue, rel=1e-9)
    assert sps.binomtest(48, 80).pvalue > 0.05
    lo, hi = c.interval
    assert lo < 0 < hi and c.difference > 0
    assert c.outcome == "unclear" and c.better is None
    assert "differ by the wilcoxon test" in c.verdict and "not shown better" in c.verdict
    assert f"[{lo:+.4g}, {hi:+.4g}]" in c.verdict


def test_a_censored_median_difference_is_known_where_its_order_statistics_are() -> None:
    """Paired steps 1, 432 and one pair where only ``b`` converged (``+inf``): the median
    is the finite 432 (numpy.quantile gives nan there); with a fourth such pair it is
    only known to exceed 432 (censored); with -inf and +inf in the middle, unknown."""
    from benchmarks.study.compare import censored_sign_test

    inf = np.inf
    b = np.array([9.0, 8.0, 5.0, 5.0])
    assert censored_sign_test(np.array([10.0, 440.0, inf]), b[:3]).difference == 432.0
    assert censored_sign_test(np.array([10.0, 440.0, inf, inf]), b).difference == inf
    mixed = censored_sign_test(np.array([10.0, 3.0, 8.0, inf]), np.array([inf, 1.0, 1.0, 5.0]))
    assert mixed.difference == 4.5  # -inf, 2, 7, +inf: the middle two are finite
    assert np.isnan(censored_sign_test(np.array([1.0, inf]), np.array([inf, 1.0])).difference)
    for finite in (np.arange(7.0), np.array([3.0, -1.0, 2.5, 8.0])):  # numpy's, bit for bit
        assert exact.censored_quantile(finite, 0.5) == np.quantile(finite, 0.5)


def test_an_interval_end_without_a_finite_bound_prints_as_inf_not_censored() -> None:
    """Five pairs where only ``b`` settled: the median difference is censored, its
    interval's lower end lies outside the sample (a median needs 6 for both ends) and
    printed ``-censored``, as if ``a`` had been the censored one; it is ``-inf``."""
    from types import SimpleNamespace

    from benchmarks.study.analysis_cli import _fmt_diff
    from benchmarks.study.compare import censored_sign_test

    inf = np.inf
    res = censored_sign_test(np.full(5, inf), np.array([1.0, 2.0, 2.5, 3.0, 0.9]))
    assert res.difference == inf and res.low == -inf and res.high == inf
    row = SimpleNamespace(metric="settling", difference=res.difference,
                          interval=(res.low, res.high))
    assert _fmt_diff(row) == "censored [-inf, inf]"


def _with_study(run: Path, study: dict[str, object]) -> Path:
    (run / "run.json").write_text(json.dumps({"scenarios": {"synthetic": {"study": study}}}))
    return run


def test_runs_of_different_studies_are_not_held_to_determinism_and_one_task_is_said(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Two runs whose controllers' options differ (tuned against as given): their rows
    differ by design, not by a loss of determinism (it said 'they should be identical'
    and --check failed); a fixed-task run's comparison says it compares one task."""
    rows = two_controllers(40)
    other = [dict(r, final_position_error_mm=r["final_position_error_mm"] * 0.9) for r in rows]
    a = _with_study(write_run(tmp_path / "a", rows),
                    {"seed": 1, "controllers": ["good", "bad"], "task.kind": "fixed"})
    b = _with_study(write_run(tmp_path / "b", other),
                    {"seed": 1, "controllers": ["good (gain=2.0)", "bad"], "task.kind": "fixed"})
    assert cli_main(["compare", str(a), str(b), "--check"]) == 0  # better, not a regression
    out = capsys.readouterr().out
    assert "80 of 80 matched trials differ between the runs, whose studies differ" in out
    assert "synthetic: controllers A=['good', 'bad'] B=['good (gain=2.0)', 'bad']" in out
    _with_study(b, {"seed": 1, "controllers": ["good", "bad"], "task.kind": "fixed"})
    assert cli_main(["compare", str(a), str(b), "--check"]) == 1  # same study: they should not
    assert "should be identical" in capsys.readouterr().out
    cli_main(["compare", str(a)])
    assert "note: synthetic repeats ONE task" in capsys.readouterr().out


def test_a_comparison_without_pairs_does_not_count_in_holm() -> None:
    """Three ``steps`` comparisons, one with no pairs (neither controller converged): it
    gets no p-value and the other two are corrected over two, as scipy's Holm over two
    gives (it counted with p = 1 in m = 3)."""
    from benchmarks.study.compare import Comparison
    from benchmarks.study.verdicts import holm_and_verdicts

    def comp(p: float, n: int, direction: int) -> Comparison:
        return Comparison("s", 0, "", "a", "b", "steps", "steps", "sign-censored", n, 0.0, p,
                          float("nan"), 5.0, (1.0, 9.0), 10.0, 5.0, direction=direction)

    family = [comp(0.02, 20, 1), comp(1.0, 0, 0), comp(0.03, 20, 1)]
    holm_and_verdicts(family, "steps", False)
    assert math.isnan(family[1].p_value) and math.isnan(family[1].p_holm)
    assert family[1].verdict == "steps: no pairs to compare"
    # Holm over the two tested: 2 x 0.02 = 0.04, then max(0.04, 1 x 0.03) = 0.04
    assert family[0].p_holm == pytest.approx(0.04) and family[2].p_holm == pytest.approx(0.04)
    assert family[0].better == "b" and family[2].better == "b"  # (3 would have given 0.06)
