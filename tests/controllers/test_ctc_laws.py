"""``cartesian-ctc``, ``vision-ctc``, ``leg-edge-ctc``, ``leg-direction-ctc`` on the dynamic
world with a perfect model and no noise (:mod:`tests.controllers.ctc_world`): tracking,
the designed second-order response measured from a step, refusals.

The response is compared with the design sampled with a zero-order hold (the force is
held over the 20 ms period: the exact discretisation of the linear error dynamics),
never with the controller's formula.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.optimize import curve_fit

from controllers import registry
from controllers.base import Observation
from controllers.exceptions import ContextError, OptionError
from hexapod import HexapodGeometry
from hexapod.actuation import Actuation
from hexapod.trajectory import PoseTrajectory
from hexapod.workspace import home_pose
from tests.controllers.ctc_world import (
    DT,
    CtcWorld,
    assert_tracks_the_rotated_line,
    ideal_drives,
    line_reference,
)
from tests.controllers.test_computed_torque import _sampled_design, _step_response

LAWS = ("cartesian-ctc", "vision-ctc", "leg-edge-ctc", "leg-direction-ctc")


@pytest.fixture
def world(geometry: HexapodGeometry) -> CtcWorld:
    return CtcWorld.make(ideal_drives(geometry))


@pytest.mark.parametrize("law", LAWS)
def test_registered_force_controllers(law: str) -> None:
    ctrl = registry.create(law)
    assert ctrl.actuation is Actuation.FORCE
    with pytest.raises(OptionError, match="natural_frequency"):
        registry.create(law, natural_frequency=-1.0)
    with pytest.raises(OptionError, match="damping"):
        registry.create(law, damping=float("nan"))
    with pytest.raises(OptionError, match="smooth_goal"):
        registry.create(law, smooth_goal="yes")


@pytest.mark.parametrize("law", LAWS)
def test_missing_context_is_named(world: CtcWorld, law: str) -> None:
    R0, t0 = home_pose(world.truth)
    ctx = world.context(world.goal(R0, t0))
    ctrl = registry.create(law)
    if law != "cartesian-ctc":  # the camera laws need the estimated camera pose
        with pytest.raises(ContextError, match="context field 'camera'"):
            ctrl.reset(dataclasses.replace(ctx, camera=None))
    key = {"cartesian-ctc": "goal.rotation/translation", "vision-ctc": "goal.rotation",
           "leg-edge-ctc": "goal.normals", "leg-direction-ctc": "goal.directions"}[law]
    with pytest.raises(ContextError, match=key):
        ctrl.reset(dataclasses.replace(ctx, goal=dataclasses.replace(
            ctx.goal, normals=None, directions=None, rotation=None)))


@pytest.mark.slow
@pytest.mark.parametrize("law", LAWS)
def test_tracks_a_circle(world: CtcWorld, law: str) -> None:
    """A 10 mm circle at 5 mm/s: within 20 um of the reference all along (the held force's
    lag), within 2 um at the end."""
    R0, t0 = home_pose(world.truth)
    ref = PoseTrajectory("circle", "quintic", R0, t0, speed=0.005, acceleration=0.01,
                         radius=0.01, plane="xy")
    ctrl = registry.create(law)  # the defaults: 2 Hz, zeta 1
    ctrl.reset(world.context(world.goal(ref.end_rotation, ref.end_translation), ref))
    steps = math.ceil(ref.duration / DT) + 25
    p, _, cmds = world.run(ctrl, (R0, t0), steps)
    p_ref = ref.at(DT * np.arange(steps + 1)).translation
    err = np.linalg.norm(p - p_ref, axis=1)
    assert np.abs(p_ref - t0).max() > 0.009  # it went round the circle
    assert err.max() < 20e-6, err.max()
    assert err[-1] < 2e-6, err[-1]
    assert all(np.all(np.isfinite(c.forces)) for c in cmds)


@pytest.mark.parametrize("law", LAWS)
def test_tracks_a_line_with_a_rotation(world: CtcWorld, law: str) -> None:
    """A 12 mm line with a 2 degree rotation: the rotational reference terms too. Through
    the study's tracking wrapper (:class:`controllers.tracking.TrackingController`), which
    passes these laws through: they sample the reference themselves, anchored at the
    taught goal."""
    assert_tracks_the_rotated_line(world, registry.create(law))


@pytest.mark.parametrize("law", LAWS)
def test_step_is_the_designed_second_order(world: CtcWorld, law: str) -> None:
    """A 1-2 mm step of the goal without smoothing: every axis of the true position
    error follows one second-order response whose natural frequency and damping,
    fitted, are the zero-order-hold design's (2 Hz, zeta 0.3 held over 20 ms)."""
    fn, zeta = 2.0, 0.3
    R0, t0 = home_pose(world.truth)
    step = np.array([0.002, -0.001, 0.0015])
    ctrl = registry.create(law, natural_frequency=fn, damping=zeta, smooth_goal=False)
    ctrl.reset(world.context(world.goal(R0, t0 + step)))
    p, _, _ = world.run(ctrl, (R0, t0), 100)
    e = (p - t0 - step) / step  # -1 at t = 0 on every axis
    t = DT * np.arange(len(e))
    omega = 2 * math.pi * fn
    (w_fit, z_fit), _ = curve_fit(_step_response, np.tile(t, 3), e.T.ravel(),
                                  p0=(omega, zeta))
    residual = np.abs(e - _step_response(t, w_fit, z_fit)[:, None]).max()
    w_zoh, z_zoh = _sampled_design(omega, zeta)
    # measured (deltalab, 2 mm step): fits within 0.1 % and 0.002 of the ZOH design,
    # residuals 0.0065 (pose task, square: the continuous shape against the sampled
    # loop), 0.011 (edges) and 0.0073 (directions: least squares over 36 and 18 rows)
    exact = law in ("cartesian-ctc", "vision-ctc")
    assert residual < (0.01 if exact else 0.02), residual
    assert w_fit == pytest.approx(w_zoh, rel=0.005)
    assert z_fit == pytest.approx(z_zoh, abs=0.005)
    overshoot = e.max()
    assert overshoot == pytest.approx(math.exp(-math.pi * z_zoh / math.sqrt(1 - z_zoh**2)),
                                      abs=0.03)


@pytest.mark.parametrize("law", LAWS)
def test_bad_measurements_are_refused_with_a_reason(world: CtcWorld, law: str) -> None:
    R0, t0 = home_pose(world.truth)
    ctrl = registry.create(law)
    ctrl.reset(world.context(world.goal(R0, t0 + np.array([0.002, 0.0, 0.0]))))
    from hexapod.dynamics.robots import DynamicRobots

    robot = DynamicRobots([world.truth], R0[None].copy(), t0[None].copy())
    good = world.observation(robot, 0.0)

    def check(obs: Observation, words: str) -> None:
        cmd = ctrl.step(obs)
        assert cmd.reason is not None and words in cmd.reason, cmd.reason
        assert cmd.reason.startswith(law)
        assert cmd.actuation is Actuation.FORCE
        np.testing.assert_array_equal(cmd.values, np.zeros(6))

    bad = good.lengths.copy()
    bad[1] = np.nan
    check(dataclasses.replace(good, lengths=bad), "lengths not finite")
    check(dataclasses.replace(good, q_dot=None), "q_dot")
    qd = np.zeros(6)
    qd[3] = np.inf
    check(dataclasses.replace(good, q_dot=qd), "leg velocities not finite")
    if law == "cartesian-ctc":
        return  # the encoders only
    # four legs hidden: two left, too few for a pose or six independent feature rows
    hidden = np.array([True, True, False, True, False, True])
    normals = np.array(good.normals)
    normals[hidden] = np.nan
    directions = np.array(good.directions)
    directions[hidden] = np.nan
    few = dataclasses.replace(good, normals=normals, directions=directions,
                              edge_visible=~np.repeat(hidden[:, None], 2, axis=1),
                              direction_visible=~hidden)
    check(few, "only 2 legs seen" if law == "vision-ctc" else "rank")
    # one leg hidden: the others are enough
    one = np.zeros(6, bool)
    one[4] = True
    normals = np.array(good.normals)
    normals[one] = np.nan
    directions = np.array(good.directions)
    directions[one] = np.nan
    cmd = ctrl.step(dataclasses.replace(
        good, normals=normals, directions=directions,
        edge_visible=~np.repeat(one[:, None], 2, axis=1), direction_visible=~one))
    assert cmd.reason is None, cmd.reason
    assert np.all(np.isfinite(cmd.forces)) and np.abs(cmd.forces).max() > 0


@pytest.mark.parametrize("law", ["leg-edge-ctc", "leg-direction-ctc"])
def test_reference_features_on_the_grid_and_off_it(world: CtcWorld, law: str) -> None:
    """The features of the reference precomputed on the control grid are those computed
    on demand for an instant off the grid (2 ns later: the same forces to 1e-6)."""
    R0, t0, R1, t1, ref = line_reference(world.truth, "quintic", (1.0, -1.0, 0.5))
    on, off = registry.create(law), registry.create(law)
    for c in (on, off):
        c.reset(world.context(world.goal(R1, t1), ref))
    from hexapod.dynamics.robots import DynamicRobots

    robot = DynamicRobots([world.truth], R0[None].copy(), t0[None].copy())
    robot.drives.mode = "force"
    for k in range(15):
        obs = world.observation(robot, k * DT)
        a = on.step(obs)
        b = off.step(dataclasses.replace(obs, t=k * DT + 2e-9))
        assert a.reason is None and b.reason is None
        np.testing.assert_allclose(a.forces, b.forces, rtol=1e-6, atol=1e-6)
        robot.advance(np.arange(1), np.asarray(a.forces)[None], DT / 20, 20)
