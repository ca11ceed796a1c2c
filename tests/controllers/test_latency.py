"""The latency compensator: an image from the past, predicted to the control instant with
an exact model, gives the command of the image taken at the instant; missing or
non-finite features give a refusal with a reason, never a NaN. Over a batch: the same
commands as one compensator per trial stepped alone, to the last bit, with late and
on-time images, hidden edges, measured rates on some rows, a non-finite time, a trial
missing from some periods, both cameras and both observation paths (compiled and numpy);
and the law's goal changed through ``retarget_batch``."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from controllers.base import GoalBatch
from controllers.batch import batch_controller
from controllers.latency import LatencyCompensated
from controllers.registry import registry
from tests.controllers.controller_world import World, make_camera
from tests.controllers.one_by_one import OneByOne
from tests.controllers.test_tracking import _batch, _goal, _hidden, _observation, _same

DT = 0.02


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


@pytest.mark.parametrize("kind", ["perspective", "unified"])
@pytest.mark.parametrize("compiled", [True, False])
@pytest.mark.parametrize("law", ["leg-edge", "leg-direction", "model-based"])
def test_batch_rows_equal_one_compensator_per_trial(kind: str, compiled: bool, law: str,
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    from hexapod.geometry import deltalab
    from vision import fast_observe

    if not compiled:
        monkeypatch.setattr(fast_observe, "compiled", lambda: False)
    g = deltalab()
    world = World(g, make_camera(kind, g))
    rng = np.random.default_rng(21)
    n = 4
    Rs, ts = world.poses(n * 2, rng, max_translation=0.01, max_angle=np.deg2rad(2.0))
    contexts = [world.context(_goal(world, Rs[n + i], ts[n + i]), DT) for i in range(n)]
    options: dict[str, Any] = {"law": law, "adaptive_gain": [5.0, 1.0, 30.0]}
    batch = batch_controller("latency-compensated", options)
    assert isinstance(batch, LatencyCompensated)
    batch.reset_batch(contexts)
    singles = OneByOne(lambda: batch_controller("latency-compensated", options), contexts)
    R, t = Rs[:n].copy(), ts[:n].copy()
    past: list[list[Any]] = [[] for _ in range(n)]  # each trial's earlier observations
    late_rows = 0
    for k in range(25):
        trials = [i for i in range(n) if not (i == 3 and k % 7 == 5)]
        rows = []
        for i in trials:
            t[i] = t[i] + 4e-4 * rng.normal(size=3)
            obs = _observation(world, R[i], t[i], k * DT,
                               _hidden(rng, 0.1) if rng.random() < 0.25 else None)
            if i % 2 == 0:
                obs.q_dot = 0.01 * rng.normal(size=6)
            past[i].append(obs)
            if k >= 2 and rng.random() < 0.8:  # an image two periods old
                old = past[i][-3]
                obs.normals, obs.lines = old.normals, old.lines
                obs.directions, obs.edge_visible = old.directions, old.edge_visible
                obs.direction_visible = old.direction_visible
                obs.image_t = old.t
                late_rows += 1
            if k == 12 and i == 1:
                obs.t = float("nan")
            rows.append(obs)
        if k == 15:  # a new goal for two trials
            goals = [_goal(world, Rs[i] @ Rs[0].T @ Rs[n + i], ts[n + i] + 0.001)
                     for i in (0, 2)]
            gb = GoalBatch(**{f: np.array([getattr(x, f) for x in goals])
                              for f in ("normals", "lines", "directions", "lengths",
                                        "rotation", "translation", "edge_visible")})
            batch.retarget_batch(np.array([0, 2]), gb)
            for i, goal in zip((0, 2), goals, strict=True):
                singles.controllers[i].retarget(goal)
        _same(batch.step_batch(_batch(rows, trials)), singles.step_batch(_batch(rows, trials)))
    assert late_rows > 40
