"""The report's tables carry intervals computed as the statistics module says."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from scipy import stats as sps

from benchmarks.study import stats
from benchmarks.study.report import write_report
from tests.benchmarks.study.helpers_rows import make_rows, write_run


def test_report_cells_have_intervals(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    err = rng.lognormal(-2, 0.4, 100)
    conv = np.arange(100) >= 6  # 94 of 100
    steps = rng.integers(60, 120, 100)
    rows = make_rows("leg-edge", err, conv, steps)
    for r, c in zip(rows, rng.uniform(0.1, 2.0, 100), strict=True):
        r["calibration_median_error_mm"] = float(c) / 3
        r["calibration_max_error_mm"] = float(c)
        r["calibration_max_component_error_mm"] = float(c) * 0.9
    out = write_run(tmp_path / "run", rows)
    text = write_report(out).read_text()
    row = next(line for line in text.splitlines() if line.startswith("| synthetic |"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    ci = sps.binomtest(94, 100).proportion_ci(method="wilson")
    assert cells[4] == f"94.0 % [{100 * ci.low:.1f}, {100 * ci.high:.1f}]"
    assert cells[5] == "0"  # failed: the trials that did not run to their end
    med, lo, hi = map(float, re.match(r"([\d.]+) \[([\d.]+), ([\d.]+)\]", cells[6]).groups())
    assert med == round(float(np.median(err)), 3)
    ref = sps.quantile_test(err, p=0.5).confidence_interval(0.95)
    assert (lo, hi) == (round(ref.low, 3), round(ref.high, 3))
    assert lo < med < hi
    # steps: every trial, the 6 that did not converge censored at the run's length
    censored = np.where(conv, steps, np.inf)
    ref = sps.quantile_test(censored, p=0.5).confidence_interval(0.95)
    steps_cell = re.match(r"([\d.]+) \[(\d+), (\d+)\]", cells[11])
    assert steps_cell is not None
    assert float(steps_cell.group(1)) == np.median(censored)  # a half kept: 98.5
    assert (int(steps_cell.group(2)), int(steps_cell.group(3))) == (ref.low, ref.high)
    assert "order-statistic" in text
    assert "Wilson" in text
    # the calibration table gives seed 001's measure beside the per-point norm
    cal = next(line for line in text.splitlines() if "max coordinate error mm" in line)
    assert "median error mm (per point)" in cal
    cal_row = text.splitlines()[text.splitlines().index(cal) + 2]
    comp = float(cal_row.strip("|").split("|")[4])
    assert comp == round(max(r["calibration_max_component_error_mm"] for r in rows), 3)


def test_link_images_and_visibility_tables_have_intervals(tmp_path: Path) -> None:
    """The robot link's and the image pipeline's medians carry their order-statistic intervals,
    the trials with a hidden edge their Wilson interval (docs/statistics.md: every table)."""
    rng = np.random.default_rng(3)
    err = rng.lognormal(-2, 0.4, 40)
    rows = make_rows("leg-edge", err, np.ones(40, bool), rng.integers(60, 120, 40))
    rtt = rng.uniform(1.0, 2.0, 40)
    det = rng.uniform(3.0, 5.0, 40)
    for k, r in enumerate(rows):
        r.update(rtt_median_ms=float(rtt[k]), rtt_p99_ms=float(rtt[k]) * 2,
                 missed_periods=0, detect_time_ms=float(det[k]),
                 hidden_edge_periods=3 if k < 10 else 0)
    text = write_report(write_run(tmp_path / "run", rows)).read_text()
    lines = text.splitlines()

    def row_after(header_start: str) -> list[str]:
        i = next(k for k, line in enumerate(lines) if line.startswith(header_start))
        return [c.strip() for c in lines[i + 2].strip("|").split("|")]

    link = row_after("| sweep | controller | backend | RTT median ms")
    lo, hi = sps.quantile_test(rtt, p=0.5).confidence_interval(0.95)
    assert link[3] == f"{np.median(rtt):.3f} [{lo:.3f}, {hi:.3f}]"
    images = row_after("| sweep | controller | detection median ms")
    lo, hi = sps.quantile_test(det, p=0.5).confidence_interval(0.95)
    assert images[2] == f"{np.median(det):.3f} [{lo:.3f}, {hi:.3f}]"
    seen = row_after("| sweep | controller | hidden-edge periods")
    assert seen[3] == f"10/40: {stats.format_rate(10, 40)}"


@pytest.mark.slow
def test_steps_median_censored_at_the_cap(tmp_path: Path) -> None:
    """A controller that converges on 8 of 20 trials (500 steps run): its median steps is
    censored, "> 500", not the median of its 8 successes (no survivorship)."""
    rng = np.random.default_rng(4)
    conv = np.arange(20) < 8
    steps = np.where(conv, rng.integers(100, 200, 20), 500)
    rows = make_rows("slow", rng.lognormal(-2, 0.4, 20), conv, steps)
    text = write_report(write_run(tmp_path / "run", rows)).read_text()
    row = next(line for line in text.splitlines() if line.startswith("| synthetic |"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    low = sps.quantile_test(np.where(conv, steps, np.inf), p=0.5).confidence_interval().low
    assert cells[11] == f"> 500 [{low:.0f}, > 500]"


def test_console_steps_median_is_censored_not_the_survivors() -> None:
    """The run's console table (Summary.steps_median): 8 of 20 converged, so the median
    steps is beyond the run, not the median of the 8 that converged."""
    from benchmarks.study.metrics import summarize
    from benchmarks.study.report import TABLE_HEADER, summary_table_rows

    conv = np.arange(20) < 8
    rows = make_rows("slow", np.full(20, 0.1), conv, np.where(conv, 150, 500))
    (s,) = summarize(rows)
    assert s.steps_median == np.inf
    (row,) = summary_table_rows([s])
    assert row[TABLE_HEADER.index("steps med")] == "> run"
    conv = np.arange(20) < 15  # 15 of 20: the median is known
    (s,) = summarize(make_rows("ok", np.full(20, 0.1), conv, np.where(conv, 150, 500)))
    assert s.steps_median == 150.0


def test_an_open_end_is_not_called_censored() -> None:
    """Three trials, all settled: the median's interval is open on both sides (too few
    trials at 95 %), printed -inf and inf, not '> run' (which says a censored trial, a
    trial that did not settle, ends it); with a censored value at the rank, '> run'."""
    from benchmarks.study.intervals import censored_median_cell

    assert censored_median_cell(np.array([0.1, 0.2, 0.3]), 3, "run") == "0.200 [-inf, inf]"
    x = np.r_[np.linspace(1.0, 2.0, 5), [np.inf] * 5]  # 5 of 10 settled
    lo, hi = sps.quantile_test(np.where(np.isinf(x), 99.0, x), p=0.5).confidence_interval()
    assert hi == 99.0  # (scipy's upper end is a censored trial's stand-in)
    assert censored_median_cell(x, 3, "run") == f"> run [{lo:.3f}, > run]"
    assert censored_median_cell(np.r_[[12.0] * 9, [np.inf]], 0, 500) == "12 [12, 12]"
    assert censored_median_cell(np.array([np.nan]), 0, 500) == "-"


def test_a_report_of_an_interrupted_run_says_it_is_incomplete() -> None:
    """Three controllers planned at 4 trials: one whole, one with 1 of 4, one without a
    row (a report of an interrupted run showed its tables as if whole); a whole run: no
    note."""
    from benchmarks.study.report import incomplete_lines

    study = {"trials": 4, "controllers": ["a", "b (gain=2.0)", "c (leg-edge, x=1)"]}
    rows = [{"point": 0, "controller": "a", "trial": k} for k in range(4)]
    rows += [{"point": 0, "controller": "b", "trial": 0}]
    (text, _) = incomplete_lines(study, rows)
    assert text.startswith("**Incomplete**: 5 of the 12 trials planned (4 per sweep point "
                           "and controller, 1 sweep point(s))")
    assert "missing 3 of b; no row of c" in text
    whole = rows + [{"point": 0, "controller": c, "trial": k} for c, ks in
                    (("b", range(1, 4)), ("c", range(4))) for k in ks]
    assert incomplete_lines(study, whole) == []
    # a swept study stopped before its third point: that point is counted and named (the
    # note said '8 of the 8 trials planned at the 2 sweep point(s) with rows')
    swept = {"trials": 2, "controllers": ["a"], "sweep.noise.amplitude_deg": [0, 0.05, 0.1]}
    rows2 = [{"point": p, "controller": "a", "trial": k} for p in (0, 1) for k in (0, 1)]
    (text, _) = incomplete_lines(swept, rows2)
    assert text.startswith("**Incomplete**: 4 of the 6 trials planned (2 per sweep point "
                           "and controller, 3 sweep point(s)); missing 2 of a; no row at "
                           "sweep point(s) 2"), text
