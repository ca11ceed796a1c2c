"""The shared law: gains, pseudo-inverse, options, closed-loop convergence, missing features."""

from __future__ import annotations

import math

import numpy as np
import pytest

from controllers import registry
from controllers.exceptions import ContextError, OptionError
from controllers.law_tools import INTERACTIONS, Gain
from controllers.laws import VisionLaw
from hexapod.kinematics import inverse_jacobian
from tests.controllers.controller_world import World, closed_loop, make_camera
from tests.controllers.numpy_law import solve_normal_damped

#: Every registered controller whose law is the shared vision law.
VISION = [n for n in registry.names()
          if n in ("leg-direction", "leg-edge", "leg-edge-qp", "leg-direction-qp")
          or isinstance(registry.create(n), VisionLaw)]
CAMERAS = ["perspective", "unified"]


@pytest.fixture(params=CAMERAS)
def world(request: pytest.FixtureRequest, other_geometry) -> World:  # type: ignore[no-untyped-def]
    return World(other_geometry, make_camera(request.param, other_geometry))


def start_and_goal(world: World, seed: int) -> tuple[tuple, tuple]:
    rng = np.random.default_rng(seed)
    Rs, ts = world.poses(2, rng, max_translation=0.03, max_angle=np.deg2rad(6), margin=0.02)
    return (Rs[0], ts[0]), (Rs[1], ts[1])


# ----------------------------------------------------------------------------- gain
def test_constant_gain() -> None:
    g = Gain.from_options("x", gain=0.7)
    assert g.at_zero == g.at_infinity
    assert g(0.0) == g(10.0) == 0.7


def test_adaptive_gain_matches_its_definition() -> None:
    l0, linf, slope = 4.0, 0.4, 30.0
    g = Gain.from_options("x", adaptive_gain=(l0, linf, slope))
    assert g(0.0) == pytest.approx(l0)
    assert g(1e3) == pytest.approx(linf)
    h = 1e-7
    assert (g(h) - g(0.0)) / h == pytest.approx(-slope, rel=1e-5)
    x = 0.05
    assert g(x) == pytest.approx((l0 - linf) * math.exp(-slope * x / (l0 - linf)) + linf)


@pytest.mark.parametrize(("options", "option"), [
    ({"gain": -1.0}, "gain"),
    ({"gain": float("nan")}, "gain"),
    ({"gain": "fast"}, "gain"),
    ({"adaptive_gain": (1.0, 2.0, 3.0)}, "adaptive_gain"),
    ({"adaptive_gain": (4.0, 0.0, 3.0)}, "adaptive_gain"),
    ({"adaptive_gain": (4.0, 1.0)}, "adaptive_gain"),
    ({"interaction": "curent"}, "interaction"),
    ({"threshold": -1e-3}, "threshold"),
    ({"threshold": 2.0}, "threshold"),
    ({"damping": -0.1}, "damping"),
])
@pytest.mark.parametrize("name", VISION)
def test_options_are_validated(name: str, options: dict, option: str) -> None:
    with pytest.raises(OptionError) as info:
        registry.create(name, **options)
    assert info.value.option == option
    assert option in str(info.value)


def test_interaction_option_suggests() -> None:
    with pytest.raises(OptionError, match="did you mean 'current'"):
        registry.create("leg-edge", interaction="curent")


def test_edge_feature_option() -> None:
    with pytest.raises(OptionError, match="edge_feature"):
        registry.create("leg-edge", edge_feature="pixels")


# ----------------------------------------------------------------------------- algebra
def solve_least_squares(L: np.ndarray, e: np.ndarray, threshold: float = 1e-6,
                        damping: float = 0.0) -> tuple[np.ndarray, int, float]:
    return solve_normal_damped(L.T @ L, L.T @ e, threshold, damping * damping)


def test_least_squares_is_the_pseudo_inverse(rng: np.random.Generator) -> None:
    L = rng.normal(size=(36, 6)) * np.array([1.0, 10.0, 0.1, 1.0, 3.0, 0.01])
    e = rng.normal(size=36)
    x, rank, cond = solve_least_squares(L, e)
    np.testing.assert_allclose(x, np.linalg.pinv(L) @ e, rtol=1e-9, atol=1e-12)
    assert rank == 6
    assert cond == pytest.approx(np.linalg.cond(L), rel=1e-8)


def test_least_squares_damping(rng: np.random.Generator) -> None:
    L = rng.normal(size=(18, 6))
    e = rng.normal(size=18)
    mu = 0.3
    x, _, _ = solve_least_squares(L, e, damping=mu)
    np.testing.assert_allclose(x, np.linalg.solve(L.T @ L + mu**2 * np.eye(6), L.T @ e),
                               rtol=1e-10)


def test_least_squares_rank_deficient(rng: np.random.Generator) -> None:
    L = rng.normal(size=(12, 6))
    L[:, 5] = L[:, 0] + 1e-12 * rng.normal(size=12)  # rank 5 numerically
    e = rng.normal(size=12)
    x, rank, cond = solve_least_squares(L, e, threshold=1e-6)
    assert rank == 5
    assert cond > 1e6
    np.testing.assert_allclose(x, np.linalg.pinv(L, rcond=1e-6) @ e, atol=1e-6)


# ----------------------------------------------------------------------------- closed loop
@pytest.mark.slow
@pytest.mark.parametrize("name", VISION)
def test_exponential_decay_and_goal_reached(world: World, name: str) -> None:
    """ė = -λ e: successive error norms shrink by 1 - λ dt, and the goal pose is reached."""
    lam, dt = 2.0, 0.01
    start, goal = start_and_goal(world, 5)
    ctrl = registry.create(name, gain=lam, **({"max_speed": 10.0} if "qp" in name else {}))
    ctrl.reset(world.context(world.goal(*goal), dt))
    run = closed_loop(world, ctrl, start, goal, dt, 1500, stop_below=5e-8)
    ratios = run.error_norms[1:] / run.error_norms[:-1]
    # Exact for a linear error; the non-linearity of the features shows at the start only.
    assert np.max(np.abs(ratios - (1 - lam * dt))) < 2e-3 * lam * dt / 0.02
    assert np.max(np.abs(ratios[len(ratios) // 2:] - (1 - lam * dt))) < 1e-5
    assert run.position_errors[-1] < 1e-6
    assert run.position_errors[0] > 0.01  # the test starts far from the goal


@pytest.mark.parametrize("interaction", ["desired", "mean"])
@pytest.mark.parametrize("name", VISION)
def test_desired_and_mean_interaction_converge(world: World, name: str,
                                               interaction: str) -> None:
    lam, dt = 2.0, 0.01
    start, goal = start_and_goal(world, 6)
    ctrl = registry.create(name, gain=lam, interaction=interaction,
                           **({"max_speed": 10.0} if "qp" in name else {}))
    ctrl.reset(world.context(world.goal(*goal), dt))
    run = closed_loop(world, ctrl, start, goal, dt, 2000, stop_below=5e-8)
    assert run.position_errors[-1] < 1e-6
    tail = run.error_norms[-50:]
    np.testing.assert_allclose(tail[1:] / tail[:-1], 1 - lam * dt, atol=1e-4)


@pytest.mark.parametrize("name", VISION)
def test_adaptive_gain_converges(world: World, name: str) -> None:
    dt = 0.01
    start, goal = start_and_goal(world, 7)
    ctrl = registry.create(name, adaptive_gain=(8.0, 1.0, 200.0),
                           **({"max_speed": 10.0} if "qp" in name else {}))
    ctrl.reset(world.context(world.goal(*goal), dt))
    run = closed_loop(world, ctrl, start, goal, dt, 1000, stop_below=5e-8)
    assert run.position_errors[-1] < 1e-6
    # Near the goal the gain is lambda0.
    tail = run.error_norms[-20:]
    np.testing.assert_allclose(tail[1:] / tail[:-1], 1 - 8.0 * dt, atol=1e-3)


# ----------------------------------------------------------------------------- missing features
@pytest.mark.slow
@pytest.mark.parametrize("name", ["leg-edge", "leg-edge-qp"])
def test_hidden_edges_use_what_is_visible(world: World, name: str) -> None:
    dt = 0.01
    start, goal = start_and_goal(world, 8)
    ctrl = registry.create(name, gain=2.0)
    ctrl.reset(world.context(world.goal(*goal), dt))

    def hide(obs, k):  # type: ignore[no-untyped-def]
        obs.edge_visible = obs.edge_visible.copy()
        obs.edge_visible[2, 0] = False  # one edge of leg 2, always
        if k >= 3:
            obs.edge_visible[4] = False  # both edges of leg 4 after 3 steps
        obs.normals = obs.normals.copy()
        obs.normals[~obs.edge_visible] = np.nan
        if obs.lines is not None:
            obs.lines = obs.lines.copy()
            obs.lines[~obs.edge_visible] = np.nan

    run = closed_loop(world, ctrl, start, goal, dt, 1500, hide=hide, stop_below=5e-8)
    assert "using 11 of 12 edges" in run.commands[0].notes
    assert "using 9 of 12 edges" in run.commands[5].notes
    assert run.commands[5].features_used == 27
    assert any("predicted" in n for n in run.commands[5].notes)
    assert any("desired direction used for never-seen legs 2" in n
               for n in run.commands[0].notes)
    assert run.position_errors[-1] < 1e-6
    # Leg 4's direction is dead-reckoned for J_inv: its velocity stays that of the
    # commanded twist. Leg 2 (never seen whole) uses its desired direction: exact only
    # near the goal.
    last = len(run.commands) - 1
    for k in (5, 50, last // 2, last):
        legs = world.legs(*run.poses[k])
        J_true = inverse_jacobian(legs.base_points, legs.directions)
        legs_checked = list(range(6)) if k == last else [0, 1, 3, 4, 5]
        np.testing.assert_allclose(run.commands[k].velocities[legs_checked],
                                   (J_true @ run.commands[k].twist)[legs_checked],
                                   rtol=0, atol=1e-3 * np.abs(run.velocities[k]).max())


def test_too_few_edges_refuse_with_reason(world: World) -> None:
    start, goal = start_and_goal(world, 9)
    ctrl = registry.create("leg-edge")
    ctrl.reset(world.context(world.goal(*goal), 0.01))
    obs = world.observation(*start)
    obs.edge_visible = np.zeros((6, 2), dtype=bool)
    obs.edge_visible[0] = True  # 2 edges: rank <= 2
    obs.normals = np.where(obs.edge_visible[..., None], obs.normals, np.nan)
    cmd = ctrl.step(obs)
    assert not cmd.ok
    assert "rank" in (cmd.reason or "")
    assert cmd.rank < 6
    assert np.array_equal(cmd.velocities, np.zeros(6))


def test_hidden_leg_direction_for_the_inverse_jacobian(world: World) -> None:
    """J_inv needs every leg direction: measured, dead-reckoned, else the desired one."""
    start, goal = start_and_goal(world, 10)
    ctrl = registry.create("leg-direction")
    ctrl.reset(world.context(world.goal(*goal), 0.01))
    obs = world.observation(*start)
    obs.direction_visible = np.array([True] * 5 + [False])
    cmd = ctrl.step(obs)
    assert cmd.ok, cmd.reason
    assert "using 5 of 6 legs" in cmd.notes
    assert "desired direction used for never-seen legs 5" in cmd.notes
    # Seen once, then hidden: its direction is dead-reckoned.
    ctrl.step(world.observation(*start))
    cmd = ctrl.step(obs)
    assert cmd.ok, cmd.reason
    assert "predicted directions of hidden legs 5" in cmd.notes
    # Never seen and no desired direction: the nominal model predicts it (FK of q).
    g = world.goal(*goal)
    g.directions = g.directions.copy()
    g.directions[5] = np.nan
    ctrl.reset(world.context(g, 0.01))
    cmd = ctrl.step(obs)
    assert cmd.ok, cmd.reason
    assert any(n.startswith("nominal-model directions") and n.endswith("legs 5")
               for n in cmd.notes), cmd.notes
    # ... and without a camera pose there is no prediction: no inverse Jacobian, no motion.
    ctx = world.context(g, 0.01)
    ctx.camera = None
    ctrl.reset(ctx)
    cmd = ctrl.step(obs)
    assert not cmd.ok and "leg 5" in (cmd.reason or "")
    assert np.array_equal(cmd.velocities, np.zeros(6))


def test_nan_in_visible_feature_refuses_and_hidden_nan_is_ignored(world: World) -> None:
    start, goal = start_and_goal(world, 11)
    ctrl = registry.create("leg-edge", edge_feature="normals")
    ctrl.reset(world.context(world.goal(*goal), 0.01))
    obs = world.observation(*start)
    obs.normals = obs.normals.copy()
    obs.normals[3, 1, 2] = np.nan
    cmd = ctrl.step(obs)
    assert not cmd.ok and "normals" in (cmd.reason or "")
    assert np.array_equal(cmd.velocities, np.zeros(6))
    obs.edge_visible = np.ones((6, 2), dtype=bool)
    obs.edge_visible[3, 1] = False
    cmd = ctrl.step(obs)
    assert cmd.ok and np.all(np.isfinite(cmd.velocities))


def test_edge_feature_follows_the_camera(world: World) -> None:
    _, goal = start_and_goal(world, 12)
    ctrl = registry.create("leg-edge")
    ctrl.reset(world.context(world.goal(*goal), 0.01))
    expected = "lines" if world.kind == "perspective" else "normals"
    assert expected in ctrl.features
    forced = registry.create("leg-edge", edge_feature="normals")
    forced.reset(world.context(world.goal(*goal), 0.01))
    assert "normals" in forced.features and "lines" not in forced.features
    if world.kind == "unified":
        with pytest.raises(ContextError, match="camera"):
            registry.create("leg-edge", edge_feature="lines").reset(
                world.context(world.goal(*goal), 0.01))


def test_forced_normals_converge_with_perspective_camera(other_geometry) -> None:  # type: ignore[no-untyped-def]
    world = World(other_geometry, make_camera("perspective", other_geometry))
    start, goal = start_and_goal(world, 13)
    ctrl = registry.create("leg-edge", gain=2.0, edge_feature="normals")
    ctrl.reset(world.context(world.goal(*goal), 0.01))
    run = closed_loop(world, ctrl, start, goal, 0.01, 1500, stop_below=5e-8)
    assert run.position_errors[-1] < 1e-6


@pytest.mark.parametrize("interaction", INTERACTIONS)
def test_missing_goal_features_raise_context_error(world: World, interaction: str) -> None:
    _, goal = start_and_goal(world, 14)
    g = world.goal(*goal)
    g.directions = None
    with pytest.raises(ContextError, match=r"goal\.directions"):
        registry.create("leg-direction", interaction=interaction).reset(world.context(g, 0.01))
    g.normals = None
    g.lines = None
    with pytest.raises(ContextError, match="goal"):
        registry.create("leg-edge", interaction=interaction).reset(world.context(g, 0.01))
