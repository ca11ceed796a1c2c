"""The ``[payload]`` table of a scenario and ``[calibration_error] payload_mass_percent``:
parsed and swept, refused naming the key, fixed to every trial's true platform, the
controllers' model off by the given percentage, and no payload (or a zero mass) changing
not a bit of a trial's world."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.exceptions import ScenarioError
from benchmarks.sim import load_camera, load_geometry, make_trial
from benchmarks.study.preflight import preflight
from benchmarks.study.scenario import parse_scenario

MINIMAL = {"name": "t", "controllers": ["leg-edge"],
           "robot": {"world": "dynamic", "physics_dt": 0.001}}
TOOL = {"mass_kg": 4.0, "com_mm": [10.0, 0.0, -40.0],
        "inertia_kg_m2": [0.012, 0.012, 0.006, 0.0, 0.0, 0.0]}


def _setups(table: dict, n: int = 3) -> list:
    sc = parse_scenario(table)
    nominal = load_geometry(sc)
    camera = load_camera(sc, nominal)
    return [make_trial(sc, k, nominal, camera) for k in range(n)]


def test_payload_is_swept_and_loads_every_true_platform() -> None:
    sc = parse_scenario({**MINIMAL, "payload": {**TOOL, "mass_kg": [0.0, 4.0, 8.0]}})
    points = sc.expand()
    assert [p.payload.mass_kg for p in points] == [0.0, 4.0, 8.0]
    assert [p.sweep for p in points] == [{"payload.mass_kg": m} for m in (0.0, 4.0, 8.0)]
    bare = _setups(MINIMAL)
    for point, mass in zip(points, (0.0, 4.0, 8.0), strict=True):
        nominal = load_geometry(point)
        camera = load_camera(point, nominal)
        for a, b in zip(bare, [make_trial(point, k, nominal, camera) for k in range(3)],
                        strict=True):
            true = b.world.geometry.inertia
            assert true.platform_mass == pytest.approx(a.world.geometry.inertia.platform_mass
                                                       + mass, rel=1e-14)
            if mass:  # the platform's centre of mass moves towards the tool's
                assert true.platform_com[2] == pytest.approx(
                    -0.040 * mass / (mass + 2.0), rel=1e-12)
            assert b.nominal_geometry.inertia == true  # an exact model by default
            np.testing.assert_array_equal(a.start_translation, b.start_translation)


def test_no_payload_and_zero_mass_change_nothing() -> None:
    bare = _setups(MINIMAL)
    zero = _setups({**MINIMAL, "payload": {**TOOL, "mass_kg": 0.0}})
    for a, b in zip(bare, zero, strict=True):
        assert b.world.geometry.inertia == a.world.geometry.inertia
        assert b.nominal_geometry.inertia == a.nominal_geometry.inertia


@pytest.mark.parametrize("error", [-100.0, -20.0, 50.0])
def test_model_payload_mass_is_off_by_the_percentage(error: float) -> None:
    table = {**MINIMAL, "payload": TOOL,
             "calibration_error": {"payload_mass_percent": error, "scale": 3.0}}
    for s in _setups(table):
        true, model = s.world.geometry.inertia, s.nominal_geometry.inertia
        assert true.platform_mass == pytest.approx(2.0 + 4.0, rel=1e-14)
        assert model.platform_mass == pytest.approx(2.0 + 4.0 * (1 + error / 100), rel=1e-14)
        assert s.shared  # the true world is the nominal one: the trials batch


@pytest.mark.parametrize(("payload", "key", "words"), [
    ({**TOOL, "com_mm": [1.0, 2.0]}, "payload.com_mm", "3 numbers"),
    ({**TOOL, "inertia_kg_m2": [0.1, 0.1]}, "payload.inertia_kg_m2", "6 numbers"),
    ({**TOOL, "inertia_kg_m2": [0.01, 0.01, 0.05, 0, 0, 0]}, "payload.inertia_kg_m2",
     "triangle"),
    ({**TOOL, "mass_kg": [4.0, -1.0]}, "payload.mass_kg", "range"),
    ({**TOOL, "mas_kg": 1.0}, "payload.mas_kg", "unknown key"),
])
def test_impossible_payload_refused_naming_the_key(payload: dict, key: str, words: str
                                                   ) -> None:
    with pytest.raises(ScenarioError) as info:
        parse_scenario({**MINIMAL, "payload": payload}, "s.toml")
    assert info.value.key == key and words in str(info.value) and "s.toml" in str(info.value)


def test_payload_in_the_kinematic_world_refused() -> None:
    sc = parse_scenario({"name": "t", "controllers": ["leg-edge"], "payload": TOOL}, "k.toml")
    with pytest.raises(ScenarioError) as info:
        preflight([sc], measure=False)
    assert info.value.key == "payload" and "dynamic" in str(info.value)
