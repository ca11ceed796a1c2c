"""``leg-edge-force-mpc`` and ``pose-force-mpc`` (:mod:`controllers.force_mpc`) on the
dynamic world of the computed-torque tests (:mod:`tests.controllers.ctc_world`: the
study's integrator, force-mode drives, the camera seeing the true legs, exact encoders).

- its prediction against the world rolled with the planned forces (exact model, no
  noise): the same integration step gives the same numbers to rounding; the default
  step (4 per period) against the world's 1 ms step differs by a first-order
  integration error, bounded from the prediction itself (Richardson);
- its plan never leaves the drives' force limits (random states and goals, a drive
  weak enough that the limits bind);
- it reaches a fixed goal and tracks a circle in closed loop;
- bad input is refused (zero forces, a reason), never a NaN force.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from controllers import registry
from controllers.base import Observation
from controllers.exceptions import ContextError, OptionError
from controllers.force_mpc import ForceMPCLaw
from hexapod import HexapodGeometry, sample_poses
from hexapod.actuation import Actuation
from hexapod.dynamics.robots import DynamicRobots
from hexapod.se3 import exp_so3, pose_error
from hexapod.trajectory import PoseTrajectory
from hexapod.workspace import home_pose
from tests.controllers.ctc_world import DT, PHYSICS_STEPS, CtcWorld, ideal_drives

NAME = "leg-edge-force-mpc"
POSE = "pose-force-mpc"
#: Each force MPC and the computed-torque law of the same features (its fallback).
PAIRS = [(NAME, "leg-edge-ctc"), (POSE, "cartesian-ctc")]


def _goal_away(g: HexapodGeometry) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Home, and a goal (8, -6, 6) mm and (1, -1, 2) deg away."""
    R0, t0 = home_pose(g)
    return R0, t0, R0 @ exp_so3(np.deg2rad([1.0, -1.0, 2.0])), t0 + np.array(
        [0.008, -0.006, 0.006])


def _moving_state(world: CtcWorld, goal: tuple[np.ndarray, np.ndarray], start: tuple[
        np.ndarray, np.ndarray], periods: int = 15) -> DynamicRobots:
    """The true robot after ``periods`` of ``leg-edge-ctc`` towards ``goal`` from rest:
    a state in motion (leg speeds of several mm/s, drives out of their friction's
    Coulomb zone)."""
    robot = DynamicRobots([world.truth], start[0][None].copy(), start[1][None].copy())
    robot.drives.mode = "force"
    ctc = registry.create("leg-edge-ctc")
    ctc.reset(world.context(world.goal(*goal)))
    for k in range(periods):
        cmd = ctc.step(world.observation(robot, k * DT))
        assert cmd.reason is None
        assert not robot.advance(np.arange(1), np.asarray(cmd.forces)[None], DT / PHYSICS_STEPS,
                                 PHYSICS_STEPS).any()
    return robot


def _world_rollout(world: CtcWorld, robot: DynamicRobots, plan: np.ndarray,
                   physics_steps: int) -> dict[str, np.ndarray]:
    """A copy of ``robot`` rolled with the plan's forces, each held over a period in
    ``physics_steps`` steps: its leg lengths [m], leg rates [m/s] (N, 6) and the edge
    normals the camera sees (N, 36) at the end of every period."""
    twin = DynamicRobots([world.truth], robot.R.copy(), robot.t.copy())
    twin.drives.mode = "force"
    twin.twist[:] = robot.twist
    out: dict[str, list[np.ndarray]] = {"lengths": [], "rates": [], "features": [],
                                        "pose": []}
    for f in plan.reshape(-1, 6):
        assert not twin.advance(np.arange(1), f[None], DT / physics_steps, physics_steps).any()
        obs = world.observation(twin, 0.0)
        out["lengths"].append(twin.period_lengths[0].copy())
        out["rates"].append(np.asarray(obs.q_dot))
        out["features"].append(np.asarray(obs.normals).ravel())
        out["pose"].append(np.concatenate([twin.t[0], twin.R[0].T.ravel()]))
    return {k: np.array(v) for k, v in out.items()}


def _planned(world: CtcWorld, robot: DynamicRobots, goal: tuple[np.ndarray, np.ndarray],
             t: float, name: str = NAME, **options: object) -> ForceMPCLaw:
    """A force MPC reset towards ``goal`` that has planned from the robot's state."""
    ctrl = registry.create(name, **options)
    assert isinstance(ctrl, ForceMPCLaw)
    ctrl.reset(world.context(world.goal(*goal)))
    cmd = ctrl.step(world.observation(robot, t))
    assert cmd.reason is None and ctrl.stats.fallbacks == 0, cmd.notes
    return ctrl


# ----------------------------------------------------------------------------- prediction
@pytest.mark.slow
@pytest.mark.parametrize(("name", "substeps"), [(NAME, 4), (NAME, PHYSICS_STEPS), (POSE, 4)])
def test_prediction_is_the_worlds_integration(geometry: HexapodGeometry, name: str,
                                              substeps: int) -> None:
    """Exact model, no noise, the world stepped as the prediction steps (``dt /
    substeps``; 20 is the studies' 1 ms): the predicted leg lengths and rates are the
    world's along the planned forces.

    Tolerance: the prediction starts from the nominal forward kinematics of the lengths
    (residual below 1e-12 m) and ``K^-1 q_dot``; the rest is the same operations on the
    same model. Lengths move with the pose one for one and the twist's error grows at
    most as ``T = N dt = 0.2 s`` times the rate's, so 1e-9 m and 1e-9 m/s leave three
    orders of magnitude for the rounding of 10 x 20 steps."""
    world = CtcWorld.make(geometry)  # the robot file's drives: friction and rotor inertia
    R0, t0, R1, t1 = _goal_away(geometry)
    robot = _moving_state(world, (R1, t1), (R0, t0))
    ctrl = _planned(world, robot, (R1, t1), 15 * DT, name, substeps=substeps)
    assert ctrl.plan is not None
    pred = ctrl.prediction()
    truth = _world_rollout(world, robot, ctrl.plan, substeps)
    assert np.abs(truth["rates"][0]).max() > 5e-3  # in motion
    assert np.abs(pred["lengths"] - truth["lengths"]).max() < 1e-9
    assert np.abs(pred["rates"] - truth["rates"]).max() < 1e-9
    # the predicted normals are those the camera sees of the world's poses (unit
    # vectors moving with the pose at about 1/|A| ~ 3 per metre: the same 1e-9), the
    # predicted poses the world's
    key = "features" if name == NAME else "pose"
    assert np.abs(pred["features"] - truth[key]).max() < 1e-9


@pytest.mark.slow
def test_default_prediction_against_the_1ms_world(geometry: HexapodGeometry) -> None:
    """The default prediction (4 steps of 5 ms per period) against the world's 1 ms step:
    the difference is the first-order integration error of the (semi-implicit) Euler
    scheme, bounded from the prediction itself (Richardson), not tuned: with an error
    ``C h`` for a step ``h``, ``p_4 - world = C (5 - 1) ms`` and ``p_4 - p_8 = C (5 - 2.5)
    ms``, so ``|p_4 - world| = 1.6 |p_4 - p_8|``; the test allows ``2.4`` (the first-order
    term dominating the higher-order ones by at least two to one)."""
    world = CtcWorld.make(geometry)
    R0, t0, R1, t1 = _goal_away(geometry)
    robot = _moving_state(world, (R1, t1), (R0, t0))
    ctrl = _planned(world, robot, (R1, t1), 15 * DT)
    fine = _planned(world, robot, (R1, t1), 15 * DT, substeps=8)
    assert ctrl.plan is not None
    p4 = ctrl.prediction()
    p8 = fine.prediction(ctrl.plan)  # the same forces, the finer step
    truth = _world_rollout(world, robot, ctrl.plan, PHYSICS_STEPS)
    for key in ("lengths", "rates", "features"):
        world_value = truth[key]
        err4 = np.abs(p4[key] - world_value).max()
        step_difference = np.abs(p4[key] - p8[key]).max()
        print(f"{key}: |p4 - world| {err4:.3g}, |p4 - p8| {step_difference:.3g}")
        assert err4 <= 2.4 * step_difference, (key, err4, step_difference)


def test_one_gauss_newton_step_plans_far_from_its_rollout(geometry: HexapodGeometry) -> None:
    """The reason for the default ``max_iter`` (docs/dynamic-world.md, "Why three
    Gauss-Newton QPs"): from rest towards the goal 12 mm away (exact model, no noise),
    the nonlinear prediction along the plan of a single Gauss-Newton QP (the real-time
    iteration) ends far from the goal's normals (measured: 0.41 at the last stage, the
    plan's cost 0.20), where the plan of the default's three QPs ends within a sixth of
    that (0.039, cost 0.0073)."""
    world = CtcWorld.make(geometry)
    R0, t0, R1, t1 = _goal_away(geometry)
    end, cost = {}, {}
    for max_iter in (1, None):
        ctrl = registry.create(NAME) if max_iter is None else registry.create(
            NAME, max_iter=max_iter)
        assert isinstance(ctrl, ForceMPCLaw)
        ctrl.reset(world.context(world.goal(R1, t1)))
        robot = DynamicRobots([world.truth], R0[None].copy(), t0[None].copy())
        robot.drives.mode = "force"
        cmd = ctrl.step(world.observation(robot, 0.0))
        assert cmd.reason is None and ctrl.stats.fallbacks == 0
        pred = ctrl.prediction()
        reference = np.asarray(world.goal(R1, t1).normals, dtype=float).ravel()
        end[max_iter] = float(np.linalg.norm(pred["features"][-1] - reference))
        cost[max_iter] = pred["cost"]
    assert end[1] > 0.3
    assert end[None] < end[1] / 6
    assert cost[None] < cost[1] / 10


# ----------------------------------------------------------------------------- limits
@pytest.mark.slow
def test_plans_stay_within_the_force_limits(geometry: HexapodGeometry) -> None:
    """Random states (poses within 30 mm and 6 deg, twists up to 50 mm/s and 0.3 rad/s)
    and random goals, drives of 30 N (the robot needs about 10 N per leg against
    gravity): every planned force of every stage within its limit, and the limits bind
    (the test would otherwise say nothing)."""
    limit = 30.0
    truth = dataclasses.replace(geometry, drives=dataclasses.replace(
        geometry.drives, force_limit=np.full(6, limit)))
    world = CtcWorld.make(truth)
    rng = np.random.default_rng(37)
    Rs, ts = sample_poses(truth, 40, rng=rng, max_translation=0.03, max_angle=np.deg2rad(6),
                          margin=0.015)
    at_limit = 0
    for k in range(0, 40, 2):
        robot = DynamicRobots([truth], Rs[k][None].copy(), ts[k][None].copy())
        robot.drives.mode = "force"
        robot.twist[:] = np.concatenate([rng.uniform(-0.05, 0.05, 3),
                                         rng.uniform(-0.3, 0.3, 3)])
        ctrl = registry.create(NAME, smooth_goal=False)  # the goal as a step: large errors
        ctrl.reset(world.context(world.goal(Rs[k + 1], ts[k + 1])))
        cmd = ctrl.step(world.observation(robot, 0.0))
        assert cmd.reason is None, cmd.reason
        assert ctrl.stats.fallbacks == 0, ctrl.stats.reasons
        assert ctrl.plan is not None
        assert np.all(np.isfinite(ctrl.plan))
        assert np.abs(ctrl.plan).max() <= limit
        assert np.array_equal(np.asarray(cmd.forces), ctrl.plan[:6])
        at_limit += int(np.sum(np.abs(ctrl.plan) >= limit - 1e-9))
    assert at_limit > 20


# ----------------------------------------------------------------------------- closed loop
@pytest.mark.slow
@pytest.mark.parametrize(("name", "ctc"), PAIRS)
def test_reaches_a_fixed_goal(geometry: HexapodGeometry, name: str, ctc: str) -> None:
    """The robot file's drives (friction, rotor inertia), exact model: within the studies'
    tolerances (0.5 mm, 0.05 deg; ``quick-dynamic``) after 3 s, as the computed torque of
    the same features is, no fallback, every force finite and within the limits."""
    world = CtcWorld.make(geometry)
    R0, t0, R1, t1 = _goal_away(geometry)
    for law in (name, ctc):
        ctrl = registry.create(law)
        ctrl.reset(world.context(world.goal(R1, t1)))
        p, Rs, cmds = world.run(ctrl, (R0, t0), 150)
        dp, dr = pose_error(Rs[-1], p[-1], R1, t1)
        assert np.linalg.norm(dp) < 0.5e-3, law
        assert np.rad2deg(np.linalg.norm(dr)) < 0.05, law
        forces = np.array([c.forces for c in cmds])
        assert np.all(np.isfinite(forces))
        assert np.abs(forces).max() <= geometry.drives.force_limit.max()
        if law == name:
            assert isinstance(ctrl, ForceMPCLaw)
            assert ctrl.stats.fallbacks == 0 and ctrl.stats.steps == 150


@pytest.mark.slow
@pytest.mark.parametrize(("name", "ctc"), PAIRS)
def test_tracks_a_circle_as_the_ctc_does(geometry: HexapodGeometry, name: str, ctc: str) -> None:
    """A 10 mm circle at 20 mm/s, frictionless drives, exact model: the force MPC's
    largest distance to the reference is no larger than that of the computed torque of
    the same features (both measured here), and under 0.1 mm."""
    world = CtcWorld.make(ideal_drives(geometry))
    R0, t0 = home_pose(world.truth)
    ref = PoseTrajectory("circle", "quintic", R0, t0, speed=0.02, acceleration=0.1,
                         radius=0.01, plane="xy")
    steps = math.ceil(ref.duration / DT) + 25
    p_ref = ref.at(DT * np.arange(steps + 1)).translation
    worst = {}
    for law in (name, ctc):
        ctrl = registry.create(law)
        ctrl.reset(world.context(world.goal(ref.end_rotation, ref.end_translation), ref))
        p, _, _ = world.run(ctrl, (R0, t0), steps)
        worst[law] = float(np.linalg.norm(p - p_ref, axis=1).max())
    assert np.abs(p_ref - t0).max() > 0.009  # it went round the circle
    assert worst[name] <= worst[ctc]
    assert worst[name] < 1e-4


@pytest.mark.slow
def test_tracks_within_binding_force_limits(geometry: HexapodGeometry) -> None:
    """A 10 mm circle at up to 100 mm/s and 3 m/s^2 with drives of 16 N (about 10 N per
    leg hold the platform against gravity): the force MPC plans within the limit and
    reaches it (the limit binds), and its largest distance to the reference is smaller
    than that of ``leg-edge-ctc``, whose commands are clipped at the limit (by the law
    itself since its ``saturation`` option, default ``"clip"``; before it, by the drives)
    and reach it too (both measured here)."""
    limit = 16.0
    truth = dataclasses.replace(geometry, drives=dataclasses.replace(
        geometry.drives, force_limit=np.full(6, limit)))
    world = CtcWorld.make(truth)
    R0, t0 = home_pose(truth)
    ref = PoseTrajectory("circle", "quintic", R0, t0, speed=0.1, acceleration=3.0,
                         radius=0.01, plane="xy")
    steps = math.ceil(ref.duration / DT) + 25
    p_ref = ref.at(DT * np.arange(steps + 1)).translation
    worst, forces = {}, {}
    for law in (NAME, "leg-edge-ctc"):
        ctrl = registry.create(law)
        ctrl.reset(world.context(world.goal(ref.end_rotation, ref.end_translation), ref))
        p, _, cmds = world.run(ctrl, (R0, t0), steps)
        worst[law] = float(np.linalg.norm(p - p_ref, axis=1).max())
        forces[law] = np.abs(np.array([c.forces for c in cmds]))
    assert forces[NAME].max() <= limit
    assert np.sum(forces[NAME] >= limit - 1e-9) > 0  # the limit binds
    # the computed torque is clipped at the limit, which binds for it too
    assert forces["leg-edge-ctc"].max() <= limit
    assert np.sum(forces["leg-edge-ctc"] >= limit - 1e-9) > 0
    assert worst[NAME] < worst["leg-edge-ctc"]


# ----------------------------------------------------------------------------- refusals
@pytest.mark.parametrize("name", [NAME, POSE])
def test_options_are_checked(name: str) -> None:
    ctrl = registry.create(name)
    assert ctrl.actuation is Actuation.FORCE
    for key, value in (("horizon", 0), ("horizon", 2.5), ("substeps", True), ("max_iter", 0),
                       ("friction_smoothing", -1.0), ("error_weight", float("nan"))):
        with pytest.raises(OptionError, match=key):
            registry.create(name, **{key: value})
    with pytest.raises(OptionError, match="rate_weight"):
        registry.create(name, rate_weight=0.0, effort_weight=0.0)
    with pytest.raises(OptionError, match="error_weight"):
        registry.create(name, error_weight=0.0, terminal_weight=0.0)


@pytest.mark.slow
def test_bad_input_is_refused_never_a_nan_force(geometry: HexapodGeometry) -> None:
    """NaN lengths, leg rates or time, no leg rates, no normals, every normal NaN: a
    refusal naming the reading, zero forces; a missing camera is a ContextError. One NaN
    edge is a hidden edge: the others still command finite forces."""
    world = CtcWorld.make(geometry)
    R0, t0, R1, t1 = _goal_away(geometry)
    robot = DynamicRobots([geometry], R0[None].copy(), t0[None].copy())
    ctx = world.context(world.goal(R1, t1))
    with pytest.raises(ContextError, match="camera"):
        registry.create(NAME).reset(dataclasses.replace(ctx, camera=None))
    with pytest.raises(ContextError, match=r"goal\.normals"):
        registry.create(NAME).reset(dataclasses.replace(
            ctx, goal=dataclasses.replace(ctx.goal, normals=None)))
    ctrl = registry.create(NAME)
    ctrl.reset(ctx)
    good = world.observation(robot, 0.0)
    nan_lengths = np.array(good.lengths, dtype=float)
    nan_lengths[2] = np.nan
    nan_normals = np.full((6, 2, 3), np.nan)
    cases = {
        "lengths": dataclasses.replace(good, lengths=nan_lengths),
        "leg velocities": dataclasses.replace(good, q_dot=np.full(6, np.nan)),
        "time": dataclasses.replace(good, t=float("nan")),
        "Observation.q_dot": dataclasses.replace(good, q_dot=None),
        "Observation.normals": dataclasses.replace(good, normals=None),
        "edges seen": dataclasses.replace(good, normals=nan_normals),
    }
    for what, obs in cases.items():
        cmd = ctrl.step(obs)
        assert cmd.reason is not None and what in cmd.reason, (what, cmd.reason)
        assert np.array_equal(np.asarray(cmd.forces), np.zeros(6))
    one_hidden = np.array(good.normals, dtype=float)
    one_hidden[3, 1] = np.nan
    cmd = ctrl.step(dataclasses.replace(good, normals=one_hidden))
    assert cmd.reason is None
    assert np.all(np.isfinite(np.asarray(cmd.forces)))
    assert cmd.features_used == 11


@pytest.mark.slow
@pytest.mark.parametrize(("name", "ctc"), PAIRS)
def test_a_failed_nominal_model_falls_back_with_the_reason(geometry: HexapodGeometry,
                                                            name: str, ctc: str) -> None:
    """Lengths no pose has (forward kinematics fails; each could be a leg): the held law's
    command, noting ``force-mpc fallback: <reason>``, counted with its reason. Lengths no
    leg can have are refused before, with the leg and the value."""
    world = CtcWorld.make(geometry)
    R0, t0, R1, t1 = _goal_away(geometry)
    robot = DynamicRobots([geometry], R0[None].copy(), t0[None].copy())
    ctrl = registry.create(name)
    ctrl.reset(world.context(world.goal(R1, t1)))
    good = world.observation(robot, 0.0)
    assert ctrl.step(good).reason is None
    far = ctrl.step(dataclasses.replace(good, lengths=np.array([0.05, 3.0] * 3)))
    assert far.reason == (f"{name}: measured lengths: leg 0 at 0.05 m, where no leg of the "
                          "nominal robot can be (its stroke 345 to 485 mm)")
    assert ctrl.stats.fallbacks == 0
    cmd = ctrl.step(dataclasses.replace(good, t=0.02, lengths=np.array([0.21, 0.62] * 3)))
    assert cmd.reason is not None and cmd.reason.startswith(f"{ctc}: ")  # the held law's
    reason = "nominal model failed: forward kinematics"
    assert any(n.startswith(f"force-mpc fallback: {reason}") for n in cmd.notes), cmd.notes
    assert ctrl.stats.fallbacks == 1 and next(iter(ctrl.stats.reasons)).startswith(reason)


def test_step_before_reset_refuses() -> None:
    cmd = registry.create(NAME).step(Observation(0.0, np.full(6, 0.4), q_dot=np.zeros(6)))
    assert not cmd.ok and "reset" in (cmd.reason or "")


@pytest.mark.slow
def test_virtual_machine_gives_the_compiled_results(geometry: HexapodGeometry) -> None:
    """``compiled = False`` (the CasADi virtual machine, ``casadi.conic``) plans the same
    forces as the generated C, to rounding (the same expression graph)."""
    world = CtcWorld.make(geometry)
    R0, t0, R1, t1 = _goal_away(geometry)
    robot = _moving_state(world, (R1, t1), (R0, t0), periods=5)
    plans = [_planned(world, robot, (R1, t1), 5 * DT, compiled=c).plan for c in (True, False)]
    assert plans[0] is not None and plans[1] is not None
    assert np.abs(plans[0] - plans[1]).max() < 1e-9 * max(1.0, float(np.abs(plans[0]).max()))


@pytest.mark.slow
def test_pose_variant_refuses_bad_readings_and_names_a_missing_goal(
        geometry: HexapodGeometry) -> None:
    """``pose-force-mpc`` needs no camera (its features are the encoders' pose) but the
    goal pose; NaN lengths or leg rates are refused with zero forces."""
    world = CtcWorld.make(geometry)
    R0, t0, R1, t1 = _goal_away(geometry)
    ctx = world.context(world.goal(R1, t1))
    with pytest.raises(ContextError, match=r"goal\.rotation"):
        registry.create(POSE).reset(dataclasses.replace(
            ctx, goal=dataclasses.replace(ctx.goal, rotation=None)))
    ctrl = registry.create(POSE)
    ctrl.reset(dataclasses.replace(ctx, camera=None))
    robot = DynamicRobots([geometry], R0[None].copy(), t0[None].copy())
    good = world.observation(robot, 0.0)
    for what, obs in (("lengths", dataclasses.replace(good, lengths=np.full(6, np.nan))),
                      ("leg velocities", dataclasses.replace(good, q_dot=np.full(6, np.inf)))):
        cmd = ctrl.step(obs)
        assert cmd.reason is not None and what in cmd.reason, cmd.reason
        assert np.array_equal(np.asarray(cmd.forces), np.zeros(6))
    cmd = ctrl.step(dataclasses.replace(good, normals=None, directions=None))
    assert cmd.reason is None and np.all(np.isfinite(np.asarray(cmd.forces)))


@pytest.mark.parametrize("max_iter", [1, 3, 20])
def test_the_note_says_whether_the_plan_converged(geometry: HexapodGeometry,
                                                  max_iter: int) -> None:
    """The command's note carries the SQP's own status (converged in k iterations, or
    not, with its last step) beside the last QP's, and ``stats.unconverged`` counts the
    periods that applied an unconverged plan: a plan from rest 12 mm from its goal does
    not converge in its first period within 20 QPs (its Gauss-Newton steps cycle: the
    docs' "Solver"), which the note said nothing of (only "unconstrained optimum")."""
    world = CtcWorld.make(geometry)
    R0, t0, R1, t1 = _goal_away(geometry)
    robot = DynamicRobots([world.truth], R0[None].copy(), t0[None].copy())
    robot.drives.mode = "force"
    ctrl = registry.create(NAME, max_iter=max_iter)
    ctrl.reset(world.context(world.goal(R1, t1)))
    notes = []
    for k in range(3):
        cmd = ctrl.step(world.observation(robot, k * DT))
        assert cmd.reason is None and ctrl.stats.fallbacks == 0, cmd.notes
        (note,) = cmd.notes
        notes.append(note)
        assert note.startswith("force-mpc: "), note
        assert "SQP iteration" in note and "; last QP: " in note, note
        robot.advance(np.arange(1), np.asarray(cmd.forces)[None], DT / PHYSICS_STEPS,
                      PHYSICS_STEPS)
    unconverged = sum(n.startswith("force-mpc: not converged") for n in notes)
    assert unconverged >= 1  # the first period's plan, at least (measured: all three)
    assert ctrl.stats.unconverged == (unconverged if max_iter > 1 else 0)
