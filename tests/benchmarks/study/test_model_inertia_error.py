"""The controllers' model's systematic inertial errors (``[calibration_error]
model_mass_error_percent`` / ``model_inertia_error_percent``): the true robot is the robot
file's divided by ``1 + e / 100`` (what the controllers are told stays the file's), the
keys are checked and not multiplied by ``scale``, the other draws are unchanged, and the
sign means what it says on the dynamic world: computed torque with a model too light
lets the platform sag under gravity, with a model too heavy lifts it."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.exceptions import ScenarioError
from benchmarks.sim import load_camera, load_geometry, make_trial, run_trials
from benchmarks.study.scenario import load_scenario, parse_scenario

MINIMAL = {"name": "t", "controllers": ["leg-edge"]}
KEYS = ("model_mass_error_percent", "model_inertia_error_percent")


def _setups(table: dict, n: int = 5) -> list:
    sc = parse_scenario(table)
    nominal = load_geometry(sc)
    camera = load_camera(sc, nominal)
    return [make_trial(sc, k, nominal, camera) for k in range(n)]


@pytest.mark.parametrize(("mass", "inertia"), [(30.0, 0.0), (-30.0, 20.0), (0.0, -45.0)])
def test_the_true_robot_is_the_model_divided_by_the_error(mass: float, inertia: float) -> None:
    """Every trial's true masses are the file's / (1 + e_m/100) and its rotational
    inertias the file's / (1 + e_i/100), the same for every trial, whatever ``scale``;
    the controllers' nominal geometry keeps the file's; the poses and the geometric
    errors drawn are those without the inertial error."""
    geometric = {"base_points_mm": 1.0, "joint_offsets_mm": 0.5}
    plain = _setups({**MINIMAL, "calibration_error": geometric})
    drawn = _setups({**MINIMAL, "calibration_error": {
        **geometric, "scale": 3.0, "model_mass_error_percent": mass,
        "model_inertia_error_percent": inertia}})
    fm, fi = 1.0 + mass / 100.0, 1.0 + inertia / 100.0
    for a, b in zip(plain, drawn, strict=True):
        file_inertia = b.nominal_geometry.inertia
        assert file_inertia == a.nominal_geometry.inertia  # the controllers' model
        true = b.world.geometry.inertia
        for key in ("platform_mass", "body_mass", "rod_mass"):
            assert getattr(file_inertia, key) == pytest.approx(fm * getattr(true, key),
                                                              rel=1e-12), key
        for key in ("platform_inertia", "body_inertia", "rod_inertia"):
            np.testing.assert_allclose(np.asarray(getattr(file_inertia, key)),
                                       fi * np.asarray(getattr(true, key)), rtol=1e-12)
        np.testing.assert_array_equal(a.start_rotation, b.start_rotation)
        # scale 3 multiplies the standard deviations, not the model's error
        np.testing.assert_allclose(
            b.world.geometry.base_points - b.nominal_geometry.base_points,
            3.0 * (a.world.geometry.base_points - a.nominal_geometry.base_points), rtol=1e-12)
        np.testing.assert_array_equal(b.world.geometry.drives.rotor_inertia,
                                      a.world.geometry.drives.rotor_inertia)


def test_an_error_alone_makes_the_world_differ_from_the_model() -> None:
    (s,) = _setups({**MINIMAL, "calibration_error": {"model_mass_error_percent": 10.0}}, 1)
    assert s.world.geometry.inertia.platform_mass == pytest.approx(
        s.nominal_geometry.inertia.platform_mass / 1.1)
    np.testing.assert_array_equal(s.world.geometry.base_points,
                                  s.nominal_geometry.base_points)


@pytest.mark.parametrize("key", KEYS)
@pytest.mark.parametrize(("value", "fragment"), [(-60.0, "out of the allowed range"),
                                                 (150.0, "out of the allowed range"),
                                                 ("ten", "expected a number")])
def test_bad_values_name_the_file_and_key(key: str, value: object, fragment: str) -> None:
    with pytest.raises(ScenarioError) as info:
        parse_scenario({**MINIMAL, "calibration_error": {key: value}}, "err.toml")
    text = str(info.value)
    assert "err.toml" in text and f"calibration_error.{key}" in text and fragment in text, text


def test_the_builtin_study_sweeps_both_errors() -> None:
    sc = load_scenario("inertia-error")
    assert sc.world == "dynamic"
    points = [(p.calibration_error.model_mass_error_percent,
               p.calibration_error.model_inertia_error_percent) for p in sc.expand()]
    assert sorted(points) == [(m, i) for m in (-30.0, 0.0, 30.0) for i in (-30.0, 0.0, 30.0)]


def test_computed_torque_sags_with_a_light_model_and_rises_with_a_heavy_one() -> None:
    """At rest after a small move, computed torque (no integral action) holds the
    platform where its leg stiffness balances the gravity its model gets wrong: a model
    30 % too light (true robot 1/0.7 times heavier) leaves it below the goal, one 30 %
    too heavy above; the exact model holds it within 0.1 mm. The mismatches are
    0.43 and 0.23 of the modelled weight: the light model's sag is the larger."""
    sc = parse_scenario({
        "name": "sag", "seed": 3, "trials": 1, "controllers": ["computed-torque"],
        "robot": {"world": "dynamic"},
        "calibration_error": {"model_mass_error_percent": [-30.0, 0.0, 30.0]},
        "task": {"kind": "random-pairs", "max_translation_mm": 5.0, "max_angle_deg": 1.0,
                 "max_steps": 150, "fixed_duration": True}})
    dz = {}
    for p in sc.expand():
        (res,) = run_trials(p, 0, [0], record_trials=1)
        assert res.series is not None
        dz[p.calibration_error.model_mass_error_percent] = float(
            res.series["translations"][-1][2] - res.series["goal_translation"][2])
    assert abs(dz[0.0]) < 1e-4
    assert dz[-30.0] < -1e-3 and dz[30.0] > 1e-3
    assert abs(dz[-30.0]) > 1.5 * abs(dz[30.0])
