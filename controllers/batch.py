"""A registered controller as the study engine steps it (``docs/plugins.md``).

Every :class:`~controllers.base.Controller` steps a batch of trials (``step_batch``; a
plugin class that defines only the per-trial ``step`` is stepped one instance per trial
by the base). A factory may also return an object that is no ``Controller`` but has
``reset`` and ``step``: :class:`ForeignController` adapts it the same way.
"""

from __future__ import annotations

from typing import Any

from controllers.base import (
    Actuation,
    Command,
    Controller,
    ControllerContext,
    Goal,
    Observation,
    registry,
)


def actuation_of(controller: Any) -> Actuation:
    """What a controller object declares it commands: its ``actuation`` attribute, leg
    velocities when it has none (plugins written before typed actuation)."""
    return Actuation(getattr(controller, "actuation", Actuation.VELOCITY))


class ForeignController(Controller):
    """A registered object that is not a :class:`Controller` (only ``reset`` and
    ``step``, maybe ``retarget``): one object per trial, built by the registry.

    Args:
        registered: Its registry name (or ``module:attr``).
        options: Its options.
    """

    def __init__(self, registered: str, options: dict[str, Any]) -> None:
        self.inner: Any = registry.create(registered, **options)
        self.name = str(getattr(self.inner, "name", registered))
        self.features = frozenset(getattr(self.inner, "features", frozenset({"lengths"})))
        self.actuation = actuation_of(self.inner)

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
    return ForeignController(name, options)
