"""``check``'s payload facts (benchmarks.study.payload_check): the static leg forces grow
with the payload as the weight it adds, a static load beyond the drives' limit is warned
naming the leg, the peak along a reference is at least the static load."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.study.payload_check import describe_payload, payload_facts
from benchmarks.study.scenario import parse_scenario

TABLE = {"name": "t", "controllers": ["leg-edge"], "trials": 3,
         "robot": {"world": "dynamic", "physics_dt": 0.001},
         "payload": {"mass_kg": [0.0, 10.0, 150.0]},
         "task": {"kind": "trajectory", "shape": "circle", "radius_mm": 10.0,
                  "speed_mm_s": 100.0, "acceleration_mm_s2": 2000.0, "margin_mm": 15.0,
                  "max_translation_mm": 20.0, "max_steps": 100}}


@pytest.mark.slow
def test_static_and_peak_forces_with_the_payload() -> None:
    sc = parse_scenario(TABLE, "p.toml")
    facts = payload_facts(sc, samples=3)
    assert [f.mass_kg for f in facts] == [0.0, 10.0, 150.0]
    # 10 kg more weight: the six legs' vertical components carry 98.1 N more together,
    # so the largest leg force grows by at least a sixth of it
    assert facts[1].static_n.max() - facts[0].static_n.max() > 98.1 / 6
    for f in facts:
        assert f.peak_n is not None and np.all(f.peak_n >= f.static_n * (1 - 1e-9))
    assert not facts[0].problems and not facts[1].problems
    (problem,) = facts[2].problems
    assert problem.severity == "warning" and "static load alone exceeds" in problem.text
    assert "150 kg" in problem.text and "p.toml" in problem.text and "leg " in problem.text
    text = "\n".join(describe_payload(facts, sc))
    assert "150 kg: static" in text and "beyond the limit" in text


@pytest.mark.parametrize("table", [{k: v for k, v in TABLE.items() if k != "payload"},
                                   {**TABLE, "robot": {}}])
def test_no_payload_or_kinematic_world_no_facts(table: dict) -> None:
    assert payload_facts(parse_scenario(table), samples=2) == []
