"""Typed actuation: a command says whether it sets leg velocities or leg forces, and
whatever applies it refuses the kind it cannot apply, naming the controller."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from benchmarks.sim import run_trials
from benchmarks.study.scenario import ControllerSpec, load_scenario
from controllers.base import Command, CommandBatch, registry
from controllers.batch import actuation_of, batch_controller
from hexapod.actuation import Actuation, check_actuation
from hexapod.backends.sim import SimulatedRobot
from hexapod.exceptions import ActuationError
from hexapod.geometry import deltalab
from tests.controllers.one_by_one import stacked

PLUGIN = "tests.controllers.force_plugin:LegSpringForces"
REFUSAL = ("controller 'springs' commands leg forces [N], but the kinematic world applies "
           "only leg velocities [m/s]")


def test_a_force_plugin_declares_and_returns_forces() -> None:
    ctrl = registry.create(PLUGIN)
    assert ctrl.actuation is Actuation.FORCE
    assert actuation_of(batch_controller(PLUGIN, {})) is Actuation.FORCE
    assert actuation_of(registry.create("leg-edge")) is Actuation.VELOCITY


def test_command_values_follow_the_actuation() -> None:
    f = np.arange(6.0)
    cmd = Command.of_forces(f, error_norm=1.0)
    assert cmd.actuation is Actuation.FORCE
    np.testing.assert_array_equal(cmd.values, f)
    np.testing.assert_array_equal(cmd.velocities, np.zeros(6))
    refused = Command.refuse("no", actuation=Actuation.FORCE)
    np.testing.assert_array_equal(refused.values, np.zeros(6))
    batch = stacked([cmd, refused])
    assert batch.actuation is Actuation.FORCE
    np.testing.assert_array_equal(batch.values, [f, np.zeros(6)])
    velocity = Command(np.ones(6))
    with pytest.raises(ActuationError, match="row 0"):
        CommandBatch.zeros(1, Actuation.FORCE).put(0, velocity)


@pytest.mark.parametrize("engine", ["batched", "per-trial"])
def test_the_kinematic_world_refuses_a_force_controller(engine: str) -> None:
    sc = replace(load_scenario("quick").with_overrides(trials=2),
                 controllers=(ControllerSpec(PLUGIN, "springs"),))
    point = sc.expand()[0]
    rows = [r.row for r in run_trials(point, 0, [0, 1], engine=engine)]
    for row in rows:
        assert row["converged"] is False
        assert row["steps"] == 0
        assert REFUSAL in row["failure"], row["failure"]
        assert row["failure"].startswith("ActuationError")


def test_a_velocity_backend_refuses_forces_and_applies_velocities() -> None:
    g = deltalab()
    robot = SimulatedRobot(g)
    q0 = robot.measured_lengths()
    with pytest.raises(ActuationError, match="controller 'springs' commands leg forces"):
        robot.apply(np.ones(6), Actuation.FORCE, 0.02, "springs")
    np.testing.assert_array_equal(robot.measured_lengths(), q0)  # nothing applied
    v = np.full(6, 1e-3)
    step = robot.apply(v, Actuation.VELOCITY, 0.02, "springs")
    np.testing.assert_allclose(step.lengths, q0 + 0.02 * v, rtol=0, atol=1e-15)


def test_check_actuation_names_everything() -> None:
    with pytest.raises(ActuationError) as info:
        check_actuation("force", (Actuation.VELOCITY,), "the GCS board", "my-law")
    err = info.value
    assert (err.controller, err.actuation, err.receiver) == ("my-law", "force", "the GCS board")
    assert check_actuation("velocity", (Actuation.VELOCITY,), "x", "y") is Actuation.VELOCITY
    with pytest.raises(ActuationError, match="unknown actuation 'torque'"):
        check_actuation("torque", tuple(Actuation), "x", "my-law")


@pytest.mark.parametrize("engine", ["batched", "per-trial"])
def test_a_fall_under_a_refusing_force_law_is_blamed_on_its_refusals(engine: str,
                                                                     tmp_path: Path) -> None:
    """A force law that refuses commands no force: the platform falls onto an end stop
    before the refusals' own limit ends the trial, and the row said only 'leg 0 hit its
    end stop'; it now says the controller had refused, how long and why. (quick-dynamic's
    robot with a speed limit out of reach: its drives would brake the fall at 50 mm/s,
    too slowly to reach the end stop before the refusals' limit.)"""
    from benchmarks.study.scenario import load_scenario as load

    deltalab().replace(max_speed=10.0).to_toml(tmp_path / "robot.toml")
    text = (Path(load_scenario("quick-dynamic").source).read_text()
            .replace('preset = "deltalab"', 'geometry = "robot.toml"'))
    (tmp_path / "study.toml").write_text(text)
    sc = replace(load(str(tmp_path / "study.toml")).with_overrides(trials=1, max_steps=60),
                 controllers=(ControllerSpec("tests.controllers.force_plugin:RefusingForces",
                                             "blind"),))
    row = run_trials(sc.expand()[0], 0, [0], engine=engine)[0].row
    assert "hit its end stop" in row["failure"], row["failure"]
    assert "the controller had refused to move for the last" in row["failure"]
    assert row["failure"].endswith("period(s): my sensor is blind)"), row["failure"]


def test_a_velocity_law_on_force_mode_drives_is_refused_before_any_trial(
        tmp_path: Path) -> None:
    """A robot file whose drives are in force mode (no velocity loop) with leg-edge: check
    said the setup could run and every trial failed; the study is refused as a force law
    in the kinematic world is, naming the controller and the drives' mode."""
    from benchmarks.exceptions import ScenarioError
    from benchmarks.study.scenario import check_controllers
    from benchmarks.study.scenario import load_scenario as load

    g = deltalab()
    g.replace(drives=g.drives.replace(mode="force")).to_toml(tmp_path / "robot.toml")
    (tmp_path / "study.toml").write_text(
        'name = "fm"\ncontrollers = ["leg-edge", "computed-torque"]\n'
        '[robot]\ngeometry = "robot.toml"\nworld = "dynamic"\n')
    with pytest.raises(ScenarioError) as info:
        check_controllers(load(str(tmp_path / "study.toml")))
    assert info.value.key == "controllers[0]"
    assert "force-mode drives (robot file [drives] mode = \"force\")" in str(info.value)
