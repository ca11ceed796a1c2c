"""``benchmarks.sim.book``: a fixed-duration task's tail errors are the medians of the
errors of its last fifth of periods, the recorded series' (both engines' rows)."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.sim import run_trials
from benchmarks.study.scenario import parse_scenario


@pytest.mark.parametrize("engine", ["batched", "per-trial"])
def test_the_tail_errors_are_the_medians_of_the_last_fifth(engine: str) -> None:
    sc = parse_scenario({
        "name": "tail", "seed": 5, "trials": 3, "controllers": ["joint-space"],
        "controller_options": {"gain": 2.0},
        "task": {"kind": "random-pairs", "fixed_duration": True, "max_steps": 42}})
    results = run_trials(sc, 0, [0, 1, 2], record_trials=3, engine=engine)
    tail = sc.task.max_steps // 5
    for res in results:
        row, ser = res.row, res.series
        assert ser is not None and len(ser["position_error"]) == sc.task.max_steps + 1
        assert row["tail_position_error_mm"] == float(
            np.median(ser["position_error"][-tail:]) * 1e3)
        assert row["tail_orientation_error_deg"] == float(
            np.rad2deg(np.median(ser["orientation_error"][-tail:])))
        assert row["tail_position_error_mm"] > 0.0  # (a slow law: still moving)
