"""The batch of the task computed-torque laws as arrays (:mod:`controllers.task_ctc_rows`):
a batch whose trials' state is views of its arrays steps as independent per-trial laws
do, to the last bit, with integral action and a saturation strategy, tracking their own
references or reaching fixed goals (each started by its trial's own first step), and
with a row stepped by its trial's own step in between."""

from __future__ import annotations

import numpy as np
import pytest

from controllers import registry
from controllers.task_ctc import TaskComputedTorque
from controllers.task_ctc_rows import TaskRows
from hexapod import HexapodGeometry
from hexapod.dynamics.robots import DynamicRobots
from tests.controllers.ctc_world import DT, CtcWorld, ideal_drives, line_reference
from tests.controllers.test_ctc_rows import _batch, _rows_of


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
        forces, norms = np.zeros((n, 6)), np.zeros(n)
        if step == 5:  # row 1 by its trial's own step, the others as one batch
            cmd = batch.step_row(1, obs.item(1))
            forces[1], norms[1] = cmd.forces, cmd.error_norm
            idx = np.array([0, 2])
            part = batch.step_batch(_rows_of(obs, idx))
            assert part.forces is not None
            forces[idx], norms[idx] = part.forces, part.error_norm
        else:
            full = batch.step_batch(obs)
            assert full.forces is not None and all(r is None for r in full.reasons)
            forces, norms = full.forces, full.error_norm
        for j, s in enumerate(singles):
            cmd = s.step(obs.item(j))
            assert cmd.reason is None, cmd.reason
            assert forces[j].tobytes() == np.asarray(cmd.forces).tobytes(), (step, j)
            assert norms[j] == cmd.error_norm
        assert not robots.advance(np.arange(n), forces, DT / 20, 20).any()
    rows = batch._rows
    assert isinstance(rows, TaskRows)
    for j, s in enumerate(singles):
        inst = batch.trial_instances[j]
        assert isinstance(inst, TaskComputedTorque) and inst.compiled is not None
        assert inst.compiled_steps == s.compiled_steps
        assert inst.compiled.row.base is rows.X  # the trial's row is the batch's
        assert inst.integral.tobytes() == s.integral.tobytes()
