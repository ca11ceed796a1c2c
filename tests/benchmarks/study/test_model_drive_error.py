"""The controllers' model's systematic drive errors (``[calibration_error]``
``model_friction_error_percent``, ``model_rotor_inertia_error_percent``,
``model_drive_bandwidth_error_percent``): the model a controller receives (the robot
file's drives) is the true robot's times ``1 + e / 100``, exactly; the keys are checked,
not multiplied by ``scale``, and leave the other draws as they were."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.exceptions import ScenarioError
from benchmarks.sim import load_camera, load_geometry, make_trial
from benchmarks.study.scenario import parse_scenario

MINIMAL = {"name": "t", "controllers": ["leg-edge"]}
KEYS = {"model_friction_error_percent": ("viscous", "coulomb"),
        "model_rotor_inertia_error_percent": ("rotor_inertia",),
        "model_drive_bandwidth_error_percent": ("velocity_bandwidth",)}


def _setups(table: dict, n: int = 3) -> list:
    sc = parse_scenario(table)
    nominal = load_geometry(sc)
    camera = load_camera(sc, nominal)
    return [make_trial(sc, k, nominal, camera) for k in range(n)]


@pytest.mark.parametrize("key", sorted(KEYS))
@pytest.mark.parametrize("error", [30.0, -25.0])
def test_the_model_is_the_truth_times_the_factor(key: str, error: float) -> None:
    geometric = {"base_points_mm": 1.0}
    plain = _setups({**MINIMAL, "calibration_error": geometric})
    drawn = _setups({**MINIMAL, "calibration_error": {**geometric, "scale": 2.0, key: error}})
    factor = 1.0 + error / 100.0
    for a, b in zip(plain, drawn, strict=True):
        model, true = b.nominal_geometry.drives, b.world.geometry.drives
        assert model == a.nominal_geometry.drives  # the controllers keep the file's
        for field in ("viscous", "coulomb", "rotor_inertia", "velocity_bandwidth"):
            expected = factor if field in KEYS[key] else 1.0
            np.testing.assert_allclose(getattr(model, field), expected * getattr(true, field),
                                       rtol=1e-12, err_msg=field)
            if field not in KEYS[key]:
                np.testing.assert_array_equal(getattr(true, field),
                                              getattr(a.world.geometry.drives, field))
        # the other draws are unchanged (scale multiplies the std, not the model's error)
        np.testing.assert_allclose(
            b.world.geometry.base_points - b.nominal_geometry.base_points,
            2.0 * (a.world.geometry.base_points - a.nominal_geometry.base_points), rtol=1e-12)
        np.testing.assert_array_equal(a.start_rotation, b.start_rotation)
        assert true.mode == model.mode


def test_an_error_alone_makes_the_world_differ() -> None:
    (s,) = _setups({**MINIMAL, "calibration_error": {"model_friction_error_percent": 25.0}},
                   1)
    assert s.world.geometry.drives.viscous[0] == pytest.approx(
        s.nominal_geometry.drives.viscous[0] / 1.25)
    np.testing.assert_array_equal(s.world.geometry.base_points, s.nominal_geometry.base_points)


def test_the_keys_sweep() -> None:
    sc = parse_scenario({**MINIMAL, "calibration_error": {
        "model_drive_bandwidth_error_percent": [-20.0, 0.0, 50.0]}})
    assert [p.calibration_error.model_drive_bandwidth_error_percent
            for p in sc.expand()] == [-20.0, 0.0, 50.0]


@pytest.mark.parametrize("key", sorted(KEYS))
@pytest.mark.parametrize(("value", "fragment"), [(-60.0, "out of the allowed range [-50, 100]"),
                                                 (101.0, "out of the allowed range"),
                                                 ("ten", "expected a number")])
def test_bad_values_name_the_file_key_and_range(key: str, value: object, fragment: str
                                                 ) -> None:
    with pytest.raises(ScenarioError) as info:
        parse_scenario({**MINIMAL, "calibration_error": {key: value}}, "err.toml")
    text = str(info.value)
    assert "err.toml" in text and f"calibration_error.{key}" in text and fragment in text, text
