"""Trajectory tracking in a batch: ``retarget`` keeps the law's state and sets exactly the
goal that ``reset`` would; ``retarget_batch`` (features written into the compiled core's
inputs, the instances told later) gives the commands of per-trial retargets; and
:class:`controllers.tracking.TrackingController` over a batch gives the commands of one
per trial stepped alone, row for row, with hidden goal edges, hidden measured edges, a
non-finite time and the feed-forward."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import pytest

from controllers import registry
from controllers.base import (
    CommandBatch,
    ControllerContext,
    Goal,
    GoalBatch,
    Observation,
    ObservationBatch,
)
from controllers.control_grid import CHUNK
from controllers.exceptions import ContextError
from controllers.tracking import (
    TrackingController,
    model_goals,
    tracking_plan,
    tracking_plans,
)
from hexapod.trajectory import PoseTrajectory
from tests.controllers.controller_world import World, make_camera
from tests.controllers.one_by_one import OneByOne, stacked

DT = 0.02
GAIN = {"adaptive_gain": [5.0, 1.0, 30.0]}


def _world(kind: str) -> World:
    from hexapod.geometry import deltalab

    g = deltalab()
    return World(g, make_camera(kind, g))


def _observation(world: World, R: np.ndarray, t: np.ndarray, time: float,
                 hidden: np.ndarray | None = None) -> Observation:
    """The world's observation with the edges ``hidden`` (6, 2) NaN and flagged."""
    obs = world.observation(R, t, time)
    obs.direction_visible = np.ones(6, dtype=bool)
    if hidden is not None and hidden.any():
        obs.edge_visible = ~hidden
        obs.normals = np.where(hidden[..., None], np.nan, obs.normals)
        if obs.lines is not None:
            obs.lines = np.where(hidden[..., None], np.nan, obs.lines)
        legs = hidden.any(axis=1)
        obs.direction_visible = ~legs
        obs.directions = np.where(legs[:, None], np.nan, obs.directions)
    return obs


def _goal(world: World, R: np.ndarray, t: np.ndarray, hidden: np.ndarray | None = None
          ) -> Goal:
    """The world's goal with the edges ``hidden`` (6, 2) unseen (NaN, flagged)."""
    goal = world.goal(R, t)
    goal.edge_visible = np.ones((6, 2), dtype=bool)
    if hidden is not None and hidden.any():
        goal.edge_visible = ~hidden
        goal.normals = np.where(hidden[..., None], np.nan, goal.normals)
        if goal.lines is not None:
            goal.lines = np.where(hidden[..., None], np.nan, goal.lines)
        goal.directions = np.where(hidden.any(axis=1)[:, None], np.nan, goal.directions)
    return goal


def _batch(rows: list[Observation], trials: list[int]) -> ObservationBatch:
    def stack(name: str) -> Any:
        values = [getattr(o, name) for o in rows]
        return None if values[0] is None else np.array(values)

    image_t = [o.t if o.image_t is None else o.image_t for o in rows]
    rates = [np.full(6, np.nan) if o.q_dot is None else o.q_dot for o in rows]
    return ObservationBatch(
        trials=np.array(trials), t=np.array([o.t for o in rows]), lengths=stack("lengths"),
        normals=stack("normals"), lines=stack("lines"), directions=stack("directions"),
        edge_visible=stack("edge_visible"), direction_visible=stack("direction_visible"),
        image_t=np.array(image_t, dtype=float),
        q_dot=None if all(o.q_dot is None for o in rows) else np.array(rates))


def _same(a: CommandBatch, b: CommandBatch) -> None:
    assert a.reasons == b.reasons
    np.testing.assert_array_equal(a.velocities, b.velocities)
    np.testing.assert_array_equal(a.error_norm, b.error_norm)


def _hidden(rng: np.random.Generator, p: float) -> np.ndarray:
    """A random (6, 2) mask of hidden edges (each edge with probability ``p``)."""
    return rng.random((6, 2)) < p


# ------------------------------------------------------------------------ retarget
@pytest.mark.parametrize(("law", "kind", "options"), [
    ("leg-edge", "perspective", {}),
    ("leg-edge", "unified", {}),
    ("leg-direction", "perspective", {}),
    ("leg-edge", "perspective", {"interaction": "desired"}),
    ("leg-direction", "perspective", {"interaction": "mean"}),
    ("leg-edge-qp", "perspective", {}),
])
def test_retarget_sets_the_goal_of_reset_and_keeps_the_state(law: str, kind: str,
                                                            options: dict[str, Any]) -> None:
    """After hidden edges (dead-reckoned directions, a commanded twist), ``retarget``
    leaves the estimate as it was and reads the new goal as ``reset`` does: the same
    desired features, visibility, compiled-core input, and the same command on a fully
    visible observation (where the estimate plays no part) to the last bit. ``reset``
    instead forgets the dead-reckoned directions."""
    world = _world("omni" if kind == "unified" else kind)
    R, t = world.home()
    rng = np.random.default_rng(4)
    Rs, ts = world.poses(3, rng, max_translation=0.01, max_angle=np.deg2rad(2.0))
    goal0 = _goal(world, Rs[0], ts[0])
    goal1 = _goal(world, Rs[1], ts[1])
    kept = registry.create(law, **GAIN, **options)
    kept.reset(world.context(goal0, DT))
    hide = np.zeros((6, 2), dtype=bool)
    hide[2] = True
    for k in range(3):
        cmd = kept.step(_observation(world, R, t, k * DT, hide if k else None))
        assert cmd.ok, cmd.reason
        R, t = world.move(R, t, cmd.twist, DT)
    before_twist = kept.estimate.twist.copy()
    before_dirs = kept.estimate.directions.copy()
    assert np.all(np.isfinite(before_dirs[2]))  # leg 2 dead-reckoned, not forgotten
    kept.retarget(goal1)
    np.testing.assert_array_equal(kept.estimate.directions, before_dirs)
    np.testing.assert_array_equal(kept.estimate.twist, before_twist)
    assert np.any(before_twist)
    fresh = registry.create(law, **GAIN, **options)
    fresh.reset(world.context(goal1, DT))
    np.testing.assert_array_equal(kept.desired_features(), fresh.desired_features())
    np.testing.assert_array_equal(kept._goal_visible, fresh._goal_visible)
    np.testing.assert_array_equal(kept._q_star, fresh._q_star)
    assert (kept.kernel is None) == (fresh.kernel is None)
    if kept.kernel is not None:
        np.testing.assert_array_equal(kept.kernel.inputs["desired"],
                                      fresh.kernel.inputs["desired"])
    assert kept.context is not None  # the goal of a batch of one: views of goal1
    np.testing.assert_array_equal(kept.context.goal.normals, goal1.normals)
    obs = _observation(world, R, t, 3 * DT)
    a, b = kept.step(obs), fresh.step(obs)
    assert a.ok and b.ok
    np.testing.assert_array_equal(a.velocities, b.velocities)
    assert a.error_norm == b.error_norm
    fresh.reset(world.context(goal1, DT))
    assert not np.any(np.isfinite(fresh.estimate.directions))  # reset forgets


def test_retarget_to_a_bad_goal_is_refused_and_keeps_the_old_goal() -> None:
    world = _world("perspective")
    R, t = world.home()
    law = registry.create("leg-edge", **GAIN)
    goal = _goal(world, R, t + np.array([0.002, 0.0, 0.0]))
    law.reset(world.context(goal, DT))
    desired = law.desired_features().copy()
    with pytest.raises(ContextError, match=r"goal\.lengths"):
        law.retarget(dataclasses.replace(goal, lengths=np.full(6, np.nan)))
    with pytest.raises(ContextError, match="no visible desired edge"):
        law.retarget(dataclasses.replace(goal, edge_visible=np.zeros((6, 2), dtype=bool)))
    np.testing.assert_array_equal(law.desired_features(), desired)
    assert law.kernel is not None and law.context is not None and law.context.goal is goal
    with pytest.raises(ContextError, match="before reset"):
        registry.create("leg-edge").retarget(goal)


@pytest.mark.parametrize(("law", "kind", "options"), [
    ("leg-edge", "perspective", {}),
    ("leg-edge", "unified", {}),
    ("leg-direction", "perspective", {}),
    ("leg-edge", "perspective", {"interaction": "mean"}),
    ("leg-edge-qp", "perspective", {}),
    ("model-based", "perspective", {}),
    ("joint-space", "perspective", {}),
])
def test_retarget_batch_gives_the_commands_of_per_instance_retargets(
        law: str, kind: str, options: dict[str, Any]) -> None:
    """Five trials, twelve periods, a new goal for a random subset of trials each period
    (some goals with hidden edges: the instance reads them; the others go to the compiled
    core's inputs first), observations with random hidden edges (rows the core cannot
    finish, stepped by instances that must have read their pending goal): the batch's
    commands are those of per-instance ``retarget`` and ``step``, to the last bit."""
    world = _world("omni" if kind == "unified" else kind)
    rng = np.random.default_rng(11)
    n = 5
    Rs, ts = world.poses(n * 14, rng, max_translation=0.01, max_angle=np.deg2rad(2.0))
    contexts = [world.context(_goal(world, Rs[i], ts[i]), DT) for i in range(n)]
    opts = {**GAIN, **options}
    batch = registry.create(law, **opts)
    assert hasattr(batch, "retarget_batch")
    batch.reset_batch(contexts)
    loop = OneByOne(lambda: registry.create(law, **opts), contexts)
    quick = instance = 0
    for k in range(12):
        moved = np.flatnonzero(rng.random(n) < 0.7)
        if len(moved):
            goals = [_goal(world, Rs[n * (k + 1) + i], ts[n * (k + 1) + i],
                           _hidden(rng, 0.1) if rng.random() < 0.3 else None) for i in moved]
            gb = GoalBatch(**{f: np.array([getattr(g, f) for g in goals])
                              for f in ("normals", "lines", "directions", "lengths",
                                        "rotation", "translation", "edge_visible")})
            if hasattr(batch, "_batch_desired"):
                ok = batch._batch_desired(gb)[1]
                quick += int(ok.sum())
                instance += int((~ok).sum())
            batch.retarget_batch(moved, gb)
            for j, i in enumerate(moved):
                loop.controllers[i].retarget(goals[j])
        rows = [_observation(world, Rs[i], ts[i] + 0.001 * k, k * DT,
                             _hidden(rng, 0.15) if rng.random() < 0.4 else None)
                for i in range(n)]
        _same(batch.step_batch(_batch(rows, list(range(n)))),
              loop.step_batch(_batch(rows, list(range(n)))))
    if law.startswith("leg-") and options.get("interaction", "current") == "current":
        assert quick > 10 and instance > 3  # both retarget paths ran


# ------------------------------------------------------------------------ tracking
def _tracking_contexts(world: World, n: int) -> list[ControllerContext]:
    """``n`` trials tracking 5 mm circles (1.1 s) from nearby start poses."""
    rng = np.random.default_rng(5)
    Rs, ts = world.poses(n, rng, max_translation=0.008, max_angle=np.deg2rad(1.5))
    out = []
    for i in range(n):
        ref = PoseTrajectory("circle", "quintic", Rs[i], ts[i], speed=0.03,
                             acceleration=0.2, radius=0.005, plane="xy")
        ctx = world.context(_goal(world, ref.end_rotation, ref.end_translation), DT)
        out.append(dataclasses.replace(ctx, reference=ref))
    return out


@pytest.mark.slow
@pytest.mark.parametrize(("law", "options"), [
    ("leg-edge", {}),
    ("leg-direction", {}),
    ("leg-edge-qp", {}),
    ("model-based", {}),
    ("joint-space", {}),
    ("latency-compensated", {"law": "leg-edge"}),
    ("leg-edge-mpc", {"drive_model": "lag", "horizon": 3, "compiled": False}),
])
def test_tracking_a_batch_gives_the_rows_of_one_tracking_controller_per_trial(
        law: str, options: dict[str, Any]) -> None:
    """Four trials tracking their circles for 70 periods (past the references' end), with
    hidden edges at random, a row whose time is NaN, and a trial missing from some steps:
    the commands of one :class:`TrackingController` over the batch are those of one per
    trial stepped alone, feed-forward included, to the last bit."""
    world = _world("perspective")
    n = 4
    contexts = _tracking_contexts(world, n)
    opts = {**GAIN, **options}
    tracking = TrackingController(registry.create(law, **opts))
    tracking.reset_batch(contexts)
    singles = [TrackingController(registry.create(law, **opts)) for _ in range(n)]
    for ctrl, ctx in zip(singles, contexts, strict=True):
        ctrl.reset(ctx)
    rng = np.random.default_rng(8)
    refused = 0
    for k in range(70):
        trials = [i for i in range(n) if not (i == 1 and k % 9 == 4)]
        rows = []
        for i in trials:
            s = contexts[i].reference.at(np.array([k * DT]))
            obs = _observation(world, s.rotation[0], s.translation[0] + 2e-4 * rng.normal(size=3),
                               k * DT, _hidden(rng, 0.1) if rng.random() < 0.3 else None)
            if k == 30 and i == 2:
                obs.t = float("nan")
            rows.append(obs)
        got = tracking.step_batch(_batch(rows, trials))
        want = stacked([singles[i].step(o) for i, o in zip(trials, rows,
                                                                              strict=True)])
        _same(got, want)
        refused += sum(r is not None and r.startswith("time is nan") for r in got.reasons)
    assert refused == 1


def test_the_feed_forward_is_the_nominal_length_rate() -> None:
    """With the feed-forward, a row's command is the one without it plus
    ``(q*(t_{k+1}) - q*(t_k)) / dt`` of its period (zero after the reference's end)."""
    world = _world("perspective")
    contexts = _tracking_contexts(world, 2)
    with_ff = TrackingController(registry.create("leg-edge", **GAIN))
    without = TrackingController(registry.create("leg-edge", **GAIN), feed_forward=False)
    with_ff.reset_batch(contexts)
    without.reset_batch(contexts)
    from hexapod.kinematics import inverse_kinematics

    for k in (0, 10, 40, 200):
        rows = []
        for ctx in contexts:
            s = ctx.reference.at(np.array([k * DT]))
            rows.append(_observation(world, s.rotation[0], s.translation[0], k * DT))
        a = with_ff.step_batch(_batch(rows, [0, 1]))
        b = without.step_batch(_batch(rows, [0, 1]))
        for i, ctx in enumerate(contexts):
            times = np.array([k, k + 1]) * DT
            s = ctx.reference.at(np.minimum(times, ctx.reference.duration + 10 * DT))
            q = inverse_kinematics(ctx.geometry, s.rotation, s.translation)
            rate = (q[1] - q[0]) / DT
            if k == 200:  # past the end of the grid: nothing to feed forward
                rate = np.zeros(6)
            np.testing.assert_allclose(a.velocities[i] - b.velocities[i], rate, atol=1e-12)
            if k == 10:
                assert np.abs(rate).max() > 1e-3


def test_model_goals_of_some_fields_are_those_of_all_fields() -> None:
    """``fields=`` leaves out the goal fields not asked for and gives the others to the
    last bit as without it (the leg-edge CTC's grid asks for its own field only)."""
    ctx = _tracking_contexts(_world("perspective"), 1)[0]
    sample = ctx.reference.at(np.linspace(0.0, 1.2, 7))
    every = model_goals(ctx, sample.rotation, sample.translation)
    for fields in (("normals",), ("lines",), ("directions",), ("lengths", "edge_visible")):
        some = model_goals(ctx, sample.rotation, sample.translation, fields=fields)
        assert set(some) == {"rotation", "translation", *fields}
        for field in fields:
            assert np.array_equal(some[field], every[field], equal_nan=True), field


def test_the_plans_of_a_batch_are_those_of_each_trial_alone() -> None:
    """:func:`tracking_plans` over more trials than a chunk
    (:data:`~controllers.control_grid.CHUNK`), in two model worlds taken turn about (the
    perspective and the unified camera), gives every trial the goals and feed-forward of
    :func:`tracking_plan` of that trial alone, to the last bit; a trial whose period is
    not positive is refused by name."""
    worlds = [_world("perspective"), _world("unified")]
    n = 2 * CHUNK + 3  # (more than a chunk in each world)
    per_world = [_tracking_contexts(w, n) for w in worlds]
    contexts = [per_world[k % 2][k] for k in range(n)]
    plans = tracking_plans(contexts, "leg-edge")
    assert len(plans) == n
    for ctx, plan in zip(contexts, plans, strict=True):
        alone = tracking_plan(ctx, "leg-edge")
        assert plan.dt == alone.dt
        assert np.array_equal(plan.q_rate, alone.q_rate)
        assert set(plan.goals) == set(alone.goals)
        for key, value in alone.goals.items():
            got = plan.goals[key]
            if value is None:
                assert got is None, key
            else:
                assert got is not None and np.array_equal(got, value, equal_nan=True), key
    assert plans[0].goals["lines"] is not None and plans[1].goals["lines"] is None
    bad = [contexts[0], dataclasses.replace(contexts[1], dt=0.0)]
    with pytest.raises(ContextError, match="dt"):
        tracking_plans(bad, "leg-edge")
