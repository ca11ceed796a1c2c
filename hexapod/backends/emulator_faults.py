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
        glitch_after: After this many commands, every position the board reports has its
            first leg ``glitch`` longer than it is (a glitching encoder or a corrupted
            reading that passed the checksum); the legs themselves are not moved.
        glitch: The ``glitch_after`` offset [m].
        drive_fault_after: At this command the board latches a drive fault of code
            ``drive_fault_code`` (a code the protocol does not define): its legs hold,
            every ``MOV`` from then on is answered with it, ``ERR?`` reads it first (and
            clears it).
        drive_fault_code: The ``drive_fault_after`` code.
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
    glitch_after: int | None = None
    glitch: float = 0.03
    drive_fault_after: int | None = None
    drive_fault_code: int = 30
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
        if not math.isfinite(self.glitch):
            raise BackendError(f"fault glitch must be finite, got {self.glitch} m")
        if self.drive_fault_code < 1:
            raise BackendError(f"fault drive_fault_code must be >= 1, got "
                               f"{self.drive_fault_code}")
        for name in ("silent_after", "disconnect_after", "stall_after", "glitch_after",
                     "drive_fault_after"):
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
        if self.glitch_after is not None:
            args += ["--glitch-after", str(self.glitch_after), "--glitch-mm",
                     repr(self.glitch * 1e3)]
        if self.drive_fault_after is not None:
            args += ["--drive-fault-after", str(self.drive_fault_after),
                     "--drive-fault-code", str(self.drive_fault_code)]
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
