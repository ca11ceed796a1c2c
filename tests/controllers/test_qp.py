"""The QP law (OSQP): classical command away from limits, strokes never violated at a limit."""

from __future__ import annotations

import numpy as np
import pytest

from controllers import registry
from controllers.solvers.osqp_limits import LimitQP
from hexapod.kinematics import inverse_jacobian
from tests.controllers.controller_world import World, closed_loop, make_camera

PAIRS = [("leg-edge", "leg-edge-qp"), ("leg-direction", "leg-direction-qp")]


@pytest.fixture(params=["perspective", "unified"])
def world(request: pytest.FixtureRequest, other_geometry) -> World:  # type: ignore[no-untyped-def]
    return World(other_geometry, make_camera(request.param, other_geometry))


@pytest.mark.parametrize(("classical", "qp"), PAIRS)
def test_matches_the_classical_law_away_from_limits(world: World, classical: str, qp: str,
                                                    rng: np.random.Generator) -> None:
    Rs, ts = world.poses(6, rng, max_translation=0.02, max_angle=np.deg2rad(4), margin=0.03)
    goal = world.goal(Rs[0], ts[0])
    a = registry.create(classical, gain=0.5)
    b = registry.create(qp, gain=0.5)
    a.reset(world.context(goal, 0.02))
    b.reset(world.context(goal, 0.02))
    for R, t in zip(Rs[1:], ts[1:], strict=True):
        obs = world.observation(R, t)
        ca, cb = a.step(obs), b.step(obs)
        assert ca.ok and cb.ok, (ca.reason, cb.reason)
        assert cb.active_constraints == []
        scale = np.abs(ca.velocities).max()
        assert scale > 1e-4  # a real motion, below the speed limit
        assert scale < world.geometry.max_speed
        np.testing.assert_allclose(cb.velocities, ca.velocities, rtol=0, atol=1e-6 * scale)
        np.testing.assert_allclose(cb.twist, ca.twist, rtol=0,
                                   atol=1e-6 * np.abs(ca.twist).max())
    assert b.solver.qp._solver is not None  # set up once, then updated and warm-started


def _pose_with_long_legs(world: World, extra: float) -> tuple[np.ndarray, np.ndarray]:
    """The home pose moved so that legs 0 and 1 reach ``q_max + extra``, the others fixed
    (seed 002's long rear legs); resolved-rate path, so no jump of assembly mode."""
    geo = world.geometry
    R, t = world.home()
    target = geo.q_max + extra
    for _ in range(1000):
        legs = world.legs(R, t)
        gap = target - legs.lengths[:2].max()
        if abs(gap) < 1e-12:
            break
        qdot = np.zeros(6)
        qdot[:2] = np.clip(target - legs.lengths[:2], -0.002, 0.002)
        tau = np.linalg.solve(inverse_jacobian(legs.base_points, legs.directions), qdot)
        R, t = world.move(R, t, tau, 1.0)
    return R, t


@pytest.mark.parametrize("kind", ["perspective", "unified"])
@pytest.mark.parametrize(("classical", "qp"), PAIRS)
def test_never_violates_a_stroke(geometry, kind: str, classical: str, qp: str) -> None:  # type: ignore[no-untyped-def]
    """Reference robot (the other one is close to singular at its home pose)."""
    world = World(geometry, make_camera(kind, geometry))
    geo = world.geometry
    dt, margin = 0.02, 0.002
    start = _pose_with_long_legs(world, -0.03)
    goal = _pose_with_long_legs(world, 0.005)  # 5 mm beyond the stroke
    ctx = world.context(world.goal(*goal), dt, margin=margin)
    # The classical law drives the legs beyond the stroke (so the test can fail) ...
    ref = registry.create(classical, gain=2.0)
    ref.reset(ctx)
    run_ref = closed_loop(world, ref, start, goal, dt, 300, move_legs=True)
    assert run_ref.lengths[:, :2].max() > geo.q_max + 0.004
    # ... the QP law never goes past q_max - margin, nor past the speed limit.
    law = registry.create(qp, gain=2.0)
    law.reset(ctx)
    run = closed_loop(world, law, start, goal, dt, 300, move_legs=True)
    assert run.lengths.max() <= geo.q_max - margin + 1e-9
    assert run.lengths.min() >= geo.q_min + margin - 1e-9
    assert np.abs(run.velocities).max() <= geo.max_speed * (1 + 1e-9)
    # It slides along the limit: legs 0/1 end at the limit, the others keep moving.
    assert run.lengths[-1, :2].max() > geo.q_max - margin - 1e-5
    active = [c for cmd in run.commands[-10:] for c in cmd.active_constraints]
    assert any(c in ("leg 0 upper stroke", "leg 1 upper stroke") for c in active), active
    assert run.error_norms[-1] < 0.5 * run.error_norms[0]


def test_solver_failures_are_reported_not_raised(world: World) -> None:
    qp = LimitQP()
    L = np.eye(6)
    J = np.eye(6)
    tau, why = qp.solve(L, np.full(6, np.nan), 1.0, J, -np.ones(6), np.ones(6))
    assert tau is None and "non-finite" in why
    tau, why = qp.solve(L, np.ones(6), 1.0, J, np.ones(6), -np.ones(6))
    assert tau is None and "lower bound above upper" in why
    tau, why = qp.solve(L, np.ones(6), 1.0, J, -np.ones(6), np.ones(6))
    assert tau is not None and why == "solved"
    np.testing.assert_allclose(tau, -np.ones(6), atol=1e-6)


def test_max_iterations_gives_zero_command_with_reason(world: World) -> None:
    Rs, ts = world.poses(2, np.random.default_rng(3), margin=0.02)
    law = registry.create("leg-edge-qp", max_iter=1, eps_abs=1e-12, eps_rel=1e-12)
    law.reset(world.context(world.goal(Rs[0], ts[0]), 0.02))
    cmd = law.step(world.observation(Rs[1], ts[1]))
    assert not cmd.ok
    assert "OSQP status" in (cmd.reason or "")
    assert np.array_equal(cmd.velocities, np.zeros(6))
    assert cmd.rank == 6
