"""The latency compensator over a batch: the same commands as one compensator per trial,
to the last bit, with late and on-time images, hidden edges, measured rates on some rows,
a non-finite time, a trial missing from some periods, both cameras and both observation
paths (compiled and numpy); and the law's goal changed through ``retarget_batch``."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from controllers.base import GoalBatch
from controllers.batch import batch_controller
from controllers.latency import LatencyCompensated
from tests.controllers.controller_world import World, make_camera
from tests.controllers.one_by_one import OneByOne
from tests.controllers.test_tracking_batch import _batch, _goal, _hidden, _observation, _same

DT = 0.02


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
