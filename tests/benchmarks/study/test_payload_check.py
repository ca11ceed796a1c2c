"""``check``'s payload facts (benchmarks.study.payload_check): the static leg forces grow
with the payload as the weight it adds, a static load beyond the drives' limit is warned
naming the leg, the peak along a reference is at least the static load."""

from __future__ import annotations

from pathlib import Path

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


def test_the_kinematic_world_has_no_facts() -> None:
    assert payload_facts(parse_scenario({**TABLE, "robot": {}}), samples=2) == []


def test_without_a_payload_the_robot_s_own_weight_is_checked(tmp_path: Path) -> None:
    """Drives too weak to hold the robot itself (5.5 N for about 8 N per leg), no
    [payload] table: check said nothing and every trial fell onto an end stop; the
    static load is now checked in every dynamic study, an error when no start holds."""
    from hexapod.geometry import deltalab

    plain = {k: v for k, v in TABLE.items() if k != "payload"}
    facts = payload_facts(parse_scenario(plain, "p.toml"), samples=3)
    assert len(facts) == 1 and facts[0].peak_n is None and not facts[0].problems
    assert 0 < facts[0].static_n.max() < 50 and facts[0].held == 1.0
    g = deltalab()
    weak = g.replace(drives=g.drives.replace(force_limit=np.full(6, 5.5),
                                             coulomb=np.full(6, 1.0)))
    weak.to_toml(tmp_path / "weak.toml")
    table = {**plain, "robot": {**plain["robot"], "geometry": str(tmp_path / "weak.toml")}}
    sc = parse_scenario(table, str(tmp_path / "p.toml"))
    facts = payload_facts(sc, samples=3)
    severities = [p.severity for p in facts[0].problems]
    assert severities == ["warning", "error"], facts[0].problems
    assert "the robot's own weight alone (no payload) exceeds" in facts[0].problems[0].text
    assert "no controller can hold the platform where a trial starts" in facts[0].problems[1].text
    assert "Static load (the robot's own weight" in "\n".join(describe_payload(facts, sc))


def test_a_payload_centre_of_mass_off_the_platform_is_warned_of() -> None:
    """A centre of mass 3 m from the platform's axis (metres in a millimetre key) or
    below the base plane was taken without a word."""
    for com, text in (([3000.0, 0.0, 0.0], "3000 mm from the platform's axis, beyond its"),
                      ([0.0, 0.0, -600.0], "below the base plane at home")):
        table = {**TABLE, "payload": {"mass_kg": 1.0, "com_mm": com}}
        problems = [p for f in payload_facts(parse_scenario(table, "p.toml"), samples=2)
                    for p in f.problems]
        assert any(text in p.text and p.severity == "warning" for p in problems), problems
    ok = payload_facts(parse_scenario({**TABLE, "payload": {"mass_kg": 1.0}}, "p.toml"),
                       samples=2)
    assert not [p for f in ok for p in f.problems]
