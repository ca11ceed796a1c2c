"""``[robot] model``: the controllers' inertia and drives from another robot file, the
world's truth unchanged."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from benchmarks.exceptions import ScenarioError
from benchmarks.sim import load_camera, load_geometry, make_trial
from benchmarks.study.scenario import load_scenario
from hexapod.geometry import preset


def _write(tmp_path: Path, model: str | None) -> Path:
    text = ('name = "t"\ncontrollers = ["leg-edge"]\n[robot]\npreset = "deltalab"\n'
            'world = "dynamic"\n' + (f'model = "{model}"\n' if model else "")
            + '[calibration_error]\nmodel_mass_error_percent = -30.0\n')
    path = tmp_path / "study.toml"
    path.write_text(text)
    return path


def test_the_model_file_feeds_the_controllers_only(tmp_path: Path) -> None:
    g = preset("deltalab")
    heavy = g.replace(inertia=g.inertia.replace(platform_mass=3.3),
                      drives=g.drives.replace(viscous=np.full(6, 61.0)))
    heavy.to_toml(tmp_path / "identified.toml")
    setups = []
    for model in (None, "identified.toml"):
        sc = load_scenario(str(_write(tmp_path, model)))
        nominal = load_geometry(sc)
        setups.append(make_trial(sc, 0, nominal, load_camera(sc, nominal)))
    plain, modelled = setups
    assert modelled.nominal_geometry.inertia.platform_mass == 3.3
    np.testing.assert_array_equal(modelled.nominal_geometry.drives.viscous, 61.0)
    np.testing.assert_array_equal(modelled.nominal_geometry.base_points, g.base_points)
    assert plain.nominal_geometry.inertia.platform_mass == g.inertia.platform_mass
    # the truth is the robot file's with the scenario's error, whatever the model
    assert modelled.world.geometry.inertia == plain.world.geometry.inertia
    assert modelled.world.geometry.inertia.platform_mass == pytest.approx(2.0 / 0.7)
    np.testing.assert_array_equal(modelled.start_lengths, plain.start_lengths)


def test_a_missing_or_bad_model_file_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ScenarioError, match=r"robot\.model"):
        load_scenario(str(_write(tmp_path, "nowhere.toml")))
    (tmp_path / "bad.toml").write_text("name = 'x'\n")
    with pytest.raises(ScenarioError, match=r"robot\.model"):
        load_scenario(str(_write(tmp_path, "bad.toml")))


def test_check_names_the_controllers_model_and_warns_of_another_robot_s(
        tmp_path: Path) -> None:
    """A model file made for another robot (other points and strokes) was taken without
    a word, and check never showed the controllers' model: it is named, with its
    masses, in check and in the run's settings, and another robot's file is warned of."""
    from benchmarks.study.check_command import examine, scenario_setup
    from benchmarks.study.inputs import settings
    from hexapod.geometry import HexapodGeometry, circular_points

    g = preset("deltalab")
    g.replace(inertia=g.inertia.replace(platform_mass=3.3)).to_toml(tmp_path / "same.toml")
    angles = np.deg2rad([5.0, -5.0, 115.0, 125.0, 235.0, 245.0])
    HexapodGeometry(circular_points(0.9, angles), circular_points(0.5, angles + 1.0),
                    (0.9, 1.2), 0.03, 0.05, "big-hexapod").to_toml(tmp_path / "big.toml")
    for name, warned in (("same.toml", False), ("big.toml", True)):
        sc = load_scenario(str(_write(tmp_path, name)))
        setup = scenario_setup(sc)
        assert any("controllers' model: [inertia] and [drives] of" in n and name in n
                   for n in setup.notes), setup.notes
        texts = [p.text for p in examine(setup).problems]
        assert any("describes another robot" in t for t in texts) is warned, texts
        assert name in settings(sc)["controllers' model"]
