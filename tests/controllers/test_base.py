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


def test_reset_and_retarget_are_final_where_the_step_is_batched() -> None:
    ctx = _contexts(1)[0]
    with pytest.raises(TypeError, match=r"reset\(\) is the base's per-trial adapter"):
        class OwnReset(Controller):
            def reset(self, context: ControllerContext) -> None: ...

            def step_trial(self, observation: Observation) -> Command:
                return Command(np.zeros(6))
    with pytest.raises(TypeError, match=r"retarget\(\) is the base's per-trial adapter"):
        class OwnRetarget(JointSpaceController):
            def retarget(self, goal: Goal) -> None: ...

    class ResetOnly(Controller):  # no step yet: which shape it takes is its subclass's
        def reset(self, context: ControllerContext) -> None:
            self.q_star = np.asarray(context.goal.lengths)

    with pytest.raises(TypeError, match="final"):  # an inherited reset as well
        class Batched(ResetOnly):
            def step_trial(self, observation: Observation) -> Command:
                return Command(np.zeros(6))

    class PerTrial(ResetOnly):  # the per-trial shape: the inherited reset is the trial's
        def step(self, observation: Observation) -> Command:
            return Command(self.q_star - np.asarray(observation.lengths))

    assert PerTrial.reset_trial is vars(ResetOnly)["reset"]
    law = PerTrial()
    law.reset(ctx)
    obs = _observations(1, np.random.default_rng(1)).item(0)
    np.testing.assert_array_equal(law.step(obs).velocities,
                                  np.asarray(ctx.goal.lengths) - obs.lengths)


def test_the_doc_batch_example_refuses_before_reset_and_follows_a_moving_goal() -> None:
    cls = _doc_classes()["MyBatchLaw"]
    law = cls(gain=2.0)
    obs = _observations(3, np.random.default_rng(5))  # trials 2, 1, 0
    assert all(r is not None and "reset" in r for r in law.step_batch(obs).reasons)
    contexts = _contexts(3)
    law.reset_batch(contexts)
    goal = np.full(6, 0.55)
    law.retarget_batch(np.array([2]), GoalBatch(lengths=goal[None]))
    got = law.step_batch(obs)
    assert got.reasons == [None, None, None]
    np.testing.assert_array_equal(got.velocities[0], -2.0 * (obs.lengths[0] - goal))
    np.testing.assert_array_equal(got.velocities[2], -2.0 * (
        obs.lengths[2] - np.asarray(contexts[0].goal.lengths)))
    with pytest.raises(ValueError, match="outside the batch's 3 trials"):
        law.step_batch(ObservationBatch(
            trials=np.array([3]), t=np.zeros(1), lengths=obs.lengths[:1], normals=None,
            lines=None, directions=None, edge_visible=np.ones((1, 6, 2), bool),
            direction_visible=np.ones((1, 6), bool)))


def test_a_batch_law_without_a_retarget_says_what_it_lacks() -> None:
    class OwnBatch(Controller):
        name = "own-batch"

        def reset_batch(self, contexts: Any) -> None:
            self.q_star = np.array([c.goal.lengths for c in contexts], dtype=float)
            self.trial_instances = [self] * len(contexts)

        def step_batch(self, observations: ObservationBatch) -> CommandBatch:
            out = CommandBatch.zeros(len(observations))
            out.velocities[:] = self.q_star[observations.trials] - observations.lengths
            return out

    law = OwnBatch()
    law.reset_batch(_contexts(2))
    with pytest.raises(NotImplementedError, match=r"OwnBatch: .*define retarget_batch"):
        law.retarget_batch(np.array([1]), GoalBatch(lengths=np.full((1, 6), 0.5)))


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


class FailsOnTrial(Controller):
    """A per-trial plugin whose trial ``bad`` (by its goal's offset) fails: in ``reset``
    (``where="reset"``), by raising in ``step``, or by returning three values."""

    name = "fails-on-trial"

    def __init__(self, where: str = "step") -> None:
        self.where = where

    def reset(self, context: ControllerContext) -> None:
        self.goal = np.asarray(context.goal.lengths)
        self.bad = bool(self.goal[0] > self.goal[1])
        if self.bad and self.where == "reset":
            raise ValueError("deliberate reset failure")

    def step(self, observation: Observation) -> Command:
        if self.bad and self.where == "step":
            raise RuntimeError("deliberate step failure")
        v = self.goal - observation.lengths
        return Command(v[:3] if self.bad and self.where == "shape" else v)


def _one_bad(n: int, bad: int) -> list[ControllerContext]:
    contexts = _contexts(n)
    q = np.array(contexts[bad].goal.lengths, dtype=float)
    q[0] += 1e-4
    contexts[bad] = ControllerContext(base_points=contexts[bad].base_points,
                                      geometry=contexts[bad].geometry, camera=None, dt=0.02,
                                      goal=Goal(lengths=q))
    return contexts


@pytest.mark.parametrize("where", ["step", "shape", "reset"])
def test_a_failing_trial_is_isolated_in_its_row(where: str) -> None:
    from controllers.exceptions import CommandError

    ctrl = FailsOnTrial(where)
    ctrl.reset_batch(_one_bad(4, bad=2))  # a reset that raises is that trial's failure
    obs = _observations(4, np.random.default_rng(5))  # trials 3, 2, 1, 0: trial 2 is row 1
    out = ctrl.step_batch(obs)
    assert list(ctrl.crashes) == [1]
    exc = ctrl.crashes[1]
    if where == "step":
        assert isinstance(exc, RuntimeError) and str(exc) == "deliberate step failure"
    elif where == "reset":
        assert isinstance(exc, ValueError) and str(exc) == "deliberate reset failure"
    else:
        assert isinstance(exc, CommandError)
        assert str(exc) == ("controller 'fails-on-trial' returned a command of shape (3,); a "
                            "command holds one value per leg, shape (6,)")
    assert out.reasons[1] == f"{type(exc).__name__}: {exc}"
    np.testing.assert_array_equal(out.velocities[1], np.zeros(6))
    for row in (0, 2, 3):  # the other rows are stepped as usual
        trial = int(obs.trials[row])
        assert out.reasons[row] is None
        np.testing.assert_array_equal(out.velocities[row], np.asarray(
            _one_bad(4, 2)[trial].goal.lengths) - obs.lengths[row])
    ok = ctrl.step_batch(obs.rows(np.array([0, 2])))  # the next step starts afresh
    assert ctrl.crashes == {} and ok.reasons == [None, None]


@pytest.mark.parametrize("where", ["step", "shape", "reset"])
def test_one_trial_stepped_alone_raises_its_failure(where: str) -> None:
    from controllers.exceptions import CommandError

    ctrl = FailsOnTrial(where)
    ctx = _one_bad(3, bad=2)[2]
    if where == "reset":
        with pytest.raises(ValueError, match="deliberate reset failure"):
            ctrl.reset(ctx)
        return
    ctrl.reset(ctx)
    obs = _observations(1, np.random.default_rng(2)).item(0)
    if where == "step":
        with pytest.raises(RuntimeError, match="deliberate step failure"):
            ctrl.step(obs)
    else:  # the per-trial adapter hands the command back as it is; a batch checks it
        assert np.shape(ctrl.step(obs).values) == (3,)
        from controllers.tracking import TrackingController

        wrapped = TrackingController(FailsOnTrial(where))  # an own step_batch: checked
        wrapped.reset(ctx)
        with pytest.raises(CommandError, match=r"shape \(3,\)"):
            wrapped.step(obs)


def test_an_array_batch_whose_reset_fails_fails_as_a_whole() -> None:
    from controllers.exceptions import ContextError
    from controllers.leg_edge import LegEdgeController

    law = LegEdgeController()
    with pytest.raises(ContextError):
        law.reset_batch(_contexts(2))  # no camera: the law's arrays cannot be built


def test_a_foreign_object_is_stepped_one_object_per_trial() -> None:
    from controllers.batch import ForeignController

    class Plain:
        """Not a Controller: reset and step only."""

        def reset(self, context: ControllerContext) -> None:
            self.inner = FailsOnTrial("step")
            self.inner.reset(context)

        def step(self, observation: Observation) -> Command:
            return self.inner.step(observation)

    made: list[Plain] = []
    ctrl = ForeignController(lambda: made.append(Plain()) or made[-1], name="plain")
    ctrl.reset_batch(_one_bad(3, bad=0))
    assert len(made) == 3 and len({id(i.inner) for i in made}) == 3
    obs = _observations(3, np.random.default_rng(4))  # trials 2, 1, 0: trial 0 is row 2
    out = ctrl.step_batch(obs)
    assert list(ctrl.crashes) == [2] and out.reasons[:2] == [None, None]
    one = ForeignController.adopt(made[1])  # already reset: a batch of one
    from dataclasses import replace

    row = replace(obs.rows(np.array([1])), trials=np.array([0]))
    assert one.step_batch(row).reasons == [None]


def test_a_per_trial_plugin_without_step_is_told_so() -> None:
    """A plugin that defines reset but no step (or misspells it) was told it 'defines
    neither reset_batch nor reset_trial', although it defines reset."""

    class NoStep(Controller):
        name = "no-step"

        def reset(self, context: ControllerContext) -> None:  # type: ignore[misc]
            self.goal = context.goal

        def stepp(self, observation: Observation) -> Command:
            return Command.refuse("never called")

    with pytest.raises(NotImplementedError,
                       match=r"NoStep: defines reset\(context\) but no step\(observation\)"):
        NoStep().reset_trial(_contexts(1)[0])  # what the batch's reset calls per trial


def test_a_per_trial_plugin_without_reset_is_told_so() -> None:
    """The opposite slip: a step and no reset was told it 'defines neither reset_batch nor
    reset_trial', names the author never wrote."""

    class NoReset(Controller):
        name = "no-reset"

        def step(self, observation: Observation) -> Command:  # type: ignore[misc]
            return Command.refuse("never called")

    with pytest.raises(NotImplementedError,
                       match=r"NoReset: defines step\(observation\) but no reset\(context\)"):
        NoReset().reset_trial(_contexts(1)[0])
