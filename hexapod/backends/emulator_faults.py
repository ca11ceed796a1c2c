"""The faults an emulated device's server injects (:class:`FaultConfig`), seeded.

:class:`~hexapod.backends.emulator_server.EmulatorServer` keeps a :class:`FaultState`
(the configuration, its generator, the command count and a pending disconnection) and
corrupts lines with :func:`garble`.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass, field

from hexapod.exceptions import BackendError

__all__ = ["FaultConfig", "FaultState", "garble"]


@dataclass(frozen=True)
class FaultConfig:
    """Faults the emulator injects, drawn from a generator seeded with ``seed``.

    Attributes:
        latency: Fixed delay added to every reply [s].
        jitter: Extra delay, uniform in [0, jitter], added to every reply [s].
        drop_rate: Probability that a reply is not sent (the command is still executed).
        garble_rate: Probability that one byte of a line is corrupted, drawn separately
            for each received command (the board then answers ``ERR 3``) and each reply.
        silent_after: Stop replying (but keep executing commands) after this many commands.
        disconnect_after: Close the connection after replying to this many commands.
        stall_after: Stall after this many commands: for ``stall_s`` the device neither
            reads, executes nor answers anything (the commands wait in the link), then
            executes and answers them all in order (a controller frozen by a busy CPU or
            a stalled network).
        stall_s: Duration of the ``stall_after`` stall [s].
        seed: Seed of the fault generator.

    Counts of commands start when the faults are set (:meth:`Emulator.set_faults`).
    """

    latency: float = 0.0
    jitter: float = 0.0
    drop_rate: float = 0.0
    garble_rate: float = 0.0
    silent_after: int | None = None
    disconnect_after: int | None = None
    stall_after: int | None = None
    stall_s: float = 2.0
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("latency", "jitter", "stall_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise BackendError(f"fault {name} must be >= 0 s, got {value}")
        for name in ("drop_rate", "garble_rate"):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise BackendError(f"fault {name} must be a probability, got {value}")
        for name in ("silent_after", "disconnect_after", "stall_after"):
            value = getattr(self, name)
            if value is not None and value < 0:
                raise BackendError(f"fault {name} must be >= 0 commands, got {value}")

    def to_args(self) -> list[str]:
        """The ``hexapod-emulator`` options that inject these faults (milliseconds)."""
        args = ["--latency", repr(self.latency * 1e3), "--jitter", repr(self.jitter * 1e3),
                "--drop", repr(self.drop_rate), "--garble", repr(self.garble_rate),
                "--seed", str(self.seed)]
        if self.silent_after is not None:
            args += ["--silent-after", str(self.silent_after)]
        if self.disconnect_after is not None:
            args += ["--disconnect-after", str(self.disconnect_after)]
        if self.stall_after is not None:
            args += ["--stall-after", str(self.stall_after), "--stall-ms",
                     repr(self.stall_s * 1e3)]
        return args


@dataclass
class FaultState:
    """The faults being injected and their generator, counters and pending disconnection."""

    config: FaultConfig = field(default_factory=FaultConfig)
    rng: random.Random = field(default_factory=lambda: random.Random(0))
    commands: int = 0
    disconnect_pending: bool = False
    disconnect_at: float = math.inf
    stall_until: float = -math.inf


def garble(line: bytes, rng: random.Random, terminator: bytes = b"\n") -> bytes:
    """``line`` with one byte (never the final ``terminator``) replaced by another
    printable one drawn from ``rng`` (the garble fault)."""
    body = bytearray(line[: -len(terminator)] if line.endswith(terminator) else line)
    if not body:
        return line
    i = rng.randrange(len(body))
    choices = [c for c in range(0x21, 0x7F) if c != body[i]]
    body[i] = rng.choice(choices)
    return bytes(body) + line[len(body):]
