"""A robot plugin that sends and returns, as one written on a vendor library that queues
a setpoint may: the simulated robot, declared as hardware (not ``simulated``) and not
waiting out its periods (``paces_periods`` False, the default)."""

from __future__ import annotations

from hexapod.backends.sim import SimulatedRobot


class UnpacedRobot(SimulatedRobot):
    """:class:`~hexapod.backends.sim.SimulatedRobot` as a plugin for real hardware."""

    simulated = False
