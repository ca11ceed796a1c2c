"""GoalBatch mirrors Goal field by field (both take their fields from one base): a field
added to one and not the other (or to GOAL_FIELDS) would silently drop out of the batched
retarget; this keeps them in step. The batch of one of the per-trial adapter
(``ObservationBatch.of``, ``CommandBatch.of_row``) holds what the general path would."""

from __future__ import annotations

from dataclasses import fields

import numpy as np

from controllers.data import (
    GOAL_FIELDS,
    Command,
    CommandBatch,
    Goal,
    GoalBatch,
    Observation,
    ObservationBatch,
    observation_problem,
)
from controllers.law_tools import check_observation
from hexapod.actuation import Actuation


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


def _observation(rng: np.random.Generator) -> Observation:
    normals = rng.normal(size=(6, 2, 3))
    return Observation(t=0.25, lengths=rng.uniform(0.3, 0.5, 6), normals=normals,
                       directions=rng.normal(size=(6, 3)), q_dot=rng.normal(size=6),
                       image_t=0.2)


def test_a_batch_of_one_views_the_observation_or_converts_it() -> None:
    obs = _observation(np.random.default_rng(1))
    batch = ObservationBatch.of(obs)
    assert batch is not None and len(batch) == 1 and batch.item(0) is obs
    for name in ("lengths", "normals", "directions", "q_dot", "edge_visible",
                 "direction_visible"):
        assert np.shares_memory(getattr(batch, name), getattr(obs, name)), name
        np.testing.assert_array_equal(getattr(batch, name)[0], getattr(obs, name))
    assert batch.lines is None and batch.t.tolist() == [0.25] and batch.image_t.tolist() == [0.2]
    # fields given as lists (or ints) are converted, with the same values
    listed = Observation(t=1, lengths=obs.lengths.tolist(), normals=obs.normals.tolist(),
                         edge_visible=np.ones((6, 2), dtype=int).tolist())
    converted = ObservationBatch.of(listed)
    assert converted is not None
    np.testing.assert_array_equal(converted.lengths[0], obs.lengths)
    np.testing.assert_array_equal(converted.normals[0], obs.normals)
    assert converted.edge_visible.dtype == np.bool_ and converted.edge_visible.all()
    # a field of the wrong shape, or not numbers, makes no batch
    assert ObservationBatch.of(Observation(t=0.0, lengths=np.ones(5))) is None
    assert ObservationBatch.of(Observation(t=0.0, lengths=np.ones(6),
                                           normals=np.ones((6, 3)))) is None
    assert ObservationBatch.of(Observation(t=0.0, lengths=["a"] * 6)) is None  # type: ignore[arg-type]


def test_a_command_batch_of_one_row_holds_what_zeros_and_put_hold() -> None:
    commands = [
        (Command(np.arange(6.0), error_norm=0.5, rank=6), Actuation.VELOCITY),
        (Command.refuse("no edge seen", np.ones(3)), Actuation.VELOCITY),
        (Command.of_forces(np.arange(6.0) - 2, error_norm=1.5), Actuation.FORCE),
        (Command.refuse("stroke", actuation=Actuation.FORCE), Actuation.FORCE),
    ]
    for cmd, actuation in commands:
        one = CommandBatch.of_row(cmd, actuation)
        put = CommandBatch.zeros(1, actuation)
        put.put(0, cmd)
        np.testing.assert_array_equal(one.velocities, put.velocities)
        np.testing.assert_array_equal(one.error_norm, put.error_norm)
        assert one.reasons == put.reasons and one.actuation is put.actuation
        assert (one.forces is None) == (put.forces is None)
        if one.forces is not None:
            np.testing.assert_array_equal(one.forces, put.forces)
        assert one.command(0) is cmd and one.commands == [cmd]


def test_the_fast_observation_check_says_what_the_full_one_says() -> None:
    """``check_observation`` (fast paths: every feature visible and finite, or the visible
    ones finite) returns ``observation_problem``'s verdict and reason on observations
    with hidden features holding NaN, visible ones not finite, wrong shapes and dtypes,
    masks that are not boolean arrays, and non-finite lengths or times."""
    rng = np.random.default_rng(5)
    features = frozenset({"lengths", "normals", "lines", "directions"})
    verdicts = set()
    for k in range(600):
        normals = rng.normal(size=(6, 2, 3))
        lines = rng.normal(size=(6, 2, 3))
        directions = rng.normal(size=(6, 3))
        edges = rng.random((6, 2)) < (0.6 if k % 3 else 1.0)
        legs = rng.random(6) < (0.6 if k % 3 else 1.0)
        for arr, mask in ((normals, edges), (lines, edges), (directions, legs)):
            arr[~mask] = np.nan  # hidden: NaN, as the sensors give
        obs = Observation(float(k), 0.4 + 0.1 * rng.random(6), normals=normals, lines=lines,
                          directions=directions, edge_visible=edges, direction_visible=legs)
        case = k % 10
        if case == 1:  # a visible feature not finite
            i, j = np.argwhere(edges)[0] if edges.any() else (0, 0)
            obs.edge_visible[i, j] = True
            obs.normals[i, j, 1] = np.inf
        elif case == 2:
            obs.lengths[3] = np.nan
        elif case == 3:
            obs.t = float("nan")
        elif case == 4:
            obs.directions = directions[:5]
        elif case == 5:
            obs.edge_visible = edges.astype(np.int64)  # a mask of ints
        elif case == 6:
            obs.lines = lines.astype(np.float32)
        elif case == 7:
            obs.direction_visible = legs.tolist()  # a list
        want = observation_problem(obs, features)
        assert check_observation(obs, features) == want, (k, want)
        verdicts.add(want is None)
    assert verdicts == {True, False}
