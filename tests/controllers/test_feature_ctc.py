"""The feature computed-torque laws' reference grid (:mod:`controllers.feature_ctc`): the
grids of a batch's trials built together are each trial's own grid, to the last bit, and
a taught goal of another shape is refused."""

from __future__ import annotations

import numpy as np
import pytest

from controllers import registry
from controllers.exceptions import ContextError
from controllers.feature_ctc import FeatureCTC
from hexapod import HexapodGeometry
from tests.controllers.ctc_world import CtcWorld, ideal_drives, line_reference, perturbed


@pytest.mark.parametrize("name", ["leg-edge-ctc", "leg-direction-ctc"])
def test_grids_built_together_are_each_trials_own(geometry: HexapodGeometry,
                                                  name: str) -> None:
    """build_grids over trials of two model worlds (nominal robots), with references of
    several durations and a taught goal with a feature not finite (anchored at the
    model's own): each grid is the one its trial builds alone, to the last bit."""
    truth = ideal_drives(geometry)
    worlds = (CtcWorld.make(truth), CtcWorld.make(truth, perturbed(truth, 1e-3, 4)))
    laws = []
    for k in range(5):
        world = worlds[k % 2]
        _, _, R1, t1, ref = line_reference(truth, "quintic", (1.0 + 1.5 * k, -0.3, 0.4))
        goal = world.goal(R1, t1)
        if k == 2:
            goal.normals[4, 1] = np.nan
            goal.directions[4] = np.nan
        law = registry.create(name)
        assert isinstance(law, FeatureCTC)
        law.reset(world.context(goal, reference=ref))
        laws.append(law)
    laws[0].build_grids(laws)
    together = [law._grid for law in laws]
    assert len({len(grid[1]) for grid in together if grid is not None}) > 1
    for law, grid in zip(laws, together, strict=True):
        assert grid is not None and grid[0] is law.reference
        law._grid = None
        own = law.reference_grid()
        assert own[0] is grid[0]
        for a, b in zip(own[1:], grid[1:], strict=True):
            assert a.shape == b.shape and a.tobytes() == b.tobytes()


def test_a_taught_goal_of_another_shape_is_refused(geometry: HexapodGeometry) -> None:
    """The taught normals must be (6, 2, 3): the error names the field and the shape."""
    world = CtcWorld.make(ideal_drives(geometry))
    _, _, R1, t1, ref = line_reference(world.truth, "quintic", (1.0, -0.3, 0.4))
    goal = world.goal(R1, t1)
    goal.normals = goal.normals.reshape(12, 3)
    law = registry.create("leg-edge-ctc")
    with pytest.raises(ContextError, match=r"goal\.normals.*\(6, 2, 3\).*\(12, 3\)"):
        law.reset(world.context(goal, reference=ref))
