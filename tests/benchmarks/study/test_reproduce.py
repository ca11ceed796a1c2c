"""hexapod-bench reproduce: the scorecard's rules on hand-made cases, the summary counts,
and small runs of two papers' studies."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy import stats as sps

from benchmarks.cli import main as cli_main
from benchmarks.exceptions import BenchmarkError
from benchmarks.study import load, paper_figures
from benchmarks.study.paper_figures import Figure, builtin_figures
from benchmarks.study.reproduce import (
    Result,
    judge,
    measure,
    reproduce,
    select,
    summary,
    verdicts,
)
from tests.benchmarks.study.helpers_rows import make_rows, write_run


def _fig(paper: str = "1.4 mm", value: float = 1.4, tolerance: float = 0.05,
         **kw: Any) -> Figure:
    base: dict[str, Any] = dict(id="f", seed="seed001", where="sec", quantity="q", paper=paper,
                                kind="number", value=value, unit="mm", rule="equal",
                                statistic="median", study="run:andreff2005-noise",
                                tolerance=tolerance, controller="leg-direction",
                                column="final_position_error_mm", why_outside="because")
    base.update(kw)
    return Figure(**base)


def test_one_trial_and_many_trial_figures_get_the_same_rule() -> None:
    """The case the old rule got wrong: 2.43 mm [2.1, 2.8] against the paper's one-trial
    1.4 mm was 'within' (the range of single trials reached it); under the one rule it is
    outside, as it would be for a many-trial figure."""
    one, many = _fig(paper_trials=1), _fig(paper_trials=None)
    cases = [((2.43, (2.1, 2.8)), "outside (higher)"),
             ((1.2, (1.0, 1.36)), "within"),      # the interval reaches 1.35
             ((1.2, (1.0, 1.34)), "outside (lower)"),
             ((1.5, (1.45, 1.7)), "within")]      # touches 1.45
    for (v, interval), want in cases:
        assert judge(one, v, interval) == judge(many, v, interval) == want


def test_rules_below_claims_and_other_controllers() -> None:
    below = _fig("< 1 mm", 1.0, rule="below", tolerance=0.0)
    assert judge(below, 0.9, (0.8, 0.99)) == "within"
    # an interval that holds the bound is not shown below it, nor shown higher
    assert judge(below, 0.9, (0.8, 1.01)) == \
        "outside (not shown below: the interval holds the bound)"
    assert judge(below, 1.2, (1.05, 1.4)) == "outside (higher)"
    # too few trials for an interval (an end beyond the sample): no verdict either way
    assert judge(below, 0.9, (-np.inf, np.inf)).startswith("not comparable (too few trials")
    equal = _fig("0.6 mm", 0.6, 0.05)
    assert judge(equal, 0.6, (-np.inf, np.inf)).startswith("not comparable (too few trials")
    assert judge(equal, 0.6, (0.5, np.inf)).startswith("not comparable (too few trials")
    rate = _fig("100 %", 100.0, 0.5, unit="%", statistic="rate", column="")
    assert judge(rate, 1.0, (0.9996, 1.0)) == "within"
    assert judge(rate, 0.98, (0.97, 0.99)) == "outside (lower)"
    claim = replace(rate, kind="claim", paper="converges")
    assert judge(claim, 0.0, (0.0, 0.161)) == "contradicts"   # 0/20: the claim fails
    assert judge(claim, 1.0, (0.839, 1.0)) == "within"        # 20/20
    both = replace(claim, other="leg-direction", other_value=0.0)
    assert judge(both, 1.0, (0.839, 1.0), (0.0, 0.161)) == "within"
    # the edge law converging 4/20 does not make "edge converges, direction does not"
    assert judge(both, 0.2, (0.081, 0.416), (0.0, 0.161)) == "contradicts"
    assert judge(both, 1.0, (0.839, 1.0), (0.05, 0.4)) == "contradicts"
    assert judge(both, 1.0, (0.839, 1.0), None).startswith("not comparable")
    assert judge(rate, None, None) == "not comparable (no finite value)"


def test_summary_counts_rows_by_verdict_and_variants_apart() -> None:
    f = _fig()
    rs = [Result(f, "", 1.4, (1.3, 1.5), 30),                          # within
          Result(replace(f, id="g"), "", 3.0, (2.5, 3.5), 30),         # outside
          Result(replace(f, id="h", kind="claim", unit="%", statistic="rate", value=100.0,
                         tolerance=0.5), "", 0.0, (0.0, 0.16), 20),    # contradicts
          Result(replace(f, id="i"), "", None, None, 0),              # not comparable
          Result(replace(f, id="v", variant_of="f"), "", 3.0, (2.5, 3.5), 30)]
    verdicts(rs)
    assert [r.category for r in rs] == ["within", "outside", "contradicts",
                                        "not comparable", "outside"]
    assert [bool(r.why) for r in rs] == [False, True, True, True, True]
    text = summary(rs)
    assert text.startswith("4 paper figures (one row each): 1 within, 1 outside, "
                           "1 contradicts, 1 not comparable; 1 variants (a figure under "
                           "another setting): 0 within, 1 outside, 0 contradicts, "
                           "0 not comparable. Rule:")


def test_tail_maximum_rows_get_the_papers_ratio() -> None:
    mx = _fig("1.9 mm", 1.9, statistic="median_tail_max", column="",
              sweep={"noise_amplitude_deg": 0.05})
    md = _fig("0.6 mm", 0.6, column="tail_position_error_mm",
              sweep={"noise_amplitude_deg": 0.05})
    other = replace(md, sweep={"noise_amplitude_deg": 0.1})
    rs = [Result(mx, "", 1.5, (1.2, 1.6), 30, note="n"), Result(other, "", 1.0, (1, 1), 30),
          Result(md, "", 0.55, (0.5, 0.6), 30)]
    from benchmarks.study.reproduce import tail_ratios

    tail_ratios(rs)
    # 1.9 / 0.6 = 3.17; as printed 1.85 / 0.65 = 2.85 to 1.95 / 0.55 = 3.55
    assert rs[0].note == ("n; the paper's tail maximum is 3.2x its tail median (1.9 mm / "
                          "0.6 mm; 2.8x to 3.5x as printed)")
    assert rs[1].note == rs[2].note == ""


def test_select() -> None:
    assert {f.seed for f in select("all")} == set(paper_figures.SEEDS)
    assert all(f.seed == "seed003" for f in select("seed003"))
    with pytest.raises(BenchmarkError, match="seed004"):
        select("seed004")


def test_medians_use_the_order_statistic_interval_and_place_the_paper(tmp_path: Path
                                                                      ) -> None:
    rng = np.random.default_rng(3)
    x = rng.lognormal(0, 0.5, 100)
    rows = make_rows("leg-direction", x, np.ones(100, bool), np.full(100, 80),
                     scenario="andreff2005-noise", sweep={"noise_amplitude_deg": 0.05})
    d = write_run(tmp_path / "run", rows)
    fig = _fig(sweep={"noise_amplitude_deg": 0.05}, paper_trials=1)
    r = measure(fig, d, {})
    assert r.value == pytest.approx(np.median(x))
    ref = sps.quantile_test(x, p=0.5).confidence_interval(0.95)  # order statistics
    assert r.interval == pytest.approx((ref.low, ref.high))
    pct = 100 * np.mean(x <= 1.4)
    assert r.note == (f"{pct:.0f} % of the framework's 100 single trials are at or below "
                      "the paper's one-trial 1.4 mm")
    assert measure(replace(fig, paper_trials=None), d, {}).note == ""


def test_calibration_rows_compute_the_conditioning_they_are_explained_by(tmp_path: Path
                                                                         ) -> None:
    rows = make_rows("leg-direction", np.full(5, 2.0), np.ones(5, bool), np.full(5, 80),
                     scenario="andreff2005-noise", sweep={"noise_amplitude_deg": 0.05})
    for r, ratio in zip(rows, (0.01, 0.02, 0.015, 0.03, 0.011), strict=True):
        r["calibration_max_component_error_mm"] = 2.0
        r["calibration_min_singular_ratio"] = ratio
    d = write_run(tmp_path / "run", rows)
    fig = _fig(sweep={"noise_amplitude_deg": 0.05}, column="calibration_max_component_error_mm")
    # the median ratio 0.015: 1 / 0.015 = 66.7
    assert measure(fig, d, {}).note == (
        "smallest to largest singular value of a leg's calibration system 0.015 (median "
        "over calibrations): the noise is amplified about 67 times along its worst direction")


def test_one_task_studies_are_reported_as_repeatability(tmp_path: Path) -> None:
    conv = np.arange(20) < 17
    rows = (make_rows("leg-edge", np.ones(20), conv, np.full(20, 80), scenario="s")
            + make_rows("leg-direction", np.ones(20), ~conv, np.full(20, 80), scenario="s"))
    d = write_run(tmp_path / "run", rows)
    fig = _fig("converges", 100.0, 0.5, kind="claim", unit="%", statistic="rate",
               column="", controller="leg-edge", other="leg-direction", other_value=0.0)
    r = measure(fig, d, {})
    assert r.framework == "leg-edge 17/20, leg-direction 3/20 converged"
    assert r.note == ""  # no study record: not known to be one task
    (d / "run.json").write_text(json.dumps({"scenarios": {"s": {"study": {
        "task.kind": "fixed"}}}}))
    r = measure(fig, d, {})
    assert "one task (a fixed start and goal) repeated 20 times" in r.note
    verdicts([r])
    assert r.verdict == "contradicts"


@pytest.mark.slow
def test_reproduce_seed003_small(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(paper_figures.TRIALS, "tahri2009-convergence", (30, 20))
    figs = [f for f in builtin_figures() if f.study == "run:tahri2009-convergence"]
    res = reproduce("seed003", tmp_path, quick=True, say=lambda _t: None, figures=figs)
    assert [r.verdict for r in res] == ["within", "within"]
    assert all(r.n == 20 and r.value == 1.0 for r in res)
    # run again: the study is reused, not redone
    said: list[str] = []
    reproduce("seed003", tmp_path, quick=True, say=said.append, figures=figs)
    assert any("0 trials to run, 40 done" in s for s in said)
    # a directory of more trials than the scorecard plans: told in its words (it said
    # "give --trials 20 or more", an option reproduce does not take)
    from benchmarks.exceptions import StudyMismatchError

    monkeypatch.setitem(paper_figures.TRIALS, "tahri2009-convergence", (30, 10))
    with pytest.raises(StudyMismatchError) as info:
        reproduce("seed003", tmp_path, quick=True, say=lambda _t: None, figures=figs)
    assert ("trials: 20 in the directory, 10 planned by the scorecard with --quick (which "
            "takes no --trials") in str(info.value)
    assert "give --trials" not in str(info.value)


def test_a_calibration_of_other_settings_is_refused_before_any_study_runs(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A calibration directory is reused only for the same study: the same repetitions
    and settings (any calibration.json was reused as it was: a second call with more
    repetitions reported the first call's figures as its own); another one, or one that
    recorded no study, is refused naming the difference, before the run studies start."""
    from benchmarks.exceptions import StudyMismatchError

    monkeypatch.setattr("benchmarks.study.reproduce_runs.REPEATS", (2, 2))
    monkeypatch.setitem(paper_figures.TRIALS, "andreff2005-noise", (2, 2))
    figs = [f for f in builtin_figures() if f.seed == "seed001"]
    cal = [f for f in figs if f.study.startswith("calibrate:")]
    run = [f for f in figs if f.study == "run:andreff2005-noise"][:1]
    assert cal and run
    reproduce("seed001", tmp_path, quick=True, say=lambda _t: None, figures=cal)
    said: list[str] = []
    reproduce("seed001", tmp_path, quick=True, say=said.append, figures=cal)
    assert any("reusing" in s for s in said)  # the same study: reused
    said.clear()
    with pytest.raises(StudyMismatchError, match="--repeat: 2 in the directory, 3 given"):
        reproduce("seed001", tmp_path, quick=True, say=said.append, figures=[*run, *cal],
                  trials=3)
    assert said == [], "refused before the run study started"
    (d,) = tmp_path.glob("calibrate_*")
    doc = json.loads((d / "calibration.json").read_text())
    del doc["study"]  # written by an earlier version
    (d / "calibration.json").write_text(json.dumps(doc))
    with pytest.raises(StudyMismatchError, match="did not record its study"):
        reproduce("seed001", tmp_path, quick=True, say=lambda _t: None, figures=cal)


@pytest.mark.slow
def test_seed001_tail_statistics_from_the_records(tmp_path: Path,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    """The tail read from every trial's record agrees with the engine's tail median, and
    the tail maximum is printed against the tail's length."""
    monkeypatch.setitem(paper_figures.TRIALS, "andreff2005-noise", (3, 3))
    monkeypatch.setattr("benchmarks.study.reproduce_runs.REPEATS", (3, 3))
    md = tmp_path / "t.md"
    assert cli_main(["reproduce", "seed001", "--quick", "--out", str(tmp_path / "r"),
                     "--markdown", str(md)]) == 0
    d = tmp_path / "r" / "run_andreff2005-noise-quick"
    df = load(d)
    row = df[(df.controller == "leg-direction") & (df.point == 1)].iloc[0]
    with np.load(d / "trials" / f"andreff2005-noise__p1__leg-direction__"
                                f"{int(row.trial):05d}.npz") as rec:
        e = np.asarray(rec["position_error"]) * 1e3
    assert np.median(e[-100:]) == pytest.approx(row.tail_position_error_mm, rel=1e-9)
    text = md.read_text()
    assert text.count("| seed001 |") == 10
    assert "median tail maximum over the last 25 periods" in text
    assert "x its tail median (median over trials)" in text
    # the paper's ratio at 0.01 deg: 0.6 / 0.1, from 0.55 / 0.15 to 0.65 / 0.05
    assert "the paper's tail maximum is 6x its tail median (0.6 mm / 0.1 mm; 3.7x to 13x" \
        in text
    assert "final position error" not in text


def _calibration_dir(tmp_path: Path, err: np.ndarray) -> Path:
    (tmp_path / "calibration.json").write_text(json.dumps({"points": [
        {"sweep": {"noise.rotation_deg": 0.05}, "errors_mm": err.tolist()}]}))
    return tmp_path


def test_calibration_figures_are_over_calibrations_and_the_worst_point_is_simultaneous(
        tmp_path: Path) -> None:
    """30 calibrations of 6 points: the root-median-square figure is one number per
    calibration (as the paper's one calibration), its interval over the 30 (n = 30, not
    180 point errors); the worst point's interval holds whichever point is worst
    (Bonferroni over the 6 medians: scipy's quantile_test at 1 - 0.05 / 6)."""
    rng = np.random.default_rng(3)
    err = rng.lognormal(0.0, 0.5, (30, 6)) * np.array([1.0, 1.1, 0.9, 1.3, 1.25, 1.0])
    d = _calibration_dir(tmp_path, err)
    rms = _fig("1 mm", 1.0, statistic="calibration_rms_median", column="",
               sweep={"noise_rotation_deg": 0.05})
    r = measure(rms, d, {})
    per = np.sqrt(np.median(err ** 2, axis=1))
    ref = sps.quantile_test(per, p=0.5).confidence_interval(0.95)
    assert r.n == 30 and r.value == pytest.approx(np.median(per))
    assert r.interval == pytest.approx((ref.low, ref.high))
    worst = replace(rms, statistic="calibration_worst_point", rule="below", tolerance=0.0)
    w = measure(worst, d, {})
    meds = np.median(err, axis=0)
    ends = [sps.quantile_test(err[:, k], p=0.5).confidence_interval(1 - 0.05 / 6)
            for k in range(6)]
    assert w.value == pytest.approx(meds.max()) and f"(leg {int(np.argmax(meds))})" in \
        w.framework
    assert w.interval == pytest.approx((max(e.low for e in ends), max(e.high for e in ends)))
    assert "Bonferroni" in w.note


def test_the_sensitivity_default_gives_every_row_its_interval() -> None:
    """The worst of the six base points has a Bonferroni-corrected (99.17 %) interval of
    its median: at the former default of 6 trials it had no end inside the sample, so that
    row was never comparable; the default (8) is the fewest that give it both ends."""
    from benchmarks.study.exact import order_statistic_ranks
    from benchmarks.study.reproduce_cli import SENSITIVITY_TRIALS

    level = 1 - 0.05 / 6
    assert None in order_statistic_ranks(SENSITIVITY_TRIALS - 1, 0.5, level)
    assert None not in order_statistic_ranks(SENSITIVITY_TRIALS, 0.5, level)
    assert None not in order_statistic_ranks(6, 0.5, 0.95)  # (a plain median's: 6)


def test_a_refused_calibration_leaves_its_rows_not_comparable(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A setup whose camera sees a leg too poorly to calibrate (one point of a sensitivity
    grid) ended the whole study with an error after 11 minutes; its calibration rows are
    not comparable, with the reason, and the rest goes on."""
    from benchmarks.study import reproduce as rep
    from benchmarks.study.paper_figures import builtin_figures
    from vision.exceptions import CalibrationError

    figs = [f for f in builtin_figures() if f.study.startswith("calibrate:")][:2]
    assert figs

    def refuse(study: str, *args: object, **kwargs: object) -> Path:
        raise CalibrationError(4, "ill-conditioned (singular-value ratio 7.27e-04)")

    monkeypatch.setattr(rep, "run_study", refuse)
    results = rep.reproduce("all", tmp_path, True, figures=figs, say=lambda _t: None)
    assert [r.category for r in results] == ["not comparable"] * len(figs)
    assert all("the calibration was refused: " in r.verdict and "leg 4" in r.verdict
               for r in results), [r.verdict for r in results]


def test_a_run_study_whose_every_trial_failed_is_not_comparable(tmp_path: Path) -> None:
    """Every trial of a run study failed (each its own calibration refused, at a point of
    the sensitivity grid): its median and tail rows read a column or a record no trial
    wrote, and a KeyError (or 'record missing') ended the study."""
    import json

    from benchmarks.study import reproduce as rep
    from benchmarks.study.paper_figures import builtin_figures

    figs = [f for f in builtin_figures() if f.id in ("seed001-5.3-calibration-0.01",
                                                     "seed001-5.3-tail-max-0.01")]
    d = tmp_path / "run"
    d.mkdir()
    rows = [{"scenario": "s", "point": 0, "trial": k, "controller": "leg-direction",
             "backend": "sim", "converged": False, "steps": 0, "noise_amplitude_deg": 0.01,
             "failure": "CalibrationError: calibration: leg 4: ill-conditioned"}
            for k in range(3)]
    (d / "results.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    assert len(figs) == 2  # a median of a calibration column, a tail maximum
    results = [rep.measure(f, d, {}) for f in figs]
    rep.verdicts(results)
    for r in results:
        assert r.value is None and "every trial failed (CalibrationError" in r.framework
        assert r.category == "not comparable"


def test_trials_that_did_not_converge_are_not_failed_ones(tmp_path: Path) -> None:
    """A trial that ran its 500 steps without converging has a 'failure' text ('not
    converged: ...') yet ran to its end: its values count (reading every such trial as
    failed left a direction law's 0.1 deg rows 'no finite value' at 18 grid points)."""
    import json

    from benchmarks.study import reproduce as rep
    from benchmarks.study.paper_figures import builtin_figures

    fig = next(f for f in builtin_figures() if f.id == "seed001-5.3-calibration-0.01")
    d = tmp_path / "run"
    d.mkdir()
    rows = [{"scenario": "s", "point": 0, "trial": k, "controller": "leg-direction",
             "backend": "sim", "converged": False, "steps": 501, "noise_amplitude_deg": 0.01,
             fig.column: 0.1 * (k + 1),
             "failure": "not converged: rotation 0.239 deg > 0.2 deg after 500 steps"}
            for k in range(7)]
    (d / "results.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    r = rep.measure(fig, d, {})
    assert r.value == pytest.approx(0.4) and r.n == 7
