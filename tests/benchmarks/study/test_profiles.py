"""Dolan-Moré performance profiles against a hand-computed case."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from benchmarks.study.profiles import cost_table, profile, ratios
from benchmarks.study.report import write_report
from tests.benchmarks.study.helpers_rows import two_controllers, write_run


def test_profile_hand_computed() -> None:
    inf = np.inf
    # 4 problems x 3 controllers; problem 3: every controller failed
    t = np.array([[10.0, 20.0, 10.0],
                  [30.0, 15.0, inf],
                  [8.0, 8.0, 32.0],
                  [inf, inf, np.nan]])
    r = ratios(t)
    expected = np.array([[1.0, 2.0, 1.0],
                         [2.0, 1.0, inf],
                         [1.0, 1.0, 4.0],
                         [inf, inf, inf]])
    assert np.array_equal(r, expected)
    rho = profile(r, np.array([1.0, 2.0, 4.0, 1e9]))
    #            tau:  1     2     4     1e9
    assert np.allclose(rho, [[0.5, 0.75, 0.75, 0.75],
                             [0.5, 0.75, 0.75, 0.75],
                             [0.25, 0.25, 0.5, 0.5]])


@pytest.mark.slow
def test_cost_table_failures_and_report_figure(tmp_path: Path) -> None:
    rows = two_controllers(50, worse_by=1.2, worse_fails=5)
    ctrls, costs = cost_table(rows, "steps")
    assert ctrls == ["bad", "good"]
    assert costs.shape == (50, 2)
    assert np.isinf(costs[:5, 0]).all() and np.isfinite(costs[:, 1]).all()
    r = ratios(costs)
    # good is the best on every trial (bad has 7 more steps or failed)
    rho = profile(r, np.array([1.0]))
    assert rho[1, 0] == 1.0 and rho[0, 0] == 0.0
    out = write_run(tmp_path / "run", rows)
    text = write_report(out).read_text()
    assert "![performance profiles](synthetic_profiles.png)" in text
    assert (out / "synthetic_profiles.png").stat().st_size > 10_000
