"""Tests of the ``[inertia]`` and ``[drives]`` tables of the robot file: defaults, loading,
round trip, and each refusal (naming the file and the key)."""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import tomli_w

from hexapod import ConfigFileError, HexapodGeometry, build_model, deltalab
from hexapod.dynamics import DriveParameters, InertiaParameters
from hexapod.exceptions import DriveError, GeometryError, InertiaError


def _write(tmp_path: Path, inertia: dict | None = None, drives: dict | None = None) -> Path:
    table = deltalab().to_dict()
    if inertia is not None:
        table["inertia"] = inertia
    if drives is not None:
        table["drives"] = drives
    path = tmp_path / "robot.toml"
    path.write_text(tomli_w.dumps(table))
    return path


def test_preset_defaults_are_the_documented_cylinders() -> None:
    g = deltalab()
    inertia = g.inertia
    # Independent: Pinocchio's own homogeneous-cylinder inertia (lateral, lateral, axial).
    body = pin.Inertia.FromCylinder(0.5, g.leg_radius, 0.9 * g.q_min)
    rod = pin.Inertia.FromCylinder(0.2, 0.6 * g.leg_radius, 0.9 * g.q_min)
    plate = pin.Inertia.FromCylinder(2.0, 0.195, 0.01)
    np.testing.assert_allclose(inertia.body_inertia, np.diag(body.inertia)[1:], rtol=1e-14)
    np.testing.assert_allclose(inertia.rod_inertia, np.diag(rod.inertia)[1:], rtol=1e-14)
    np.testing.assert_allclose(inertia.platform_tensor, plate.inertia, rtol=1e-12)
    assert inertia.body_com == pytest.approx(0.15525)
    assert inertia.rod_com == pytest.approx(0.15525)
    np.testing.assert_array_equal(inertia.gravity, [0.0, 0.0, -9.81])
    assert g.drives == DriveParameters.default()
    assert g.drives.mode == "velocity"


def test_model_carries_the_inertia() -> None:
    g = deltalab()
    inertia = g.inertia.replace(platform_mass=3.5, platform_com=np.array([0.01, 0.0, 0.02]),
                                rod_mass=0.3, gravity=np.array([0.0, 1.0, -9.0]))
    hm = build_model(g.replace(inertia=inertia))
    total = sum(hm.model.inertias[j].mass for j in range(1, hm.model.njoints))
    assert total == pytest.approx(3.5 + 6 * (0.5 + 0.3))
    np.testing.assert_allclose(hm.model.inertias[hm.platform_joint].lever, [0.01, 0.0, 0.02])
    np.testing.assert_allclose(hm.model.gravity.linear, [0.0, 1.0, -9.0])


def test_toml_round_trip_with_partial_tables(tmp_path: Path) -> None:
    path = _write(tmp_path, inertia={"platform_mass": 4.0, "body_mass": 0.0,
                                     "body_inertia": [0.0, 0.0]},
                  drives={"force_limit": [100, 110, 120, 130, 140, 150], "mode": "force"})
    g = HexapodGeometry.from_toml(path)
    assert g.inertia.platform_mass == 4.0
    assert g.inertia.body_mass == 0.0
    assert g.inertia.rod_mass == deltalab().inertia.rod_mass  # absent keys keep the default
    np.testing.assert_array_equal(g.drives.force_limit, [100, 110, 120, 130, 140, 150])
    assert g.drives.mode == "force"
    assert g.drives.viscous[3] == DriveParameters.default().viscous[3]
    out = tmp_path / "again.toml"
    g.to_toml(out)
    again = HexapodGeometry.from_toml(out)
    assert again.inertia == g.inertia and again.drives == g.drives
    np.testing.assert_allclose(again.base_points, g.base_points, rtol=1e-12)
    assert "[inertia]" in out.read_text() and "[drives]" in out.read_text()
    assert again != deltalab()


def test_replace_resizes_default_inertia_but_keeps_given() -> None:
    g = deltalab()
    shorter = g.replace(stroke=(0.2, 0.3))
    assert shorter.inertia.body_com == pytest.approx(0.09)
    given = g.replace(inertia=g.inertia.replace(body_com=0.1))
    assert given.replace(leg_radius=0.02).inertia.body_com == 0.1


@pytest.mark.parametrize(("platform_radius", "leg_radius", "q_min"),
                         [(0.195, 0.015, 0.345), (0.05, 0.03, 0.1), (1.0, 0.002, 2.0)])
def test_defaults_pass_every_check(platform_radius: float, leg_radius: float,
                                   q_min: float) -> None:
    """The defaults are built without the checks: they must pass them."""
    default = InertiaParameters.default(platform_radius, leg_radius, q_min)
    assert default.replace() == default  # replace() validates again
    default.check_legs(q_min)
    assert InertiaParameters.default(platform_radius, leg_radius, q_min) is default
    with pytest.raises(ValueError):
        default.platform_com[0] = 1.0  # read-only, shared


def test_massless_legs_are_accepted() -> None:
    g = deltalab()
    massless = g.replace(inertia=g.inertia.massless())
    assert massless.inertia.massless_legs
    assert not g.inertia.massless_legs


@pytest.mark.parametrize(("changes", "key", "words"), [
    ({"body_mass": -0.1}, "inertia.body_mass", "negative mass"),
    ({"rod_mass": -1}, "inertia.rod_mass", "negative mass"),
    ({"platform_mass": 0.0}, "inertia.platform_mass", "must be positive"),
    ({"platform_inertia": [0.1, 0.1, 0.1, 0.2, 0.0, 0.0]}, "inertia.platform_inertia",
     "not positive definite"),
    ({"platform_inertia": [0.01, 0.01, 0.05, 0.0, 0.0, 0.0]}, "inertia.platform_inertia",
     "triangle inequality"),
    ({"body_inertia": [0.001, 0.003]}, "inertia.body_inertia", "triangle inequality"),
    ({"rod_inertia": [0.001, 0.0]}, "inertia.rod_inertia", "not positive definite"),
    ({"body_mass": 0.0}, "inertia.body_inertia", "massless body has no inertia"),
    ({"body_com": 0.4}, "inertia.body_com", "outside the leg"),
    ({"rod_com": -0.01}, "inertia.rod_com", "outside the leg"),
])
def test_inertia_refusals_name_file_and_key(tmp_path: Path, changes: dict, key: str,
                                            words: str) -> None:
    path = _write(tmp_path, inertia=changes)
    with pytest.raises(InertiaError, match=words) as exc:
        HexapodGeometry.from_toml(path)
    assert exc.value.field == key
    assert str(path) in str(exc.value) and key in str(exc.value)
    assert isinstance(exc.value, GeometryError)


@pytest.mark.parametrize(("table", "key"), [
    ({"platform_mas": 2.0}, "inertia.platform_mas"),
    ({"platform_com": [0.0, 0.0]}, "inertia.platform_com"),
    ({"body_mass": "heavy"}, "inertia.body_mass"),
])
def test_inertia_malformed_values(tmp_path: Path, table: dict, key: str) -> None:
    path = _write(tmp_path, inertia=table)
    with pytest.raises(ConfigFileError) as exc:
        HexapodGeometry.from_toml(path)
    assert exc.value.key == key
    assert str(path) in str(exc.value)


def test_inertia_misspelt_key_suggests(tmp_path: Path) -> None:
    with pytest.raises(ConfigFileError, match="did you mean 'platform_mass'"):
        HexapodGeometry.from_toml(_write(tmp_path, inertia={"platform_mas": 2.0}))


@pytest.mark.parametrize(("table", "key", "words"), [
    ({"force_limit": 0.0}, "drives.force_limit", "leg 0: must be positive"),
    ({"force_limit": [100, 100, 100, -5, 100, 100]}, "drives.force_limit",
     "leg 3: must be positive"),
    ({"viscous": [1, 1, 1, 1, 1, -1]}, "drives.viscous", "leg 5: must be non-negative"),
    ({"rotor_inertia": -1.0}, "drives.rotor_inertia", "must be non-negative"),
    ({"encoder_resolution": -1e-6}, "drives.encoder_resolution", "must be non-negative"),
    ({"velocity_bandwidth": 0}, "drives.velocity_bandwidth", "must be positive"),
    ({"coulomb": [5, 5, 300, 5, 5, 5]}, "drives.coulomb", "leg 2: Coulomb friction"),
    ({"mode": "velocty"}, "drives.mode", "did you mean 'velocity'"),
])
def test_drive_refusals_name_file_key_and_leg(tmp_path: Path, table: dict, key: str,
                                              words: str) -> None:
    path = _write(tmp_path, drives=table)
    with pytest.raises(DriveError, match=words) as exc:
        HexapodGeometry.from_toml(path)
    assert exc.value.field == key
    assert str(path) in str(exc.value)


@pytest.mark.parametrize(("table", "key"), [
    ({"force_limit": [1.0, 2.0]}, "drives.force_limit"),
    ({"mode": 3}, "drives.mode"),
    ({"viscus": 3.0}, "drives.viscus"),
    ({"coulomb": True}, "drives.coulomb"),
])
def test_drive_malformed_values(tmp_path: Path, table: dict, key: str) -> None:
    path = _write(tmp_path, drives=table)
    with pytest.raises(ConfigFileError) as exc:
        HexapodGeometry.from_toml(path)
    assert exc.value.key == key
    assert str(path) in str(exc.value)


def test_tables_must_be_tables(tmp_path: Path) -> None:
    table = deltalab().to_dict()
    table["inertia"] = 3.0
    path = tmp_path / "robot.toml"
    path.write_text(tomli_w.dumps(table))
    with pytest.raises(ConfigFileError, match="expected a table"):
        HexapodGeometry.from_toml(path)


def test_drive_per_leg_scalar_written_compactly() -> None:
    d = DriveParameters.default().replace(viscous=np.array([1.0, 2, 3, 4, 5, 6]))
    table = d.to_dict()
    assert table["force_limit"] == 200.0
    assert table["viscous"] == [1.0, 2, 3, 4, 5, 6]
    assert DriveParameters.from_dict(table, "<t>") == d


def test_inertia_parameters_construction_refuses_nan() -> None:
    with pytest.raises(InertiaError, match="not finite"):
        deltalab().inertia.replace(body_com=float("nan"))
    assert isinstance(deltalab().inertia, InertiaParameters)


def test_a_stroke_in_metres_is_named_not_the_inertia_it_breaks(tmp_path: Path) -> None:
    """``deltalab().to_toml(...)`` (which writes ``[inertia]``) with ``stroke_mm`` in
    metres: the stroke is named with the millimetre hint (the leg's centre of mass was
    blamed, "inertia.body_com ... outside the leg"); a wrong [inertia] beside a right
    stroke is still the inertia's error."""
    path = tmp_path / "robot.toml"
    deltalab().to_toml(path)
    table = tomllib.loads(path.read_text())
    assert "inertia" in table
    table["stroke_mm"] = [0.345, 0.485]
    path.write_text(tomli_w.dumps(table))
    with pytest.raises(GeometryError, match=r"stroke_mm: the longest leg length is 0\.485 mm: "
                                            r"given in metres") as info:
        HexapodGeometry.from_toml(path)
    assert not isinstance(info.value, InertiaError)
    table["stroke_mm"] = [345.0, 485.0]
    table["inertia"]["body_com"] = 0.5  # beyond the shortest leg, 345 mm
    path.write_text(tomli_w.dumps(table))
    with pytest.raises(InertiaError, match=r"inertia\.body_com"):
        HexapodGeometry.from_toml(path)
