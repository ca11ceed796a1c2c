"""The serial backend against the board emulator: :func:`open_emulated_robot` starts a
``hexapod-emulator`` (thread or child process) and connects a
:class:`~hexapod.backends.serial.SerialRobot` to it."""

from __future__ import annotations

from typing import Any

import numpy as np

from hexapod.backends.serial import SerialRobot

__all__ = ["open_emulated_robot"]


def open_emulated_robot(
    geometry: Any,
    lengths: np.ndarray | None = None,
    *,
    faults: Any = None,
    lag: float = 0.0,
    line_rate: float = 0.0,
    transport: str = "pty",
    process: bool = False,
    **robot_options: Any,
) -> SerialRobot:
    """Start an emulator for a geometry and connect a :class:`SerialRobot` to it.

    Closing the robot stops the emulator.

    Args:
        geometry: A :class:`~hexapod.geometry.HexapodGeometry` (stroke, speed limit).
        lengths: Initial leg lengths [m] (mid-stroke if None).
        faults: A :class:`~hexapod.backends.emulator.FaultConfig` (none if None).
        lag: First-order lag of the emulated legs [s].
        line_rate: Emulated line rate [baud] (0: instantaneous).
        transport: ``"pty"`` or ``"tcp"`` (loopback).
        process: Run the emulator in a child process (``hexapod-emulator``: its timing
            does not share this interpreter) instead of a thread of this one.
        robot_options: Keyword arguments of :class:`SerialRobot`.

    Returns:
        The connected robot; ``robot.emulator`` is the running
        :class:`~hexapod.backends.emulator.Emulator` (or
        :class:`~hexapod.backends.emulator.EmulatorProcess`).
    """
    from hexapod.backends.emulator import BoardConfig, Emulator, EmulatorProcess

    config = BoardConfig.from_geometry(geometry, lengths, lag=lag)
    emu: Emulator | EmulatorProcess
    if process:
        emu = EmulatorProcess(config, faults, transport=transport, line_rate=line_rate)
    else:
        emu = Emulator(config, faults, transport=transport, line_rate=line_rate).start()

    def stop_emulator() -> None:
        emu.stop()

    try:
        robot = SerialRobot(emu.url, on_close=stop_emulator, **robot_options)
    except BaseException:
        emu.stop()
        raise
    robot.emulator = emu
    return robot
