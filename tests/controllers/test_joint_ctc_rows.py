"""The batch of ``computed-torque`` as arrays (:mod:`controllers.joint_ctc_rows`): the
leg-space quintic of many rows is the per-trial one to the last bit, and a batch whose
trials' state is views of its arrays steps as independent per-trial controllers do,
through fixed goals (the quintic started at the first step), integral action, a retarget,
different references (stacked grids) and rows stepped by their trial's own step."""

from __future__ import annotations

import numpy as np
import pytest

from controllers import registry
from controllers.computed_torque import ComputedTorqueController
from controllers.data import GoalBatch
from controllers.joint_ctc_rows import QUINTIC_SIZE, JointRows, quintic_rows
from hexapod import HexapodGeometry
from hexapod.dynamics.robots import DynamicRobots
from tests.controllers.ctc_world import DT, CtcWorld, ideal_drives, line_reference
from tests.controllers.test_ctc_rows import _batch, _step_as_the_trials


def _quintic_oracle(t: float, row: np.ndarray) -> np.ndarray:
    """The per-trial quintic as it was written before the batch (Python floats)."""
    t0, T = float(row[1]), float(row[2])
    a, b = row[3:9].tolist(), row[9:15].tolist()
    if T <= 0.0:
        return np.concatenate([row[15:21], np.zeros(12)])
    x = min(max((t - t0) / T, 0.0), 1.0)
    s = x**3 * (10 - 15 * x + 6 * x**2)
    if 0.0 < x < 1.0:
        sd = 30 * x**2 * (1 - x) ** 2 / T
        sdd = 60 * x * (1 - x) * (1 - 2 * x) / T**2
    else:
        sd = sdd = 0.0
    return np.array([a[i] + s * b[i] for i in range(6)] + [sd * b[i] for i in range(6)]
                    + [sdd * b[i] for i in range(6)])


def test_the_quintic_of_many_rows_is_each_rows_quintic(rng: np.random.Generator) -> None:
    m = 400
    rows = np.zeros((m, QUINTIC_SIZE))
    rows[:, 0] = 1.0
    rows[:, 1] = rng.uniform(0.0, 1.0, m)
    rows[:, 2] = rng.uniform(0.05, 3.0, m)
    rows[::7, 2] = 0.0  # a step to the goal
    rows[:, 3:21] = rng.normal(0.4, 0.05, (m, 18))
    t = rows[:, 1] + rng.uniform(-0.5, 4.0, m)  # before, during and after the motion
    got = quintic_rows(t, rows)
    for j in range(m):
        assert got[j].tobytes() == _quintic_oracle(float(t[j]), rows[j]).tobytes(), j


def _robots(truth: HexapodGeometry, starts: list[tuple[np.ndarray, np.ndarray]]
            ) -> DynamicRobots:
    robots = DynamicRobots([truth] * len(starts), np.array([s[0] for s in starts]),
                           np.array([s[1] for s in starts]))
    robots.drives.mode = "force"
    return robots


@pytest.mark.slow
@pytest.mark.parametrize("tracking", [False, True])
def test_the_batch_steps_as_its_trials_do_through_their_own_steps(
        geometry: HexapodGeometry, tracking: bool) -> None:
    truth = ideal_drives(geometry)
    world = CtcWorld.make(truth)
    n = 4
    contexts, starts = [], []
    for k in range(n):  # a reference or a goal of its own per trial
        R0, t0, R1, t1, ref = line_reference(truth, "quintic", (0.5 + 0.2 * k, -0.3, 0.4))
        contexts.append(world.context(world.goal(R1, t1), reference=ref if tracking else None))
        starts.append((R0, t0 + np.array([0.0, 0.001 * k, 0.0])))
    robots = _robots(truth, starts)
    options = {"integral_gain": 1.0, "saturation": "scale"}
    batch = registry.create("computed-torque", **options)
    batch.reset_batch(contexts)
    singles = [registry.create("computed-torque", **options) for _ in range(n)]
    for s, ctx in zip(singles, contexts, strict=True):
        s.reset(ctx)
    for step in range(10):
        obs = _batch(world, robots, step * DT)
        if step == 5 and not tracking:  # a new goal for trial 2, keeping its state
            goal = world.goal(robots.R[0], robots.t[0])
            batch.retarget_batch(np.array([2]), GoalBatch.of(goal))
            singles[2].retarget(goal)
        # at step 7, row 1 by its trial's own step, the others as one batch
        forces = _step_as_the_trials(batch, singles, obs, step == 7, step)
        assert not robots.advance(np.arange(n), forces, DT / 20, 20).any()
    rows = batch._rows
    assert isinstance(rows, JointRows)
    assert rows.tracking.all() == tracking and not rows.shared  # four grids, stacked
    for j, s in enumerate(singles):
        inst = batch.trial_instances[j]
        assert isinstance(inst, ComputedTorqueController)
        assert inst.compiled_steps == s.compiled_steps
        assert inst.input_row.base is rows.X  # the trial's row is the batch's
        np.testing.assert_array_equal(inst._integral, s._integral)
    # a trial's compiled step is bound only by its own step (row 1 at step 7): never for
    # the rows the batch steps as arrays
    assert [inst._bound is not None for inst in batch.trial_instances] == [
        False, True, False, False]


def test_one_quintic_row_is_the_batch_row_bit_for_bit() -> None:
    """The per-trial quintic (``quintic_row_into``) gives the numbers of the batched one
    at every phase: before the start, moving, at rest at the end, and a zero duration."""
    from controllers.joint_ctc_rows import quintic_row_into, quintic_rows

    rng = np.random.default_rng(3)
    rows = np.zeros((4, 21))
    rows[:, 0] = 1.0
    rows[:, 1] = 0.2
    rows[:, 2] = (0.5, 0.5, 0.5, 0.0)
    rows[:, 3:9] = rng.uniform(0.4, 0.6, (4, 6))
    rows[:, 15:21] = rng.uniform(0.4, 0.6, (4, 6))
    rows[:, 9:15] = rows[:, 15:21] - rows[:, 3:9]
    t = np.array([0.1, 0.37, 0.9, 0.3])
    batch = quintic_rows(t, rows)
    assert np.any(batch[1, 6:12] != 0.0)  # one row is moving
    for j in range(4):
        one = np.full(18, np.nan)
        quintic_row_into(float(t[j]), rows[j], one)
        assert one.tobytes() == batch[j].tobytes(), j
