"""A robot plugin that fails where it is told to (``module:FailingRobot:WHERE``), and
records the calls the host makes to it: what a host must do when a backend fails (halt
the robot, then close it; say what failed). ``WHERE`` is one of ``open``, ``reset``,
``step``, ``step-interrupt``, ``close``, ``reset+close``, ``five-legs``; the calls go to
:data:`CALLS`."""

from __future__ import annotations

from typing import Any

import numpy as np

from hexapod.backends.base import Backend, BackendStep
from hexapod.backends.sim import SimulatedRobot

#: Every call the host made, as ``(where, method)`` (a test reads then clears it).
CALLS: list[tuple[str, str]] = []


class FailingRobot(SimulatedRobot):
    """:class:`~hexapod.backends.sim.SimulatedRobot` as hardware, failing at ``where``."""

    simulated = False
    #: The base's: calls :meth:`halt` (the simulator's own does not)
    halt_confirmed = Backend.halt_confirmed

    def __init__(self, geometry: Any, where: str = "") -> None:
        if where == "open":
            raise ValueError("vendor SDK: device not found")
        self.where = ""  # (the simulator's own set-up resets it: not a host's call)
        super().__init__(geometry)
        self.where = where

    def reset(self, lengths: np.ndarray | None = None) -> Any:
        CALLS.append((self.where, "reset"))
        if self.where in ("reset", "reset+close"):
            raise RuntimeError("vendor SDK: reset failed")
        return super().reset(lengths)

    def step(self, velocities: np.ndarray, dt: float) -> BackendStep:
        CALLS.append((self.where, "step"))
        if self.where == "step":
            raise RuntimeError("vendor SDK: drive fault E42")
        if self.where == "step-interrupt":
            raise KeyboardInterrupt
        return super().step(velocities, dt)

    def measured_lengths(self) -> np.ndarray:
        q = super().measured_lengths()
        return q[:5] if self.where == "five-legs" else q

    def halt(self) -> Any:
        CALLS.append((self.where, "halt"))
        return super().halt()

    def close(self) -> None:
        CALLS.append((self.where, "close"))
        if self.where in ("close", "reset+close"):
            raise RuntimeError("vendor SDK: close failed")
        super().close()
