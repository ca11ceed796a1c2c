"""The oracle of a batch: one controller per trial, each stepped alone (a batch of one,
through the per-trial ``reset``, ``retarget`` and ``step``)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from controllers.base import Command, CommandBatch, ControllerContext, ObservationBatch
from hexapod.actuation import Actuation


def stacked(commands: list[Command]) -> CommandBatch:
    """Per-trial :class:`Command` objects (all of one actuation) stacked into a batch."""
    kind = commands[0].actuation if commands else Actuation.VELOCITY
    out = CommandBatch.zeros(len(commands), kind)
    for k, c in enumerate(commands):
        out.put(k, c)
    return out


class OneByOne:
    """One controller per context, each reset with its own.

    Args:
        make: Builds a fresh controller.
        contexts: One per trial.
    """

    def __init__(self, make: Callable[[], Any], contexts: Sequence[ControllerContext]
                 ) -> None:
        self.controllers = [make() for _ in contexts]
        for ctrl, ctx in zip(self.controllers, contexts, strict=True):
            ctrl.reset(ctx)

    def step_batch(self, observations: ObservationBatch) -> CommandBatch:
        """Each row stepped by its trial's controller alone."""
        return stacked(
            [self.controllers[int(t)].step(observations.item(k))
             for k, t in enumerate(observations.trials)])
