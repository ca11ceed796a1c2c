"""The one step of ``computed-torque`` (:mod:`controllers.joint_ctc_rows`): its C
leg-space quintic is the Python expressions' to the last bit, and a batch whose trials'
state is views of its arrays steps as independent per-trial controllers (batches of one)
do, through fixed goals (the quintic started at the first step), integral action, a
retarget, different references (stacked grids), a row stepped alone, and batches of
eight rows or more (the compiled step in lanes)."""

from __future__ import annotations

import numpy as np
import pytest

from controllers import registry
from controllers.computed_torque import ComputedTorqueController
from controllers.data import GoalBatch
from controllers.joint_ctc_rows import QUINTIC_SIZE, JointRows
from hexapod import HexapodGeometry, deltalab
from hexapod.dynamics.robots import DynamicRobots
from hexapod.workspace import home_pose
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


def _quintics(rows: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The desired legs (m, 18) of a fixed-goal controller whose quintic is each row of
    ``rows`` (m, 21) in turn, at the times ``t`` (m,) [s] (its C)."""
    world = CtcWorld.make(ideal_drives(deltalab()))
    ctrl = registry.create("computed-torque")
    assert isinstance(ctrl, ComputedTorqueController)
    ctrl.reset(world.context(world.goal(*home_pose(world.truth))))
    out = np.empty((len(rows), 18))
    for j, row in enumerate(rows):
        ctrl._quintic[:] = row
        out[j] = np.concatenate(ctrl.desired(float(t[j])))
    return out


def test_the_quintic_is_the_python_expressions_bit_for_bit(rng: np.random.Generator) -> None:
    m = 400
    rows = np.zeros((m, QUINTIC_SIZE))
    rows[:, 0] = 1.0
    rows[:, 1] = rng.uniform(0.0, 1.0, m)
    rows[:, 2] = rng.uniform(0.05, 3.0, m)
    rows[::7, 2] = 0.0  # a step to the goal
    rows[:, 3:21] = rng.normal(0.4, 0.05, (m, 18))
    t = rows[:, 1] + rng.uniform(-0.5, 4.0, m)  # before, during and after the motion
    t[::11] = rows[::11, 1] + rows[::11, 2]  # at the end exactly
    got = _quintics(rows, t)
    moving = 0
    for j in range(m):
        oracle = _quintic_oracle(float(t[j]), rows[j])
        assert got[j].tobytes() == oracle.tobytes(), j
        moving += bool(np.any(oracle[6:12] != 0.0))
    assert moving > 50  # a quarter of the rows mid-motion


def _robots(truth: HexapodGeometry, starts: list[tuple[np.ndarray, np.ndarray]]
            ) -> DynamicRobots:
    robots = DynamicRobots([truth] * len(starts), np.array([s[0] for s in starts]),
                           np.array([s[1] for s in starts]))
    robots.drives.mode = "force"
    return robots


@pytest.mark.slow
@pytest.mark.parametrize("n", [4, 9])
@pytest.mark.parametrize("tracking", [False, True])
def test_the_batch_steps_as_its_trials_do_as_batches_of_one(
        geometry: HexapodGeometry, tracking: bool, n: int) -> None:
    truth = ideal_drives(geometry)
    world = CtcWorld.make(truth)
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
        # at step 7, row 1 alone, the others as one batch
        forces = _step_as_the_trials(batch, singles, obs, step == 7, step)
        assert not robots.advance(np.arange(n), forces, DT / 20, 20).any()
    rows = batch._rows
    assert isinstance(rows, JointRows)
    assert rows.tracking.all() == tracking and not rows.shared  # a grid per trial, stacked
    for j, s in enumerate(singles):
        inst = batch.trial_instances[j]
        assert isinstance(inst, ComputedTorqueController)
        assert inst.compiled_steps == s.compiled_steps == 10
        assert inst._row is not None and inst._row.base is rows.X  # the batch's row
        np.testing.assert_array_equal(inst._integral, s._integral)
