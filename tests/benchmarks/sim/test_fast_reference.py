"""The fast trajectory keys of ``[task]``: the ``s-curve`` profile with ``jerk_mm_s3`` and
``peak_acceleration_mm_s2`` (swept) reach each trial's reference as the scenario says,
in SI units."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.exceptions import ScenarioError
from benchmarks.sim import load_camera, load_geometry, make_trial
from benchmarks.sim.reference import trial_reference
from benchmarks.study.scenario import parse_scenario

TASK = {"kind": "trajectory", "shape": "lemniscate", "profile": "s-curve", "radius_mm": 12.0,
        "speed_mm_s": 200.0, "acceleration_mm_s2": 4000.0, "jerk_mm_s3": 80_000.0,
        "max_translation_mm": 20.0, "margin_mm": 20.0}


def test_peak_acceleration_swept_reaches_the_reference() -> None:
    sc = parse_scenario({"name": "t", "controllers": ["leg-edge"],
                         "task": {**TASK, "peak_acceleration_mm_s2": [5000.0, 20000.0]}})
    points = sc.expand()
    durations = []
    for point, peak in zip(points, (5.0, 20.0), strict=True):
        nominal = load_geometry(point)
        ref = trial_reference(point, make_trial(point, 0, nominal, load_camera(point, nominal)))
        assert ref is not None and ref.profile == "s-curve" and ref.jerk == 80.0
        t = np.linspace(0.0, ref.duration, 50_001)
        reached = np.linalg.norm(ref.at(t).acceleration, axis=1).max()
        assert peak * (1 - 1e-4) <= reached <= peak * (1 + 1e-9)
        durations.append(ref.duration)
    assert durations[1] == pytest.approx(durations[0] / 2, rel=1e-12)  # 4x the acceleration


def test_jerk_out_of_range_refused() -> None:
    with pytest.raises(ScenarioError) as info:
        parse_scenario({"name": "t", "controllers": ["leg-edge"],
                        "task": {**TASK, "jerk_mm_s3": 0.0}}, "s.toml")
    assert info.value.key == "task.jerk_mm_s3"


def test_check_warns_a_reference_faster_than_the_legs() -> None:
    """A circle scaled to 2 m/s^2 moves the legs faster than deltalab's 50 mm/s: check
    warns naming the speed and the keys; at 40 mm/s it does not."""
    from benchmarks.study.trajectory_check import trajectory_facts

    task = {"kind": "trajectory", "shape": "circle", "radius_mm": 10.0, "speed_mm_s": 40.0,
            "margin_mm": 15.0, "max_translation_mm": 20.0, "max_steps": 400}
    slow, fast = (trajectory_facts(parse_scenario(
        {"name": "t", "controllers": ["leg-edge"], "task": {**task, **extra}}, "x.toml"),
        samples=3)[0] for extra in ({}, {"peak_acceleration_mm_s2": 2000.0}))
    assert 0 < slow.leg_speed_mm_s < 50.0 and not slow.problems
    assert fast.leg_speed_mm_s > 50.0 and fast.max_speed_mm_s == 50.0
    (problem,) = fast.problems
    assert "above the robot's leg speed limit 50 mm/s" in problem.text
    assert "peak_acceleration_mm_s2" in problem.text and "x.toml" in problem.text
