"""hexapod-bench reproduce: verdict rules, and small runs of two papers' studies."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy import stats as sps

from benchmarks.cli import main as cli_main
from benchmarks.exceptions import BenchmarkError
from benchmarks.study import load, paper_figures
from benchmarks.study.paper_figures import Figure
from benchmarks.study.reproduce import Result, _half_unit, reproduce, select, verdicts


def test_half_unit_of_printed_figures() -> None:
    assert _half_unit("0.6 mm") == pytest.approx(0.05)
    assert _half_unit("10 mm") == pytest.approx(0.5)
    assert _half_unit("1.2 cm") == pytest.approx(0.5)  # in mm
    assert _half_unit("< 1 mm") == pytest.approx(0.5)


def _fig(paper: str, value: float, relation: str = "equal", measure: str = "median:x"
         ) -> Figure:
    return Figure("seed001", "sec", "q", paper, value, relation, "run:s", measure,
                  why_outside="because")


def test_verdict_rules() -> None:
    rs = [
        Result(_fig("0.6 mm", 0.6), "", 0.52, (0.50, 0.56), 30),   # meets [0.55, 0.65]
        Result(_fig("0.6 mm", 0.6), "", 0.45, (0.40, 0.54), 30),   # below it
        Result(_fig("3 mm", 3.0), "", 3.6, None, 30),              # max: value vs [2.5, 3.5]
        Result(_fig("< 1 mm", 1.0, "below"), "", 0.9, (0.8, 0.99), 30),
        Result(_fig("< 1 mm", 1.0, "below"), "", 0.9, (0.8, 1.01), 30),
        Result(_fig("100 %", 1.0, measure="rate:converged"), "", 1.0, (0.9996, 1.0), 10000),
        Result(_fig("100 %", 1.0, measure="rate:converged"), "", 0.98, (0.97, 0.99), 1000),
    ]
    verdicts(rs)
    assert [r.verdict for r in rs] == ["within", "outside (lower)", "outside (higher)",
                                       "within", "outside (higher)", "within",
                                       "outside (lower)"]
    assert [bool(r.why) for r in rs] == [False, True, True, False, True, False, True]


def test_paired_verdicts_are_holm_corrected() -> None:
    better = _fig("edge better", 0.0, "better")
    rs = [Result(better, "", -1.0, (-2.0, -0.5), 20, "better", 0.02),
          Result(better, "", -1.0, (-2.0, -0.5), 20, "better", 0.03),
          Result(better, "", 1.0, (0.5, 2.0), 20, "worse", 1e-6)]
    verdicts(rs)
    # Holm: 1e-6 * 3, 0.02 * 2 = 0.04, 0.03 * 1 -> max(0.04, 0.03) = 0.04
    assert rs[0].verdict == "within (Holm p = 0.04)"
    assert rs[1].verdict == "within (Holm p = 0.04)"
    assert rs[2].verdict.startswith("outside (not found better")


def test_select() -> None:
    assert {f.seed for f in select("all")} == set(paper_figures.SEEDS)
    assert all(f.seed == "seed003" for f in select("seed003"))
    with pytest.raises(BenchmarkError, match="seed004"):
        select("seed004")


def test_reproduce_seed003_small(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(paper_figures.TRIALS, "tahri2009-convergence", (30, 20))
    res = reproduce("seed003", tmp_path, quick=True, say=lambda _t: None)
    assert [r.verdict for r in res] == ["within", "within"]
    assert all(r.n == 20 and r.value == 1.0 for r in res)
    # run again: the study is reused, not redone
    said: list[str] = []
    reproduce("seed003", tmp_path, quick=True, say=said.append)
    assert any("0 trials to run, 40 done" in s for s in said)


@pytest.mark.slow
def test_seed001_tail_statistics_from_the_records(tmp_path: Path,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    """The tail read from every trial's record agrees with the engine's tail median."""
    monkeypatch.setitem(paper_figures.TRIALS, "andreff2005-noise", (3, 3))
    monkeypatch.setattr("benchmarks.study.reproduce.REPEATS", (3, 3))
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
    assert text.count("| seed001 |") == 13
    assert "max error on any coordinate of any base point" in text


def test_single_trial_figures_use_the_range_of_single_trials(tmp_path: Path) -> None:
    from benchmarks.study.reproduce import measure
    from tests.benchmarks.study.helpers_rows import make_rows, write_run

    rng = np.random.default_rng(3)
    x = rng.lognormal(0, 0.5, 100)
    rows = make_rows("leg-direction", x, np.ones(100, bool), np.full(100, 80),
                     scenario="andreff2005-noise", sweep={"noise_amplitude_deg": 0.05})
    d = write_run(tmp_path / "run", rows)
    base = dict(seed="seed001", where="s", quantity="q", paper="1.4 mm", value=1.4,
                relation="equal", study="run:andreff2005-noise",
                measure="median:final_position_error_mm",
                sweep={"noise_amplitude_deg": 0.05}, controller="leg-direction")
    one = measure(Figure(**base, single=True), d, {})
    many = measure(Figure(**base), d, {})
    assert one.value == many.value == pytest.approx(np.median(x))
    assert one.interval == pytest.approx(tuple(np.percentile(x, [2.5, 97.5])))
    ref = sps.quantile_test(x, p=0.5).confidence_interval(0.95)  # order statistics
    assert many.interval == pytest.approx((ref.low, ref.high))
    assert one.interval[1] - one.interval[0] > 3 * (many.interval[1] - many.interval[0])
