"""Scenario keys of the dynamic world: ``[robot] world``/``physics_dt`` and the inertial
calibration errors; errors name the file and the key; the draws of the other errors
are unchanged by the new ones."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.exceptions import ScenarioError
from benchmarks.sim import load_camera, load_geometry, make_trial
from benchmarks.study.scenario import builtin_scenarios, load_scenario, parse_scenario

MINIMAL = {"name": "t", "controllers": ["leg-edge"]}


def test_the_kinematic_world_is_the_default_of_every_builtin_but_the_dynamic_ones() -> None:
    for name in builtin_scenarios():
        sc = load_scenario(name)
        dynamic = "dynamic" in name or name in ("inertia-error", "paccot2008-tracking",
                                                "mpc-drives", "mpc-drives-tracking",
                                                "payload-saturation")
        assert sc.world == ("dynamic" if dynamic else "kinematic"), name
        assert sc.physics_dt == 0.001


def test_world_and_physics_dt_are_read() -> None:
    sc = parse_scenario({**MINIMAL, "robot": {"world": "dynamic", "physics_dt": 0.0005,
                                              "dt": 0.01}})
    assert (sc.world, sc.physics_dt, sc.dt) == ("dynamic", 0.0005, 0.01)


@pytest.mark.parametrize(
    ("robot", "key", "fragment"),
    [
        ({"world": "dynamical"}, "robot.world", "dynamic"),
        ({"world": 1}, "robot.world", "expected a string"),
        ({"physics_dt": 0.0}, "robot.physics_dt", "out of the allowed range"),
        ({"physics_dt": "1ms"}, "robot.physics_dt", "expected a number"),
        ({"world": "dynamic", "physics_dt": 0.03}, "robot.physics_dt",
         "longer than the control period"),
        ({"world": "dynamic", "physics_dt": 0.003}, "robot.physics_dt",
         "not a whole number of physics steps"),
        ({"physic_dt": 0.001}, "robot.physic_dt", "physics_dt"),
    ],
)
def test_bad_world_keys_name_the_file_and_key(robot: dict, key: str, fragment: str) -> None:
    with pytest.raises(ScenarioError) as info:
        parse_scenario({**MINIMAL, "robot": robot}, "world.toml")
    text = str(info.value)
    assert "world.toml" in text and key in text and fragment in text, text


def test_the_kinematic_world_takes_no_physics_step() -> None:
    """``physics_dt`` is the dynamic world's: a kinematic study's period need not be a
    multiple of it (its range is still checked)."""
    sc = parse_scenario({**MINIMAL, "robot": {"dt": 0.0125, "physics_dt": 0.003}})
    assert (sc.world, sc.dt) == ("kinematic", 0.0125)


@pytest.mark.parametrize("key", ["mass_percent", "inertia_percent"])
def test_inertial_errors_are_checked(key: str) -> None:
    with pytest.raises(ScenarioError) as info:
        parse_scenario({**MINIMAL, "calibration_error": {key: -1.0}}, "err.toml")
    assert f"calibration_error.{key}" in str(info.value) and "err.toml" in str(info.value)
    with pytest.raises(ScenarioError, match="beyond the allowed 50"):
        parse_scenario({**MINIMAL, "calibration_error": {key: 30.0, "scale": [1.0, 2.0]}})
    sc = parse_scenario({**MINIMAL, "calibration_error": {key: [0.0, 10.0]}})
    assert [getattr(p.calibration_error, key) for p in sc.expand()] == [0.0, 10.0]


def test_the_true_robot_gets_the_inertial_error_and_the_controllers_the_file() -> None:
    """20 % mass and inertia errors: every trial's true masses differ from the robot
    file's, by factors whose log has about the stated spread; the nominal geometry (what
    the controller context gets) keeps the file's; the other draws (poses, base points)
    are those without the inertial error."""
    base = {**MINIMAL, "calibration_error": {"base_points_mm": 1.0}}
    with_err = {**MINIMAL, "calibration_error": {"base_points_mm": 1.0, "mass_percent": 20.0,
                                                 "inertia_percent": 20.0}}
    factors = []
    for table in (base, with_err):
        sc = parse_scenario(table)
        nominal = load_geometry(sc)
        camera = load_camera(sc, nominal)
        setups = [make_trial(sc, k, nominal, camera) for k in range(40)]
        factors.append(setups)
    plain, drawn = factors
    masses = []
    for a, b in zip(plain, drawn, strict=True):
        np.testing.assert_array_equal(a.start_rotation, b.start_rotation)
        np.testing.assert_array_equal(a.world.geometry.base_points, b.world.geometry.base_points)
        assert b.nominal_geometry.inertia == a.nominal_geometry.inertia
        ti, ni = b.world.geometry.inertia, a.world.geometry.inertia
        assert ti.platform_mass != ni.platform_mass
        masses.append([ti.platform_mass / ni.platform_mass, ti.rod_mass / ni.rod_mass,
                       ti.platform_inertia[0] / ni.platform_inertia[0]])
    spread = np.std(np.log(masses), axis=0)
    assert np.all((spread > 0.12) & (spread < 0.3)), spread


def test_drives_section_sets_the_bandwidth_of_the_robot_and_the_model() -> None:
    """``[drives] velocity_bandwidth_hz`` (a sweep axis) replaces the robot file's
    bandwidth in the nominal geometry the controllers get AND in every trial's true
    robot; 0 keeps the file's; the rest of the drives is the file's."""
    sc = parse_scenario({**MINIMAL, "robot": {"world": "dynamic"},
                         "drives": {"velocity_bandwidth_hz": [0.0, 7.5]}})
    points = sc.expand()
    assert [p.sweep for p in points] == [{"drives.velocity_bandwidth_hz": 0.0},
                                         {"drives.velocity_bandwidth_hz": 7.5}]
    file_drives = load_geometry(points[0]).drives
    assert np.all(file_drives.velocity_bandwidth == 50.0)
    nominal = load_geometry(points[1])
    np.testing.assert_array_equal(nominal.drives.velocity_bandwidth, np.full(6, 7.5))
    np.testing.assert_array_equal(nominal.drives.force_limit, file_drives.force_limit)
    trial = make_trial(points[1], 0, nominal, load_camera(points[1], nominal))
    np.testing.assert_array_equal(trial.world.geometry.drives.velocity_bandwidth,
                                  np.full(6, 7.5))
    np.testing.assert_array_equal(trial.nominal_geometry.drives.velocity_bandwidth,
                                  np.full(6, 7.5))


@pytest.mark.parametrize(
    ("drives", "key", "fragment"),
    [
        ({"velocity_bandwidth_hz": -5.0}, "drives.velocity_bandwidth_hz", "out of the allowed"),
        ({"velocity_bandwidth_hz": "fast"}, "drives.velocity_bandwidth_hz", "expected a number"),
        ({"velocity_bandwidth": 5.0}, "drives.velocity_bandwidth", "velocity_bandwidth_hz"),
    ],
)
def test_bad_drives_keys_name_the_file_and_key(drives: dict, key: str, fragment: str) -> None:
    with pytest.raises(ScenarioError) as info:
        parse_scenario({**MINIMAL, "drives": drives}, "drives.toml")
    text = str(info.value)
    assert "drives.toml" in text and key in text and fragment in text, text


@pytest.mark.slow
def test_a_dynamic_run_records_and_reports_its_drives(tmp_path) -> None:
    """quick-dynamic through the CLI: every row has the drive figures, the recorded trial
    its leg forces, and the report a drives table (the figures are not sweep values)."""
    from benchmarks.cli import main as cli_main
    from benchmarks.study.metrics import sweep_values
    from benchmarks.study.results import read_results

    out = tmp_path / "qd"
    assert cli_main(["run", "quick-dynamic", "--out", str(out), "--trials", "2",
                     "--controllers", "leg-edge", "--no-progress", "--record", "1",
                     "--max-steps", "60"]) == 0
    rows = read_results(out)
    for key in ("max_leg_force_n", "saturation_time_s", "drive_tracking_rms_mm_s",
                "drive_tracking_max_mm_s"):
        assert all(isinstance(r[key], float) and r[key] >= 0 for r in rows), key
    assert all(sweep_values(r) == {} for r in rows)
    forces = np.load(next((out / "trials").glob("*.npz")))["leg_forces"]
    assert forces.shape == (61, 6) and np.all(np.isfinite(forces))
    # sampled at the ends of the periods: within the largest force over every physics step
    assert 0 < np.abs(forces).max() <= max(r["max_leg_force_n"] for r in rows)
    report = (out / "report.md").read_text()
    assert "Drives (dynamic world" in report and "max leg force N" in report


@pytest.mark.slow
def test_run_world_overrides_the_scenarios_world(tmp_path) -> None:
    """``run quick --world dynamic`` runs quick in the dynamic world (its rows carry the
    drive figures), ``--world kinematic`` runs quick-dynamic without them."""
    from benchmarks.cli import main as cli_main
    from benchmarks.study.results import read_results

    for name, world, has in (("quick", "dynamic", True), ("quick-dynamic", "kinematic", False)):
        out = tmp_path / name
        assert cli_main(["run", name, "--world", world, "--out", str(out), "--trials", "1",
                         "--controllers", "leg-edge", "--no-progress", "--record", "0",
                         "--max-steps", "20"]) == 0
        rows = read_results(out)
        assert rows and all(("max_leg_force_n" in r) == has for r in rows)
