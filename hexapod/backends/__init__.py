"""Robot backends: simulated robot, serial robot, firmware emulator."""

from hexapod.backends.base import Backend, BackendStep, clamp_velocities
from hexapod.backends.sim import SimulatedRobot

__all__ = ["Backend", "BackendStep", "SimulatedRobot", "clamp_velocities"]
