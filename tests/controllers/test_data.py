"""GoalBatch mirrors Goal field by field (both take their fields from one base): a field
added to one and not the other (or to GOAL_FIELDS) would silently drop out of the batched
retarget; this keeps them in step."""

from __future__ import annotations

from dataclasses import fields

import numpy as np

from controllers.data import GOAL_FIELDS, Goal, GoalBatch


def test_goal_batch_has_exactly_the_goal_fields() -> None:
    assert tuple(f.name for f in fields(Goal)) == GOAL_FIELDS
    assert tuple(f.name for f in fields(GoalBatch)) == GOAL_FIELDS


def test_a_goal_survives_the_batch_round_trip() -> None:
    rng = np.random.default_rng(0)
    goal = Goal(normals=rng.normal(size=(6, 2, 3)), directions=rng.normal(size=(6, 3)),
                lengths=rng.uniform(0.3, 0.5, 6), rotation=np.eye(3),
                translation=rng.normal(size=3), edge_visible=np.ones((6, 2), bool))
    batch = GoalBatch.of(goal)
    assert len(batch) == 1
    back = batch.item(0)
    for name in GOAL_FIELDS:
        a, b = getattr(goal, name), getattr(back, name)
        assert (a is None) == (b is None), name
        if a is not None:
            np.testing.assert_array_equal(a, b)
