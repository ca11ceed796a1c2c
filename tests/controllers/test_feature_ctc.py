"""The feature computed-torque laws' reference grid (:mod:`controllers.feature_ctc`): the
grid's rows sanitised at once are each row's own sanitising, and the grids of a batch's
trials built together each trial's own grid, to the last bit."""

from __future__ import annotations

import numpy as np
import pytest

from controllers import registry
from controllers.feature_ctc import FeatureCTC, _sanitised, _sanitised_rows
from hexapod import HexapodGeometry
from tests.controllers.ctc_world import CtcWorld, ideal_drives, line_reference, perturbed


@pytest.mark.parametrize("m", [36, 18])
def test_the_grid_sanitised_at_once_is_each_row_sanitised(rng: np.random.Generator,
                                                          m: int) -> None:
    rows = rng.normal(size=(60, 3, m))
    rows[3, 2, 4] = np.nan  # a feature's acceleration unknown: the feature's rows go
    rows[7, 0, :3] = np.inf
    rows[9, 1, 5] = -0.0
    clean, known = _sanitised_rows(rows)
    assert len(clean) == len(known) == 60
    for k, r in enumerate(rows):
        one, kept = _sanitised(r)
        assert clean[k].tobytes() == one.tobytes()
        if kept is None:
            assert known[k].all()
        else:
            assert np.array_equal(known[k], kept)
    assert [k for k, x in enumerate(known) if not x.all()] == [3, 7]
    assert not known[3][3:6].any() and known[3][:3].all()
    assert np.isfinite(np.stack(clean)).all()


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
