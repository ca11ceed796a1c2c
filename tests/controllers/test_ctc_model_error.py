"""Paccot's argument on the dynamic world: under a geometric calibration error (the
controller's nominal base and platform points off by ``eps`` while the world has the
truth; the camera exact), where does each computed-torque law settle?

Measured (deltalab, goal 19.7 mm and 1.5 degrees from home, ``eps`` = 0.5 / 1 mm, the
points moved in random directions, seed 3), final true position error:

- ``computed-torque`` and ``cartesian-ctc``: 728 / 1456 um (the encoders' forward
  kinematics of the nominal model: proportional to ``eps``, amplified by the mechanism);
- ``vision-ctc``: 162 / 325 um (the pose of the legs seen, with the estimated base points,
  fitted to the nominal platform points; its taught goal carries the nominal goal
  lengths, so the bias cancels only in part);
- ``leg-edge-ctc``, ``leg-direction-ctc``: 55 / 110 um (taught features: the goal is the
  true one; what is left is the nominal dynamic model's static error, the gravity forces
  of a wrong geometry, against the stiffness ``omega_n^2`` of a law without integral
  action: a quarter at twice the natural frequency, while vision-ctc's kinematic bias
  does not move).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from controllers import registry
from hexapod import HexapodGeometry
from hexapod.se3 import exp_so3, pose_error
from hexapod.workspace import home_pose
from tests.controllers.ctc_world import CtcWorld, ideal_drives, perturbed

LAWS = ("computed-torque", "cartesian-ctc", "vision-ctc", "leg-edge-ctc",
        "leg-direction-ctc")
STEPS = 120  # the quintic (about 1.3 s) and 1 s of settling


def _final_errors(truth: HexapodGeometry, eps: float, law: str, fn: float = 2.0
                  ) -> tuple[float, float]:
    """Final true position [m] and rotation [rad] error with points off by ``eps``."""
    R0, t0 = home_pose(truth)
    Rg = R0 @ exp_so3(np.array([0.02, -0.01, 0.015]))
    tg = t0 + np.array([0.015, -0.01, 0.008])
    world = CtcWorld.make(truth, perturbed(truth, eps, seed=3))
    ctrl = registry.create(law, natural_frequency=fn)
    ctrl.reset(world.context(world.goal(Rg, tg)))
    p, R, _ = world.run(ctrl, (R0, t0), STEPS)
    pos, ang = pose_error(R[-1], p[-1], Rg, tg)
    return float(pos), float(ang)


@pytest.mark.slow
def test_errors_grow_as_the_theory_says(geometry: HexapodGeometry) -> None:
    truth = ideal_drives(geometry)
    err = {(law, eps): _final_errors(truth, eps, law) for law in LAWS
           for eps in (0.0005, 0.001)}
    for law in LAWS:  # every law's error is proportional to the calibration error
        ratio = err[law, 0.001][0] / err[law, 0.0005][0]
        assert 1.8 < ratio < 2.2, (law, ratio)
    for eps in (0.0005, 0.001):
        ct, cart, vis = (err[law, eps][0] for law in LAWS[:3])
        assert ct > 0.5 * eps  # the encoders' pose is off by the order of eps
        assert cart == pytest.approx(ct, rel=0.01)  # the same pose, the same settling
        assert vis < 0.5 * cart  # the legs seen: closer
        for law in ("leg-edge-ctc", "leg-direction-ctc"):
            pos, ang = err[law, eps]
            assert pos < 0.5 * vis, (law, pos, vis)  # the taught features: closer still
            assert ang < 0.2 * err["cartesian-ctc", eps][1]


def test_the_feature_laws_residual_is_the_dynamic_models(geometry: HexapodGeometry) -> None:
    """At twice the natural frequency the leg-edge law's residual is a quarter (a static
    force error over ``omega_n^2``); vision-ctc's is a pose bias, unchanged."""
    truth = ideal_drives(geometry)
    edge = [_final_errors(truth, 0.001, "leg-edge-ctc", fn)[0] for fn in (2.0, 4.0)]
    vis = [_final_errors(truth, 0.001, "vision-ctc", fn)[0] for fn in (2.0, 4.0)]
    assert edge[0] / edge[1] == pytest.approx(4.0, rel=0.1)
    assert vis[0] / vis[1] == pytest.approx(1.0, abs=0.1)


def test_a_perfect_model_settles_on_the_goal(geometry: HexapodGeometry) -> None:
    truth = ideal_drives(geometry)
    for law in LAWS:
        pos, ang = _final_errors(truth, 0.0, law)
        assert pos < 1e-7 and ang < 1e-6, (law, pos, ang)


@pytest.mark.parametrize("law", LAWS[1:])
def test_refused_on_the_kinematic_world(law: str) -> None:
    from benchmarks.sim import run_trials
    from benchmarks.study.scenario import ControllerSpec, load_scenario

    sc = dataclasses.replace(load_scenario("quick").with_overrides(trials=1),
                             controllers=(ControllerSpec(law, "ctc"),))
    row = run_trials(sc.expand()[0], 0, [0], engine="per-trial")[0].row
    assert row["converged"] is False and row["steps"] == 0
    assert row["failure"].startswith("ActuationError")
    assert ("controller 'ctc' commands leg forces [N], but the kinematic world applies only "
            "leg velocities [m/s]") in row["failure"]


@pytest.mark.slow
def test_leg_edge_ctc_in_the_study_dynamic_world() -> None:
    """quick-dynamic (its calibration error, noise and drive friction), batched engine:
    the leg-edge law converges (to 0.1 mm when measured; the scenario's threshold is
    0.5 mm)."""
    from benchmarks.sim import run_trials
    from benchmarks.study.scenario import ControllerSpec, load_scenario

    sc = dataclasses.replace(load_scenario("quick-dynamic").with_overrides(trials=1),
                             controllers=(ControllerSpec("leg-edge-ctc", "edge-ctc"),))
    row = run_trials(sc.expand()[0], 0, [0], engine="batched")[0].row
    assert row["failure"] is None, row["failure"]
    assert row["converged"] is True
    assert 0.0 < row["max_leg_force_n"] < 200.0
