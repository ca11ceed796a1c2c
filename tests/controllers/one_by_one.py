"""The oracle of a batch: one controller per trial, each stepped alone (a batch of one,
through the per-trial ``reset``, ``retarget`` and ``step``)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from controllers.base import CommandBatch, ControllerContext, ObservationBatch


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
        return CommandBatch.from_commands(
            [self.controllers[int(t)].step(observations.item(k))
             for k, t in enumerate(observations.trials)])
