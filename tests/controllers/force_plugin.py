"""A controller that commands leg forces, written as a plugin in one file.

Everything a force law needs from the framework is here: it declares
``actuation = Actuation.FORCE`` and returns :meth:`Command.of_forces`. It is a
spring-damper on the leg lengths, ``f = -k (q - q*) - c q_dot`` [N] (``q_dot``
from the observation when the robot measures it, else from the last two lengths).
Register it as ``tests.controllers.force_plugin:LegSpringForces`` (or through the
``hexapod.controllers`` entry-point group).
"""

from __future__ import annotations

import numpy as np

from controllers.base import Command, Controller, ControllerContext, Observation
from hexapod.actuation import Actuation


class LegSpringForces(Controller):
    """Leg forces pulling the lengths to the goal's: ``f = -k (q - q*) - c q_dot`` [N].

    Args:
        stiffness: ``k`` [N/m].
        damping: ``c`` [N s/m].
    """

    name = "test-leg-spring-forces"
    features = frozenset({"lengths"})
    actuation = Actuation.FORCE

    def __init__(self, stiffness: float = 2e4, damping: float = 300.0) -> None:
        self.stiffness = float(stiffness)
        self.damping = float(damping)
        self._goal = np.zeros(6)
        self._q_prev: np.ndarray | None = None
        self._dt = 1.0

    def reset(self, context: ControllerContext) -> None:
        if context.goal.lengths is None:
            raise ValueError("goal.lengths is needed")
        self._goal = np.asarray(context.goal.lengths, dtype=float)
        self._dt = float(context.dt)
        self._q_prev = None

    def step(self, observation: Observation) -> Command:
        q = np.asarray(observation.lengths, dtype=float)
        if observation.q_dot is not None:
            q_dot = np.asarray(observation.q_dot, dtype=float)
        else:
            q_dot = np.zeros(6) if self._q_prev is None else (q - self._q_prev) / self._dt
        self._q_prev = q.copy()
        err = q - self._goal
        forces = -self.stiffness * err - self.damping * q_dot
        return Command.of_forces(forces, error=err, error_norm=float(np.linalg.norm(err)))


class RefusingForces(LegSpringForces):
    """Refuses every period ("my sensor is blind"): the drives get no force and the
    platform falls under gravity (a failure the results must blame on the refusals)."""

    name = "test-refusing-forces"

    def step(self, observation: Observation) -> Command:
        return Command.refuse("my sensor is blind", actuation=Actuation.FORCE)
