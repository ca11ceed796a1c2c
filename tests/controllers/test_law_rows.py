"""The image-based laws' one step over a batch (:mod:`controllers.law_rows`): every row
of a batch, whatever its kind (all features seen, a hidden feature, a non-finite
length, a limit QP whose optimum touches a bound), gets the command of its batch of
one (the per-trial step) to the last bit, period after period."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import pytest

from controllers import registry
from controllers.base import Command, CommandBatch, Observation, ObservationBatch
from controllers.law_rows import ACCEPTED, RARE, REJECTED, LawRows
from tests.controllers.controller_world import World, make_camera

LAWS = ["leg-direction", "leg-edge", "leg-direction-qp", "leg-edge-qp"]


@pytest.fixture(params=["perspective", "unified"])
def world(request: pytest.FixtureRequest, other_geometry) -> World:  # type: ignore[no-untyped-def]
    return World(other_geometry, make_camera(request.param, other_geometry))


def _hidden(obs: Observation) -> Observation:
    """The observation with edge (2, 0) and the direction of leg 2 hidden."""
    edges = np.ones((6, 2), dtype=bool)
    edges[2, 0] = False
    legs = np.arange(6) != 2
    return dataclasses.replace(
        obs, edge_visible=edges, direction_visible=legs,
        normals=np.where(edges[..., None], obs.normals, np.nan),
        lines=None if obs.lines is None else np.where(edges[..., None], obs.lines, np.nan),
        directions=np.where(legs[:, None], obs.directions, np.nan))


def _stacked(rows: list[Observation]) -> ObservationBatch:
    """One batch of the observations (trial k: row k)."""
    def field(name: str) -> np.ndarray | None:
        values = [getattr(o, name) for o in rows]
        return None if values[0] is None else np.stack([np.asarray(v) for v in values])

    return ObservationBatch(
        np.arange(len(rows)), np.array([o.t for o in rows]), *(
            field(f) for f in ("lengths", "normals", "lines", "directions", "edge_visible",
                               "direction_visible")))


def _same(out: CommandBatch, j: int, one: Command) -> None:
    """Row ``j`` of ``out`` is ``one`` to the last bit (and so are the diagnostics of the
    command Python made for it, where it made one)."""
    assert out.velocities[j].tobytes() == one.velocities.tobytes()
    assert np.float64(out.error_norm[j]).tobytes() == np.float64(one.error_norm).tobytes()
    assert out.reasons[j] == one.reason
    kept = None if out.commands is None else out.commands[j]
    if kept is not None:
        for name in ("error", "twist", "condition", "rank", "features_used", "notes",
                     "active_constraints"):
            a, b = getattr(kept, name), getattr(one, name)
            assert np.asarray(a).tobytes() == np.asarray(b).tobytes(), name


@pytest.mark.parametrize("name", LAWS)
def test_every_kind_of_row_equals_its_batch_of_one(world: World, name: str,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """Row 0 sees everything, row 1 hides an edge (a leg direction), row 2 has a
    non-finite length (refused with its reason), row 3's stroke window (its context's
    margin) leaves the QP's unconstrained optimum outside a bound (OSQP): each row's
    command, norm and reason are its batch of one's, bit for bit, over 6 periods; the
    C took rows 0 and 3 (the QP laws: row 3 rejected to OSQP), Python rows 1 and 2."""
    rng = np.random.default_rng(3)
    Rs, ts = world.poses(5, rng, max_translation=0.02, max_angle=np.deg2rad(4), margin=0.03)
    ctx = world.context(world.goal(Rs[0], ts[0]), 0.02)
    q_min, q_max = world.geometry.stroke
    narrow = dataclasses.replace(ctx, stroke_margin=0.49 * (q_max - q_min))
    contexts = [ctx, ctx, ctx, narrow]
    batch = registry.create(name, gain=2.0)
    batch.reset_batch(contexts)
    singles = [registry.create(name, gain=2.0) for _ in contexts]
    for one, c in zip(singles, contexts, strict=True):
        one.reset(c)
    codes: list[np.ndarray] = []
    real = LawRows.step

    def recorded(self: LawRows, *args: Any) -> tuple[np.ndarray, Any]:
        code, b = real(self, *args)
        if len(code) > 1:
            codes.append(code.copy())
        return code, b

    monkeypatch.setattr(LawRows, "step", recorded)
    poses = list(zip(Rs[1:], ts[1:], strict=True))
    qp = name.endswith("-qp")
    for step in range(6):
        rows = [world.observation(R, t, 0.02 * step) for R, t in poses]
        rows[1] = _hidden(rows[1])
        lengths = rows[2].lengths.copy()
        lengths[3] = np.nan
        rows[2] = dataclasses.replace(rows[2], lengths=lengths)
        out = batch.step_batch(_stacked(rows))
        assert not batch.crashes
        for j, one in enumerate(singles):
            cmd = one.step(rows[j])
            _same(out, j, cmd)
            if j == 2:
                assert cmd.reason is not None and "lengths: leg 3" in cmd.reason
            else:
                assert cmd.reason is None, (j, cmd.reason)
            if j == 3 and qp:
                assert cmd.active_constraints, "the narrow window's bound is active"
        for j, (R, t) in enumerate(poses):  # each pose moves by its command's twist
            poses[j] = world.move(R, t, singles[j].estimate.twist, 0.02)
    assert len(codes) == 6
    assert all(code[1] == RARE and code[2] == RARE for code in codes)
    assert any(code[0] == ACCEPTED for code in codes)  # (a QP's first moves may touch a bound)
    assert all(code[3] == (REJECTED if qp else ACCEPTED) for code in codes)


def test_trials_of_two_cores_in_one_batch_equal_their_batches_of_one(
        other_geometry, monkeypatch: pytest.MonkeyPatch) -> None:  # type: ignore[no-untyped-def]
    """A perspective and a unified camera in one batch of `leg-edge`: their trials read
    lines and normals through two compiled cores (two sets of rows), each row its batch
    of one's command bit for bit, through the C."""
    worlds = [World(other_geometry, make_camera(kind, other_geometry))
              for kind in ("perspective", "unified", "perspective")]
    Rs, ts = worlds[0].poses(4, np.random.default_rng(4), max_translation=0.02,
                             max_angle=np.deg2rad(4), margin=0.03)
    contexts = [w.context(w.goal(Rs[0], ts[0]), 0.02) for w in worlds]
    batch = registry.create("leg-edge", gain=2.0)
    batch.reset_batch(contexts)
    singles = [registry.create("leg-edge", gain=2.0) for _ in contexts]
    for one, c in zip(singles, contexts, strict=True):
        one.reset(c)
    accepted = [0]
    real = LawRows.step

    def recorded(self: LawRows, *args: Any) -> tuple[np.ndarray, Any]:
        code, b = real(self, *args)
        accepted[0] += int(np.count_nonzero(code == ACCEPTED))
        return code, b

    monkeypatch.setattr(LawRows, "step", recorded)
    for step in range(3):
        rows = [w.observation(R, t, 0.02 * step)
                for w, R, t in zip(worlds, Rs[1:], ts[1:], strict=False)]
        rows = [o if o.lines is not None else dataclasses.replace(o, lines=np.zeros((6, 2, 3)))
                for o in rows]  # (the unified trial reads the normals)
        out = batch.step_batch(_stacked(rows))
        assert not batch.crashes
        for j, one in enumerate(singles):
            _same(out, j, one.step(rows[j]))
            assert out.reasons[j] is None
    assert accepted[0] == 2 * 3 * 3  # every row through the C: in the batch and alone


@pytest.mark.parametrize("name", ["leg-edge", "leg-direction"])
def test_rows_with_a_never_seen_leg_share_one_forward_kinematics(
        world: World, name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """Five trials never see leg 2 (nor does their goal): its direction is the nominal
    model's, the forward kinematics of each row's lengths warm-started at its trial's
    last model pose. The batch solves the five rows in one call per period
    (:class:`~controllers.model_directions.ModelDirections`), and each row's command
    (and notes) is its batch of one's, bit for bit, over 5 periods."""
    from controllers.model_directions import ModelDirections

    def without_leg_2(x: Any) -> Any:
        legs = np.arange(6) != 2
        out = dataclasses.replace(
            x, normals=np.where(legs[:, None, None], x.normals, np.nan),
            lines=None if x.lines is None else np.where(legs[:, None, None], x.lines, np.nan),
            directions=np.where(legs[:, None], x.directions, np.nan),
            edge_visible=np.repeat(legs[:, None], 2, axis=1))
        return dataclasses.replace(out, direction_visible=legs) if isinstance(
            x, Observation) else out

    rng = np.random.default_rng(11)
    n = 5
    Rs, ts = world.poses(n + 1, rng, max_translation=0.02, max_angle=np.deg2rad(4),
                         margin=0.03)
    ctx = world.context(without_leg_2(world.goal(Rs[0], ts[0])), 0.02)
    batch = registry.create(name, gain=2.0)
    batch.reset_batch([ctx] * n)
    singles = [registry.create(name, gain=2.0) for _ in range(n)]
    for one in singles:
        one.reset(ctx)
    solved: list[int] = []
    real = ModelDirections._solve

    def counted(self: ModelDirections) -> Any:
        solved.append(len(self.laws))
        return real(self)

    monkeypatch.setattr(ModelDirections, "_solve", counted)
    poses = list(zip(Rs[1:], ts[1:], strict=True))
    for step in range(5):
        rows = [without_leg_2(world.observation(R, t, 0.02 * step)) for R, t in poses]
        solved.clear()
        out = batch.step_batch(_stacked(rows))
        assert not batch.crashes
        assert solved == [n]  # the five rows' forward kinematics in one call
        for j, one in enumerate(singles):
            cmd = one.step(rows[j])
            _same(out, j, cmd)
            assert cmd.reason is None
            assert any("nominal-model directions" in note for note in cmd.notes), cmd.notes
        for j, (R, t) in enumerate(poses):
            poses[j] = world.move(R, t, singles[j].estimate.twist, 0.02)
