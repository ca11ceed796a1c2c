"""Controllers used by the benchmark tests through ``module:attr`` specs."""

from __future__ import annotations

import numpy as np

from controllers.base import Command, Controller, ControllerContext, Observation


class ProportionalJoints(Controller):
    """Leg lengths servoed to the goal's nominal lengths (a minimal test controller)."""

    name = "test-joints"
    features = frozenset({"lengths"})

    def __init__(self, gain: float = 2.0) -> None:
        self.gain = gain
        self.goal = np.zeros(6)

    def reset(self, context: ControllerContext) -> None:
        assert context.goal.lengths is not None
        self.goal = np.asarray(context.goal.lengths)

    def step(self, observation: Observation) -> Command:
        err = observation.lengths - self.goal
        return Command(-self.gain * err, error=err, error_norm=float(np.linalg.norm(err)))


class CrashOnSomeTrials(ProportionalJoints):
    """Raises inside ``step`` for trials whose goal lies on the +x side of the base."""

    name = "test-crash"

    def reset(self, context: ControllerContext) -> None:
        super().reset(context)
        assert context.goal.translation is not None
        self.crash = bool(context.goal.translation[0] > 0)

    def step(self, observation: Observation) -> Command:
        if self.crash and observation.t > 0.05:
            raise RuntimeError("deliberate crash for the test")
        return super().step(observation)
