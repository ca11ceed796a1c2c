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
