"""The latency compensator on single observations: an image from the past, predicted to
the control instant with an exact model, gives the command of the image taken at the
instant; missing or non-finite features give a refusal with a reason, never a NaN."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from controllers.latency import LatencyCompensated
from controllers.registry import registry
from tests.controllers.controller_world import World, make_camera


@pytest.fixture(params=["perspective", "unified"])
def world(request: pytest.FixtureRequest, other_geometry) -> World:  # type: ignore[no-untyped-def]
    return World(other_geometry, make_camera(request.param, other_geometry))


@pytest.mark.parametrize("law", ["leg-edge", "leg-direction"])
def test_an_old_image_predicted_with_an_exact_model(world: World, law: str) -> None:
    (R0, R1, Rg), (t0, t1, tg) = world.poses(3, np.random.default_rng(5), margin=0.02)
    # the legs move linearly from pose 0 (image at 0.0 s) to pose 1 (now, 0.02 s)
    q0 = world.legs(R0, t0).lengths
    ctx = world.context(world.goal(Rg, tg), 0.02)
    comp = LatencyCompensated(law=law)
    comp.reset(ctx)
    plain = registry.create(law)
    plain.reset(ctx)
    comp.step(world.observation(R0, t0, 0.0))
    now = world.observation(R1, t1, 0.02)
    old = world.observation(R0, t0, 0.0)
    late = replace(now, normals=old.normals, lines=old.lines, directions=old.directions,
                   image_t=0.0)
    assert np.abs(world.legs(R1, t1).lengths - q0).max() > 1e-3  # a real motion
    expected = plain.step(now)
    got = comp.step(late)
    assert got.ok and expected.ok
    np.testing.assert_allclose(got.velocities, expected.velocities, rtol=1e-7, atol=1e-10)
    # without the prediction the command differs
    assert np.abs(plain.step(late).velocities - expected.velocities).max() > 1e-4


def test_non_finite_features_are_refused_with_a_reason(world: World) -> None:
    (R0, R1, Rg), (t0, t1, tg) = world.poses(3, np.random.default_rng(6), margin=0.02)
    comp = LatencyCompensated(law="leg-edge")
    comp.reset(world.context(world.goal(Rg, tg), 0.02))
    comp.step(world.observation(R0, t0, 0.0))
    obs = world.observation(R1, t1, 0.02)
    normals = np.array(obs.normals)
    normals[2, 1] = np.nan
    lines = None if obs.lines is None else np.array(obs.lines)
    if lines is not None:
        lines[2, 1] = np.nan
    cmd = comp.step(replace(obs, normals=normals, lines=lines, image_t=0.0))
    assert not cmd.ok and cmd.reason and "not finite" in cmd.reason
    assert np.all(np.isfinite(cmd.velocities)) and not np.any(cmd.velocities)
    # a hidden edge stays hidden: the law runs on the others
    visible = np.ones((6, 2), dtype=bool)
    visible[2, 1] = False
    hidden = replace(obs, normals=normals, lines=lines, edge_visible=visible,
                     direction_visible=visible.all(axis=1), image_t=0.0)
    cmd = comp.step(hidden)
    assert cmd.ok, cmd.reason
    assert np.all(np.isfinite(cmd.velocities))
