"""Stepping many trials at once (``docs/plugins.md``, "Batched controllers").

A controller that implements ``reset_batch(contexts)`` and
``step_batch(observations)`` steps every trial of a study in one call (the built-in
controllers do: their compiled cores are looped over the trials in C). Any other
controller is wrapped by :class:`PerTrialLoop`: one instance per trial, ``step`` in a
loop. :func:`batch_controller` chooses.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from controllers.base import (
    Actuation,
    Command,
    CommandBatch,
    Controller,
    ControllerContext,
    ObservationBatch,
    registry,
)

log = logging.getLogger(__name__)


def actuation_of(controller: Any) -> Actuation:
    """What a controller object (or a batch wrapper of one) declares it commands: its
    ``actuation`` attribute, leg velocities when it has none (plugins written before
    typed actuation)."""
    return Actuation(getattr(controller, "actuation", Actuation.VELOCITY))


def supports_batch(controller: Any) -> bool:
    """Whether a controller object steps many trials itself."""
    return callable(getattr(controller, "reset_batch", None)) and callable(
        getattr(controller, "step_batch", None))


def step_rows_per_trial(instances: Sequence[Any], observations: ObservationBatch,
                        trials: np.ndarray, rows: np.ndarray, out: CommandBatch) -> None:
    """Step ``rows`` of a batch with their trials' own instances (the rows a batched core
    cannot finish), writing each command into ``out``.

    Args:
        instances: The per-trial controllers, by trial.
        observations: The batch.
        trials: (n,) the trial of each row.
        rows: The rows to step.
        out: The batch's commands.
    """
    for k in rows:
        out.put(int(k), instances[int(trials[k])].step(observations.item(int(k))))


class PerTrialLoop:
    """The batch interface over one controller per trial (``step`` in a loop).

    Args:
        factory: Builds a fresh controller (with its options).
    """

    def __init__(self, factory: Callable[[], Any],
                 actuation: Actuation = Actuation.VELOCITY) -> None:
        self.factory = factory
        #: What the wrapped controllers command.
        self.actuation = actuation
        self.controllers: list[Any] = []
        #: The last :class:`Command` of each row of the last step (diagnostics).
        self.last_commands: list[Command] = []

    def reset_batch(self, contexts: Sequence[ControllerContext]) -> None:
        """One controller per context, reset with it."""
        self.controllers = []
        for ctx in contexts:
            ctrl = self.factory()
            ctrl.reset(ctx)
            self.controllers.append(ctrl)

    def step_batch(self, observations: ObservationBatch) -> CommandBatch:
        """``step`` of each row's controller."""
        cmds = [self.controllers[int(t)].step(observations.item(k))
                for k, t in enumerate(observations.trials)]
        self.last_commands = cmds
        return CommandBatch.from_commands(cmds)


def batch_controller(name: str, options: dict[str, Any], batched: bool = True) -> Any:
    """The batch-interface object of a registered controller.

    Args:
        name: Registry name or ``module:attr``.
        options: The controller's options.
        batched: Use the controller's own ``step_batch`` when it has one (False: always
            the per-trial loop, the reference the batched path is tested against).

    Returns:
        An object with ``reset_batch`` and ``step_batch``.
    """
    ctrl = registry.create(name, **options)
    if batched and supports_batch(ctrl):
        return ctrl
    first = [ctrl]

    def factory() -> Controller:
        return first.pop() if first else registry.create(name, **options)

    return PerTrialLoop(factory, actuation_of(ctrl))
