"""The batch of the task computed-torque laws as arrays (:mod:`controllers.task_ctc_rows`):
a batch whose trials' state is views of its arrays steps as independent per-trial laws
do, to the last bit, with integral action and a saturation strategy, tracking their own
references or reaching fixed goals (each started at its first step), and with a row
stepped alone (a batch of one) in between."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from controllers import registry
from controllers.task_ctc import TaskComputedTorque
from controllers.task_ctc_rows import TaskRows
from hexapod import HexapodGeometry
from hexapod.dynamics.robots import DynamicRobots
from tests.controllers.ctc_world import DT, CtcWorld, ideal_drives, line_reference
from tests.controllers.test_ctc_rows import _batch, _step_as_the_trials, line_trials


@pytest.mark.slow
@pytest.mark.parametrize("tracking", [False, True])
@pytest.mark.parametrize("name", ["cartesian-ctc", "vision-ctc", "leg-edge-ctc"])
def test_the_batch_steps_as_its_trials_do(geometry: HexapodGeometry, name: str,
                                          tracking: bool) -> None:
    truth = ideal_drives(geometry)
    world = CtcWorld.make(truth)
    n = 3
    contexts, starts = [], []
    for k in range(n):  # a reference or a goal of its own per trial
        R0, t0, R1, t1, ref = line_reference(truth, "quintic", (0.5 + 0.2 * k, -0.3, 0.4))
        contexts.append(world.context(world.goal(R1, t1), reference=ref if tracking else None))
        starts.append((R0, t0 + np.array([0.0, 0.001 * k, 0.0])))
    robots = DynamicRobots([truth] * n, np.array([s[0] for s in starts]),
                           np.array([s[1] for s in starts]))
    robots.drives.mode = "force"
    options = {"integral_gain": 1.0, "saturation": "scale"}
    batch = registry.create(name, **options)
    batch.reset_batch(contexts)
    singles = [registry.create(name, **options) for _ in range(n)]
    for s, ctx in zip(singles, contexts, strict=True):
        s.reset(ctx)
    for step in range(8):
        obs = _batch(world, robots, step * DT)
        # at step 5, row 1 alone, the others as one batch
        forces = _step_as_the_trials(batch, singles, obs, step == 5, step)
        assert not robots.advance(np.arange(n), forces, DT / 20, 20).any()
    rows = batch._rows
    assert isinstance(rows, TaskRows)
    for j, s in enumerate(singles):
        inst = batch.trial_instances[j]
        assert isinstance(inst, TaskComputedTorque) and inst.compiled is not None
        assert inst.compiled_steps == s.compiled_steps
        assert inst.compiled.row.base is rows.X  # the trial's row is the batch's
        assert inst.integral.tobytes() == s.integral.tobytes()


def test_vision_rows_with_hidden_legs_are_stepped_by_the_batch(
        geometry: HexapodGeometry, monkeypatch: pytest.MonkeyPatch) -> None:
    """Rows with a leg hidden (marked so, or its direction not finite) and at least three
    non-collinear legs seen are computed by the batch (no per-row ``prepare``), with the
    per-trial laws' bits; a row with two legs seen is left to its trial's own step, which
    refuses it with the reason."""
    from controllers.task_ctc_compiled import CompiledTaskStep

    world, robots, batch, singles = _four_trials(geometry, "vision-ctc")
    n = len(singles)
    prepared: list[int] = []
    original = CompiledTaskStep.prepare

    def spy(self: CompiledTaskStep, law: TaskComputedTorque, *args: object) -> object:
        prepared.append(batch.trial_instances.index(law) if law in batch.trial_instances
                        else -1)
        return original(self, law, *args)  # type: ignore[arg-type]

    for step in range(4):
        obs = _batch(world, robots, step * DT)
        assert obs.directions is not None
        obs.direction_visible[0, 2] = False  # row 0: leg 2 marked hidden
        obs.directions[1, 4] = np.nan  # row 1: leg 4 not finite (seen: 5 legs)
        obs.direction_visible[2, [0, 3]] = False  # row 2: four legs seen
        obs.direction_visible[3, 1:5] = False  # row 3: two legs seen (refused)
        prepared.clear()
        monkeypatch.setattr(CompiledTaskStep, "prepare", spy)
        full = batch.step_batch(obs)
        monkeypatch.setattr(CompiledTaskStep, "prepare", original)
        assert sorted(set(prepared)) == [3], prepared  # only the refused row by its own
        assert full.forces is not None
        for j, s in enumerate(singles):
            cmd = s.step(obs.item(j))
            assert full.reasons[j] == cmd.reason, (step, j)
            assert full.forces[j].tobytes() == np.asarray(cmd.forces).tobytes(), (step, j)
            assert full.error_norm[j] == cmd.error_norm
        assert full.reasons[3] is not None and full.reasons[0:3] == [None] * 3
        assert not robots.advance(np.arange(n), full.forces, DT / 20, 20).any()


def test_leg_edge_rows_with_hidden_edges_are_stepped_by_the_batch(
        geometry: HexapodGeometry, monkeypatch: pytest.MonkeyPatch) -> None:
    """Rows with an edge hidden or a normal not finite (their leg's rows left out), or
    with a reference feature the model's camera does not see, are computed by the batch
    (no per-row ``prepare``) with the per-trial laws' bits: forces, error norms of the
    rows used and the integral of those rows, step after step."""
    from controllers.feature_ctc import FeatureCTC
    from controllers.task_ctc_compiled import CompiledTaskStep

    motion = FeatureCTC.motion_and_seen

    def hide(self: FeatureCTC, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        out, seen = motion(self, times)
        seen[1:3, 6:9] = False  # the model's camera misses an edge at steps 1 and 2
        return out, seen

    monkeypatch.setattr(FeatureCTC, "motion_and_seen", hide)

    world, robots, batch, singles = _four_trials(geometry, "leg-edge-ctc")
    n = len(singles)
    prepared: list[object] = []
    original = CompiledTaskStep.prepare

    def spy(self: CompiledTaskStep, *args: object) -> object:
        prepared.append(args[0])
        return original(self, *args)  # type: ignore[arg-type]

    for step in range(4):
        obs = _batch(world, robots, step * DT)
        assert obs.normals is not None and obs.edge_visible is not None
        if step % 2:  # every other step, so that a row's state goes on from the batch's
            obs.edge_visible[0, 2, 1] = False  # row 0: an edge of leg 2 hidden
            obs.normals[1, 4, 0] = np.nan  # row 1: a normal of leg 4 not finite...
            obs.edge_visible[1, 5, :] = False  # ... and leg 5 hidden
            obs.edge_visible[2, 1:3, 0] = False  # row 2: legs 1 and 2 hidden
        prepared.clear()
        monkeypatch.setattr(CompiledTaskStep, "prepare", spy)
        full = batch.step_batch(obs)
        monkeypatch.setattr(CompiledTaskStep, "prepare", original)
        assert prepared == [], step  # no row by its trial's own step
        assert full.forces is not None
        for j, s in enumerate(singles):
            cmd = s.step(obs.item(j))
            assert full.reasons[j] is None and cmd.reason is None, (step, j)
            assert full.forces[j].tobytes() == np.asarray(cmd.forces).tobytes(), (step, j)
            assert full.error_norm[j] == cmd.error_norm, (step, j)
            inst = batch.trial_instances[j]
            assert isinstance(inst, TaskComputedTorque)
            assert inst.integral.tobytes() == s.integral.tobytes(), (step, j)
        assert not robots.advance(np.arange(n), full.forces, DT / 20, 20).any()


def _four_trials(geometry: HexapodGeometry, name: str
                 ) -> tuple[CtcWorld, DynamicRobots, Any, list[Any]]:
    """A batch of four trials of ``name`` (integral action) tracking one reference from
    starts 1 mm apart, their per-trial laws, the world and its robots (force drives)."""
    truth = ideal_drives(geometry)
    world = CtcWorld.make(truth)
    n = 4
    R0, t0, R1, t1, ref = line_reference(truth, "quintic", (0.5, -0.3, 0.4))
    contexts = [world.context(world.goal(R1, t1), reference=ref) for _ in range(n)]
    starts = [(R0, t0 + np.array([0.0, 0.001 * k, 0.0])) for k in range(n)]
    robots = DynamicRobots([truth] * n, np.array([s[0] for s in starts]),
                           np.array([s[1] for s in starts]))
    robots.drives.mode = "force"
    batch = registry.create(name, integral_gain=1.0)
    batch.reset_batch(contexts)
    singles = [registry.create(name, integral_gain=1.0) for _ in range(n)]
    for s, ctx in zip(singles, contexts, strict=True):
        s.reset(ctx)
    return world, robots, batch, singles


@pytest.mark.parametrize("saturation", ["clip", "scale"])
@pytest.mark.parametrize("name", ["computed-torque", "cartesian-ctc", "leg-edge-ctc"])
def test_rows_over_a_limit_are_saturated_as_in_batches_of_one(
        geometry: HexapodGeometry, name: str, saturation: str) -> None:
    """Drives too weak for the robot's weight: every row of every step is over a limit,
    with nothing else rare in the batch; the batch's rows take the saturation strategy
    as its batches of one do (to the last bit), within the limits."""
    import dataclasses

    weak = ideal_drives(geometry)
    limit = np.full(6, 5.0)  # [N], well below the static load of each leg
    weak = dataclasses.replace(weak, drives=dataclasses.replace(weak.drives,
                                                                force_limit=limit))
    world = CtcWorld.make(weak)
    ctx, robots = line_trials(world)
    n = len(robots.R)
    batch = registry.create(name, saturation=saturation, integral_gain=1.0)
    batch.reset_batch([ctx] * n)
    singles = [registry.create(name, saturation=saturation, integral_gain=1.0)
               for _ in range(n)]
    for s in singles:
        s.reset(ctx)
    for step in range(4):
        obs = _batch(world, robots, step * DT)
        forces = _step_as_the_trials(batch, singles, obs, False, step)
        assert np.all(np.abs(forces) <= limit + 1e-12)
        assert np.any(np.isclose(np.abs(forces), limit))  # at the limit: saturated
        robots.advance(np.arange(n), forces, DT / 20, 20)
