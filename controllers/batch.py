"""A registered controller as the study engine steps it (``docs/plugins.md``).

Every :class:`~controllers.base.Controller` steps a batch of trials (``step_batch``; a
plugin class that defines only the per-trial ``step`` is stepped one instance per trial
by the base, which isolates a trial's failure to its row). A factory may also return an
object that is no ``Controller`` but has ``reset`` and ``step``:
:class:`ForeignController` adapts it the same way, one object per trial.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from controllers.base import Controller
from controllers.data import Command, ControllerContext, Goal, Observation
from controllers.registry import registry
from hexapod.actuation import Actuation


def actuation_of(controller: Any) -> Actuation:
    """What a controller object declares it commands: its ``actuation`` attribute, leg
    velocities when it has none (plugins written before typed actuation)."""
    return Actuation(getattr(controller, "actuation", Actuation.VELOCITY))


class ForeignController(Controller):
    """Objects with ``reset`` and ``step`` (maybe ``retarget``) that are not a
    :class:`Controller`, as a batch: one object per trial, built by ``make``, each row
    stepped by its object through the base's per-row loop (a trial whose object raises
    or returns a malformed command fails alone).

    Args:
        make: Builds a fresh, un-reset object (with its options).
        name: The name the commands' refusals give (default: the object's ``name``).
    """

    def __init__(self, make: Callable[[], Any], name: str | None = None) -> None:
        self.make = make
        self.inner: Any = make()
        self.name = str(name or getattr(self.inner, "name", type(self.inner).__name__))
        self.features = frozenset(getattr(self.inner, "features", frozenset({"lengths"})))
        self.actuation = actuation_of(self.inner)

    @classmethod
    def adopt(cls, obj: Any) -> ForeignController:
        """A batch of one over ``obj``, already reset (the servo session's controller)."""
        one = cls(lambda: obj)
        one.trial_instances = [one]
        return one

    def reset_trial(self, context: ControllerContext) -> None:
        """The object's ``reset``."""
        self.inner.reset(context)

    def step_trial(self, observation: Observation) -> Command:
        """The object's ``step``."""
        return self.inner.step(observation)  # type: ignore[no-any-return]

    def retarget_trial(self, goal: Goal) -> None:
        """The object's ``retarget`` when it has one, else a reset with the goal."""
        method = getattr(self.inner, "retarget", None)
        if callable(method):
            method(goal)
        else:
            super().retarget_trial(goal)


def batch_controller(name: str, options: dict[str, Any]) -> Controller:
    """The registered controller ``name`` (or ``module:attr``) built with ``options``,
    ready for ``reset_batch`` and ``step_batch``."""
    ctrl = registry.create(name, **options)
    if isinstance(ctrl, Controller):
        return ctrl
    first = [ctrl]

    def make() -> Any:
        return first.pop() if first else registry.create(name, **options)

    return ForeignController(make, name=str(getattr(ctrl, "name", name)))
