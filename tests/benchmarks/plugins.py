"""Controllers used by the benchmark tests through ``module:attr`` specs."""

from __future__ import annotations

from typing import Any

import numpy as np

from controllers.base import (
    Command,
    CommandBatch,
    Controller,
    ControllerContext,
    Observation,
    ObservationBatch,
)
from controllers.options import OptionSpec
from controllers.qp import LegEdgeQPController
from controllers.solvers.limit_qp import LimitQPSolver


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


class CrashAtStep(ProportionalJoints):
    """Raises inside ``step`` at period ``crash_step`` of every trial (a broken plugin)."""

    name = "test-crash-at-step"

    def __init__(self, gain: float = 2.0, crash_step: int = 20) -> None:
        super().__init__(gain)
        self.crash_step = crash_step
        self.calls = 0

    def step(self, observation: Observation) -> Command:
        self.calls += 1
        if self.calls > self.crash_step:
            raise RuntimeError(f"deliberate crash at call {self.calls}")
        return super().step(observation)


class WrongShape(ProportionalJoints):
    """Returns three values instead of six (a plugin author's slip)."""

    name = "test-wrong-shape"

    def step(self, observation: Observation) -> Command:
        cmd = super().step(observation)
        return Command(cmd.velocities[:3], error=cmd.error, error_norm=cmd.error_norm)


class NaNAtStep(ProportionalJoints):
    """Returns a command with a NaN from period 3 (a numerical slip in a plugin)."""

    name = "test-nan-at-step"

    def step(self, observation: Observation) -> Command:
        cmd = super().step(observation)
        if observation.t > 0.05:
            cmd.velocities[2] = np.nan
        return cmd


class LengthsOnly(ProportionalJoints):
    """Declares the encoders only and says when it is given more (the two engines must
    give it the same fields: the per-trial engine gave it every camera field)."""

    name = "test-lengths-only"

    def step(self, observation: Observation) -> Command:
        given = [f for f in ("normals", "lines", "directions")
                 if getattr(observation, f) is not None]
        if given:
            raise RuntimeError(f"given undeclared fields {given}")
        return super().step(observation)


class RefusesMoving(ProportionalJoints):
    """Refuses every period while it gives a command (a plugin that fills both)."""

    name = "test-refuses-moving"

    def step(self, observation: Observation) -> Command:
        cmd = super().step(observation)
        return Command(5.0 * cmd.velocities, reason="I refuse", error=cmd.error,
                       error_norm=cmd.error_norm)


class RefusesStill(ProportionalJoints):
    """Refuses every period with a zero command (:class:`RefusesMoving`'s baseline)."""

    name = "test-refuses-still"

    def step(self, observation: Observation) -> Command:
        cmd = super().step(observation)
        return Command(np.zeros(6), reason="I refuse", error=cmd.error,
                       error_norm=cmd.error_norm)


#: Calls of :class:`CrashingBatch`'s ``step_batch`` in this process (not rerun: counted).
BATCH_CALLS: list[int] = []


class CrashingBatch(ProportionalJoints):
    """Steps its trials as one batch and raises at its fifth batch step."""

    name = "test-crashing-batch"

    def reset_batch(self, contexts: list[ControllerContext]) -> None:
        self.goals = np.array([np.asarray(c.goal.lengths) for c in contexts])
        self.batch_steps = 0

    def step_batch(self, observations: ObservationBatch) -> CommandBatch:
        BATCH_CALLS.append(len(observations.trials))
        self.batch_steps += 1
        if self.batch_steps == 5:
            raise RuntimeError("deliberate batch crash")
        err = observations.lengths - self.goals[observations.trials]
        out = CommandBatch.zeros(len(err))
        out.velocities[:] = -self.gain * err
        out.error_norm[:] = np.linalg.norm(err, axis=1)
        return out


class AdaptiveJoints(ProportionalJoints):
    """A plugin that declares ``adaptive_gain`` (it takes quick's [controller_options])."""

    name = "test-adaptive-joints"

    def __init__(self, gain: float = 2.0, adaptive_gain: list[float] | None = None) -> None:
        super().__init__(gain)
        self.adaptive_gain = adaptive_gain


class DeclaredOptions(ProportionalJoints):
    """A plugin that declares its options itself (``OPTIONS``)."""

    name = "test-declared"
    OPTIONS = (OptionSpec("gain", "float", 2.0, "1/s", "Gain of the leg-length servo."),)


class SlowLegZeroQP(LimitQPSolver):
    """The limit QP with one more limit of its own: leg 0 at most 30 mm/s (a solver
    plugin that extends the built-in's ``solve``, as docs/plugins.md shows)."""

    CAP = 0.03

    def solve(self, N: np.ndarray, b: np.ndarray, lam: float, q: np.ndarray, J: np.ndarray,
              pre: Any) -> Any:
        tau, rank, cond, active, reason, qdot = super().solve(N, b, lam, q, J, pre)
        qdot = J @ tau if qdot is None else qdot
        if abs(qdot[0]) > self.CAP:  # the whole twist scaled down: leg 0 at the cap
            tau, qdot = tau * (self.CAP / abs(qdot[0])), None
            active = [*active, "leg 0 at 30 mm/s"]
        return tau, rank, cond, active, reason, qdot


class LegEdgeSlowLegZero(LegEdgeQPController):
    """``leg-edge-qp`` with :class:`SlowLegZeroQP`."""

    name = "test-leg-edge-slow-leg-0"

    def __init__(self, **options: Any) -> None:
        super().__init__(**options)
        self.solver = SlowLegZeroQP(self.name, self.threshold)
