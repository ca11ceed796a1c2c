"""Tests of hexapod.geometry: the reference robot, validation of every field, TOML I/O."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hexapod import ConfigFileError, GeometryError, HexapodGeometry, deltalab, preset
from hexapod.kinematics import inverse_kinematics


def test_deltalab_matches_math_section_9(geometry: HexapodGeometry) -> None:
    # Base radius 270 mm, platform radius 195 mm, all in the z = 0 plane.
    np.testing.assert_allclose(np.linalg.norm(geometry.base_points, axis=1), 0.270, atol=1e-15)
    np.testing.assert_allclose(np.linalg.norm(geometry.platform_points, axis=1), 0.195,
                               atol=1e-15)
    assert np.all(geometry.base_points[:, 2] == 0.0)
    # A pair of base joints is 2 alpha = 8.5 deg apart around angle 0.
    ang = np.rad2deg(np.arctan2(geometry.base_points[:, 1], geometry.base_points[:, 0]))
    np.testing.assert_allclose(ang[:2], [4.25, -4.25], atol=1e-12)
    pang = np.rad2deg(np.arctan2(geometry.platform_points[:, 1], geometry.platform_points[:, 0]))
    np.testing.assert_allclose(pang[:2], [60 - 5.885, -60 + 5.885], atol=1e-12)
    assert geometry.stroke == pytest.approx((0.345, 0.485))
    assert geometry.leg_radius == 0.015
    # Platform parallel at 0.36 m: every leg about 415.5 mm (middle of the stroke).
    q = inverse_kinematics(geometry, np.eye(3), np.array([0.0, 0.0, 0.36]))
    np.testing.assert_allclose(q, 0.4155, atol=5e-4)
    assert np.ptp(q) < 1e-12
    # Home height: mean leg length at mid-stroke.
    q_home = inverse_kinematics(geometry, np.eye(3), np.array([0, 0, geometry.home_height]))
    assert q_home.mean() == pytest.approx(geometry.q_mid, abs=1e-12)


def test_the_remembered_home_height_is_the_bisections_of_that_robot(
        geometry: HexapodGeometry, other_geometry: HexapodGeometry,
        monkeypatch: pytest.MonkeyPatch) -> None:
    """hexapod.workspace remembers home heights per robot (points and stroke): a new
    instance of the same robot gets the bisection's value without bisecting again; a
    robot with another stroke or other points gets its own."""
    from dataclasses import replace

    from hexapod import workspace

    monkeypatch.setattr(workspace, "_HOME_HEIGHTS", {})
    bisect = workspace._bisect_home_height
    calls: list[str] = []

    def counted(g: HexapodGeometry) -> float:
        calls.append(g.name)
        return bisect(g)

    monkeypatch.setattr(workspace, "_bisect_home_height", counted)
    h = deltalab().home_height
    assert h == bisect(geometry) and deltalab().home_height == h and calls == ["deltalab"]
    longer = replace(geometry, stroke=(geometry.q_min, geometry.q_max + 0.02))
    assert longer.home_height == bisect(longer) > h + 0.005
    assert other_geometry.home_height == bisect(other_geometry) != h
    assert calls == ["deltalab", "deltalab", "other"]
    monkeypatch.setattr(workspace, "HOME_CACHE_SIZE", 3)  # full: a fourth robot clears it
    shorter = replace(geometry, stroke=(geometry.q_min - 0.02, geometry.q_max))
    assert shorter.home_height == bisect(shorter) < h - 0.005
    assert len(workspace._HOME_HEIGHTS) == 1 and deltalab().home_height == h


def test_preset_and_unknown_preset_suggests() -> None:
    assert preset("deltalab") == deltalab()
    with pytest.raises(GeometryError, match="did you mean 'deltalab'"):
        preset("deltalb")


def test_points_are_read_only(geometry: HexapodGeometry) -> None:
    with pytest.raises(ValueError):
        geometry.base_points[0, 0] = 1.0


def _kwargs(geometry: HexapodGeometry) -> dict:
    return {"base_points": geometry.base_points.copy(),
            "platform_points": geometry.platform_points.copy(),
            "stroke": geometry.stroke, "leg_radius": geometry.leg_radius}


@pytest.mark.parametrize("field", ["base_points", "platform_points"])
def test_wrong_shape(geometry: HexapodGeometry, field: str) -> None:
    kw = _kwargs(geometry)
    kw[field] = kw[field][:5]
    with pytest.raises(GeometryError, match=r"\(5, 3\)") as exc:
        HexapodGeometry(**kw)
    assert exc.value.field == field
    kw[field] = "not numbers"
    with pytest.raises(GeometryError) as exc:
        HexapodGeometry(**kw)
    assert exc.value.field == field


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
@pytest.mark.parametrize("field", ["base_points", "platform_points"])
def test_non_finite(geometry: HexapodGeometry, field: str, bad: float) -> None:
    kw = _kwargs(geometry)
    kw[field][3, 1] = bad
    with pytest.raises(GeometryError, match="leg 3: its point's y coordinate is") as exc:
        HexapodGeometry(**kw)
    assert exc.value.field == field
    assert "not finite" in exc.value.problem


@pytest.mark.parametrize("stroke", [(0.4, 0.4), (0.5, 0.4), (-0.1, 0.4), (np.nan, 0.4),
                                    (0.3, np.inf), (0.3,), "abc"])
def test_bad_stroke(geometry: HexapodGeometry, stroke: object) -> None:
    kw = _kwargs(geometry)
    kw["stroke"] = stroke
    with pytest.raises(GeometryError) as exc:
        HexapodGeometry(**kw)
    assert exc.value.field == "stroke"


def test_q_min_equal_q_max_message(geometry: HexapodGeometry) -> None:
    with pytest.raises(GeometryError, match="must be smaller than q_max"):
        geometry.replace(stroke=(0.4, 0.4))


@pytest.mark.parametrize("radius", [0.0, -0.01, np.nan, np.inf])
def test_bad_radius(geometry: HexapodGeometry, radius: float) -> None:
    with pytest.raises(GeometryError) as exc:
        geometry.replace(leg_radius=radius)
    assert exc.value.field == "leg_radius"


@pytest.mark.parametrize("field", ["base_points", "platform_points"])
def test_coincident_joints(geometry: HexapodGeometry, field: str) -> None:
    pts = getattr(geometry, field).copy()
    pts[4] = pts[1] + 1e-5
    with pytest.raises(GeometryError, match="points 1 and 4 coincide") as exc:
        geometry.replace(**{field: pts})
    assert exc.value.field == field


@pytest.mark.parametrize("field", ["base_points", "platform_points"])
def test_collinear_joints(geometry: HexapodGeometry, field: str) -> None:
    pts = np.outer(np.arange(6) * 0.05, [1.0, 2.0, 0.5]) + np.array([0.1, 0, 0])
    with pytest.raises(GeometryError, match="collinear") as exc:
        geometry.replace(**{field: pts})
    assert exc.value.field == field


def test_toml_round_trip(tmp_path: Path, other_geometry: HexapodGeometry) -> None:
    for geo in (deltalab(), other_geometry, other_geometry.replace(max_speed=0.02)):
        path = tmp_path / f"{geo.name}.toml"
        geo.to_toml(path)
        text = path.read_text()
        assert "base_points_mm" in text and "leg_radius_mm" in text
        back = HexapodGeometry.from_toml(path)
        np.testing.assert_allclose(back.base_points, geo.base_points, atol=1e-12)
        np.testing.assert_allclose(back.platform_points, geo.platform_points, atol=1e-12)
        assert back.stroke == pytest.approx(geo.stroke, abs=1e-15)
        assert back.leg_radius == pytest.approx(geo.leg_radius, abs=1e-15)
        assert back.max_speed == pytest.approx(geo.max_speed, abs=1e-15)
        assert back.name == geo.name
        assert back.source == str(path)


def test_toml_file_in_millimetres(tmp_path: Path) -> None:
    path = tmp_path / "robot.toml"
    geo = deltalab()
    table = geo.to_dict()
    assert table["stroke_mm"] == pytest.approx([345.0, 485.0])
    assert table["leg_radius_mm"] == pytest.approx(15.0)
    path.write_text(
        "base_points_mm = " + str(table["base_points_mm"]) + "\n"
        "platform_points_mm = " + str(table["platform_points_mm"]) + "\n"
        "stroke_mm = [345, 485]\nleg_radius_mm = 15\n"
    )
    back = HexapodGeometry.from_toml(path)
    assert back.name == "robot"  # default name: the file stem
    assert back.max_speed == 0.05
    np.testing.assert_allclose(back.base_points, geo.base_points, atol=1e-12)


def _write(tmp_path: Path, table_text: str) -> Path:
    path = tmp_path / "geo.toml"
    path.write_text(table_text)
    return path


def _valid_lines() -> dict[str, str]:
    t = deltalab().to_dict()
    return {k: f"{k} = {v!r}".replace("'", '"') for k, v in t.items()}


@pytest.mark.parametrize("key", ["base_points_mm", "platform_points_mm", "stroke_mm",
                                 "leg_radius_mm"])
def test_toml_missing_key(tmp_path: Path, key: str) -> None:
    lines = _valid_lines()
    del lines[key]
    path = _write(tmp_path, "\n".join(lines.values()))
    with pytest.raises(ConfigFileError, match="missing required key") as exc:
        HexapodGeometry.from_toml(path)
    assert exc.value.key == key
    assert str(path) in str(exc.value)


@pytest.mark.parametrize(("bad", "good"), [("leg_raduis_mm", "leg_radius_mm"),
                                           ("stroke_m", "stroke_mm"),
                                           ("base_point_mm", "base_points_mm")])
def test_toml_misspelt_key_suggests(tmp_path: Path, bad: str, good: str) -> None:
    lines = _valid_lines()
    lines[good] = lines[good].replace(good, bad, 1)
    path = _write(tmp_path, "\n".join(lines.values()))
    with pytest.raises(ConfigFileError) as exc:
        HexapodGeometry.from_toml(path)
    assert exc.value.key == bad
    assert exc.value.suggestion == good
    assert f"did you mean '{good}'" in str(exc.value)


def test_toml_missing_file(tmp_path: Path) -> None:
    path = tmp_path / "nowhere.toml"
    with pytest.raises(ConfigFileError, match="file not found") as exc:
        HexapodGeometry.from_toml(path)
    assert exc.value.path == str(path)


def test_toml_bad_syntax(tmp_path: Path) -> None:
    path = _write(tmp_path, "base_points_mm = [[1, 2, 3]\nstroke_mm = = 3\n")
    with pytest.raises(ConfigFileError, match="not valid TOML"):
        HexapodGeometry.from_toml(path)


@pytest.mark.parametrize(("rows", "says"), [
    ("[[1, 2, 3], [1, 2, 3], [1, 2], [1, 2, 3], [1, 2, 3], [1, 2, 3]]",
     "expected an array of numbers of shape (6, 3): row 2 (leg 2) has 2 numbers, not 3"),
    ("[[1, 2, 3, 4], [1, 2, 3, 4], [1, 2, 3, 4], [1, 2, 3, 4], [1, 2, 3, 4], [1, 2, 3, 4]]",
     "expected shape (6, 3), got (6, 4): row 0 (leg 0) has 4 numbers, not 3"),
    ("[[1, 2, 3], [1, 2, 3], [1, 2, 3], [1, 2, 3]]", "expected shape (6, 3), got (4, 3)"),
])
def test_a_point_row_of_the_wrong_length_is_named_by_its_leg(
        tmp_path: Path, rows: str, says: str) -> None:
    lines = _valid_lines()
    lines["base_points_mm"] = f"base_points_mm = {rows}"
    with pytest.raises(ConfigFileError) as exc:
        HexapodGeometry.from_toml(_write(tmp_path, "\n".join(lines.values())))
    assert exc.value.key == "base_points_mm" and str(exc.value).endswith(says), exc.value


def test_toml_bad_values(tmp_path: Path) -> None:
    lines = _valid_lines()
    lines["stroke_mm"] = "stroke_mm = [345, 485, 500]"
    with pytest.raises(ConfigFileError, match=r"expected shape \(2,\)") as exc:
        HexapodGeometry.from_toml(_write(tmp_path, "\n".join(lines.values())))
    assert exc.value.key == "stroke_mm"
    lines = _valid_lines()
    lines["leg_radius_mm"] = 'leg_radius_mm = "wide"'
    with pytest.raises(ConfigFileError, match="finite number") as exc:
        HexapodGeometry.from_toml(_write(tmp_path, "\n".join(lines.values())))
    assert exc.value.key == "leg_radius_mm"
    # A value that parses but makes an invalid geometry names the field and the file.
    lines = _valid_lines()
    lines["stroke_mm"] = "stroke_mm = [485, 345]"
    path = _write(tmp_path, "\n".join(lines.values()))
    with pytest.raises(GeometryError) as gexc:
        HexapodGeometry.from_toml(path)
    assert gexc.value.field == "stroke_mm"  # the key as written in the file
    assert gexc.value.source == str(path)


def test_a_nan_point_names_its_leg(tmp_path: Path) -> None:
    """A robot file with a NaN coordinate: the error names the key, the leg and the axis."""
    path = tmp_path / "robot.toml"
    deltalab().to_toml(path)
    lines = path.read_text().splitlines()
    start = lines.index("base_points_mm = [")
    # the second coordinate of the fourth point (leg 3): 1 + 5 lines per point, then + 2
    lines[start + 1 + 5 * 3 + 2] = "        nan,"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(ConfigFileError) as info:
        HexapodGeometry.from_toml(path)
    assert info.value.key == "base_points_mm"
    assert "leg 3: its point's y coordinate is nan" in str(info.value)


@pytest.mark.parametrize(("change", "field", "says"), [
    # the Python constructor takes metres: these were accepted (a home 415 m high)
    ({"stroke": (345.0, 485.0)}, "stroke", "q_max 485 m: no hexapod has legs this long"),
    ({"leg_radius": 15.0}, "leg_radius", "15 m is at least the plates' radius 0.27 m"),
    ({"max_speed": 50.0}, "max_speed", "50 m/s: no hexapod's legs move this fast"),
])
def test_a_constructor_value_in_millimetres_is_refused(change: dict[str, object], field: str,
                                                       says: str) -> None:
    with pytest.raises(GeometryError, match=f"{field}: {says}.*millimetres for metres"):
        deltalab().replace(**change)


def test_a_front_camera_distance_in_millimetres_is_refused() -> None:
    from vision.cameras import front_camera
    from vision.exceptions import CameraError

    with pytest.raises(CameraError, match=r"800 m from the reference robot's base .*"
                                          r"millimetres for metres"):
        front_camera(deltalab(), distance=800)
    assert np.isfinite(front_camera(deltalab(), distance=2.0).K).all()
