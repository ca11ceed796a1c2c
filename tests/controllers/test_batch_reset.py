"""A batch controller reset again (the next work unit of a worker) starts from scratch:
its per-trial instances do not carry the previous batch, and it commands what a fresh
batch controller commands."""

from __future__ import annotations

import numpy as np
import pytest

from controllers.base import ObservationBatch
from controllers.batch import batch_controller
from tests.controllers.controller_world import World, make_camera


@pytest.mark.parametrize("name", ["leg-direction", "leg-edge", "leg-edge-qp", "model-based"])
def test_a_second_reset_batch_starts_from_scratch(name: str, other_geometry,  # type: ignore[no-untyped-def]
                                                  rng: np.random.Generator) -> None:
    world = World(other_geometry, make_camera("unified", other_geometry))
    Rs, ts = world.poses(12, rng, max_translation=0.02, max_angle=np.deg2rad(4), margin=0.03)
    contexts = [world.context(world.goal(R, t), 0.02) for R, t in zip(Rs[:6], ts[:6],
                                                                        strict=True)]
    reused = batch_controller(name, {})
    reused.reset_batch(contexts)
    reused.reset_batch(contexts[::-1])
    fresh = batch_controller(name, {})
    fresh.reset_batch(contexts[::-1])
    trials = reused.trial_instances
    assert len(trials) == 6 and trials[0] is reused  # the controller is its first trial
    batch = reused.batch_estimate
    for k, inst in enumerate(trials):  # each trial's estimate is its row of this batch's
        assert k == 0 or not (inst.trial_instances or hasattr(inst, "batch_estimate"))
        for name in ("rotation", "directions"):
            if hasattr(batch, name):
                row = getattr(inst.estimate, name)
                assert np.shares_memory(row, getattr(batch, name))
                assert np.array_equal(row, getattr(batch, name)[k], equal_nan=True)
    obs = [world.observation(R, t) for R, t in zip(Rs[6:], ts[6:], strict=True)]
    batch = ObservationBatch(
        trials=np.arange(6), t=np.zeros(6), lengths=np.array([o.lengths for o in obs]),
        normals=np.array([o.normals for o in obs]), lines=None,
        directions=np.array([o.directions for o in obs]),
        edge_visible=np.ones((6, 6, 2), dtype=bool),
        direction_visible=np.ones((6, 6), dtype=bool))
    a, b = reused.step_batch(batch), fresh.step_batch(batch)
    assert np.array_equal(a.velocities, b.velocities) and np.any(a.velocities)
