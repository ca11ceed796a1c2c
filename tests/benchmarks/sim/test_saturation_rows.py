"""The saturation columns of the dynamic world's rows: only with a ``[payload]`` (the other
scenarios' rows keep their columns), each leg's time at its limit within the trial's
(any leg's), the fractions of the time run, the error while saturated on the periods that
saturated; and a heavier payload saturates more."""

from __future__ import annotations

import pytest

from benchmarks.sim import run_trials
from benchmarks.sim.dynamic_plant import SATURATION_COLUMNS
from benchmarks.study.scenario import parse_scenario

TABLE = {"name": "t", "controllers": ["computed-torque"], "seed": 5,
         "robot": {"world": "dynamic", "physics_dt": 0.001},
         "task": {"kind": "trajectory", "shape": "circle", "radius_mm": 10.0,
                  "speed_mm_s": 40.0, "acceleration_mm_s2": 1000.0, "profile": "s-curve",
                  "jerk_mm_s3": 50000.0, "max_translation_mm": 20.0, "margin_mm": 20.0,
                  "max_steps": 60}}
EXTRA = (*SATURATION_COLUMNS, "saturated_periods", "tracking_saturated_rms_mm",
         "tracking_saturated_max_mm")


@pytest.mark.slow
def test_saturation_columns_with_a_payload_only() -> None:
    bare = parse_scenario(TABLE)
    (plain,) = run_trials(bare, 0, [0])
    assert not set(EXTRA) & set(plain.row)
    points = parse_scenario({**TABLE, "payload": {"mass_kg": [0.0, 68.0],
                                                  "com_mm": [0.0, 0.0, -50.0]}}).expand()
    rows = [run_trials(p, 0, [0])[0].row for p in points]
    for key in EXTRA:
        assert all(key in r for r in rows), key
    zero, heavy = rows
    # the same trial without payload and with a zero payload: the same figures
    assert zero["tracking_rms_position_mm"] == plain.row["tracking_rms_position_mm"]
    assert zero["saturation_time_s"] == 0.0 and zero["saturated_periods"] == 0
    assert zero["tracking_saturated_rms_mm"] is None
    # (60 periods end mid-reference: "not converged" to the goal, no end stop)
    assert str(heavy["failure"]).startswith("not converged")
    assert heavy["saturation_time_s"] > 0
    legs = heavy["saturation_legs_s"]
    assert len(legs) == 6 and max(legs) > 0
    assert all(x <= heavy["saturation_time_s"] + 1e-12 for x in legs)
    run = 60 * 0.02
    assert heavy["saturation_fraction"] == pytest.approx(heavy["saturation_time_s"] / run)
    assert heavy["saturation_legs_fraction"] == pytest.approx([x / run for x in legs])
    assert 0 < heavy["saturated_periods"] <= 60
    assert heavy["tracking_saturated_max_mm"] >= heavy["tracking_saturated_rms_mm"] > 0
