"""The controller interface: one step over a batch, per-trial adapters.

The examples of ``docs/plugins.md`` run as written: the per-trial plugin (``reset`` and
``step``) and the batch one (``reset_batch`` and ``step_batch``), each stepped both ways
(a batch of many trials, and one trial through ``step``) with the same commands; a class
that defines ``step_batch`` cannot override the final ``step``; a per-trial plugin keeps
its own ``retarget`` (or is reset with the new goal)."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from controllers.base import (
    Command,
    CommandBatch,
    Controller,
    ControllerContext,
    Goal,
    GoalBatch,
    Observation,
    ObservationBatch,
)
from controllers.joint import JointSpaceController
from hexapod.geometry import deltalab

DOC = Path(__file__).resolve().parents[2] / "docs" / "plugins.md"


def _doc_classes() -> dict[str, Any]:
    """The classes defined by the python blocks of docs/plugins.md that define a
    controller (run as written; a name defined again by a later block, as the options
    section's signature-only ``MyLaw``, keeps its first, whole definition)."""
    space: dict[str, Any] = {}
    for block in re.findall(r"```python\n(.*?)```", DOC.read_text(), flags=re.S):
        if "(Controller):" in block:
            own = dict(space)  # the earlier blocks' imports
            exec(compile(block, str(DOC), "exec"), own)
            for name, value in own.items():
                space.setdefault(name, value)
    return space


def _contexts(n: int) -> list[ControllerContext]:
    g = deltalab()
    mid = 0.5 * (g.stroke[0] + g.stroke[1])
    return [ControllerContext(base_points=g.base_points, geometry=g, camera=None, dt=0.02,
                              goal=Goal(lengths=np.full(6, mid + 0.001 * k)))
            for k in range(n)]


def _observations(n: int, rng: np.random.Generator) -> ObservationBatch:
    g = deltalab()
    q = 0.5 * (g.stroke[0] + g.stroke[1]) + 0.005 * rng.normal(size=(n, 6))
    return ObservationBatch(trials=np.arange(n)[::-1].copy(), t=np.zeros(n), lengths=q,
                            normals=None, lines=None, directions=None,
                            edge_visible=np.ones((n, 6, 2), bool),
                            direction_visible=np.ones((n, 6), bool))


def test_the_doc_examples_step_a_batch_and_one_trial_alike() -> None:
    classes = _doc_classes()
    assert {"MyLaw", "MyBatchLaw"} <= set(classes)
    rng = np.random.default_rng(3)
    for name in ("MyLaw", "MyBatchLaw"):
        cls = classes[name]
        batch = cls(gain=2.0)
        batch.reset_batch(_contexts(4))
        obs = _observations(4, rng)
        got = batch.step_batch(obs)
        assert isinstance(got, CommandBatch) and len(got.reasons) == 4
        for k, trial in enumerate(obs.trials.tolist()):
            one = cls(gain=2.0)
            one.reset(_contexts(4)[trial])
            cmd = one.step(obs.item(k))
            assert isinstance(cmd, Command)
            np.testing.assert_array_equal(cmd.velocities, got.velocities[k])
            assert cmd.reason == got.reasons[k]
    # the per-trial example refuses every row with its reason; the batch one moves
    assert classes["MyLaw"](1.0).step(obs.item(0)).reason is not None
    assert "step_batch" not in vars(classes["MyLaw"])


def test_step_is_final_where_step_batch_is_defined() -> None:
    with pytest.raises(TypeError, match="final"):
        class Twice(JointSpaceController):
            def step(self, observation: Observation) -> Command:
                return Command(np.zeros(6))


def test_the_per_trial_adapter_refuses_before_reset_and_malformed_observations() -> None:
    law = JointSpaceController()
    obs = _observations(1, np.random.default_rng(0)).item(0)
    assert law.step(obs).reason == "joint-space: reset(context) was not called"
    law.reset(_contexts(1)[0])
    assert law.step(obs).ok
    bad = Observation(t=0.0, lengths=np.ones(5))
    reason = law.step(bad).reason
    assert reason is not None and "lengths" in reason


class Forgets(Controller):
    """A per-trial plugin without retarget: the base resets it with the new goal."""

    name = "forgets"

    def reset(self, context: ControllerContext) -> None:
        self.resets = getattr(self, "resets", 0) + 1
        self.goal = np.asarray(context.goal.lengths)

    def step(self, observation: Observation) -> Command:
        return Command(self.goal - observation.lengths)


class Remembers(Forgets):
    """The same with its own retarget."""

    def retarget(self, goal: Goal) -> None:
        self.goal = np.asarray(goal.lengths)


def test_a_per_trial_plugin_is_retargeted_by_its_retarget_else_reset() -> None:
    assert Forgets.reset_trial is vars(Forgets)["reset"]
    assert Remembers.retarget_trial is vars(Remembers)["retarget"]
    for cls, resets in ((Remembers, 1), (Forgets, 2)):
        ctrl = cls()
        ctrl.reset_batch(_contexts(3))
        goal = np.full(6, 0.5)
        ctrl.retarget_batch(np.array([2]), GoalBatch(lengths=goal[None]))
        inst = ctrl.trial_instances[2]
        assert inst.resets == resets
        np.testing.assert_array_equal(inst.goal, goal)
        out = ctrl.step_batch(_observations(3, np.random.default_rng(1)))
        np.testing.assert_array_equal(out.velocities[0],  # row 0 is trial 2
                                      goal - _observations(3, np.random.default_rng(1)
                                                           ).lengths[0])
