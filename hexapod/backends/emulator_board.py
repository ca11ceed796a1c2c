"""The emulated controller board of the project's serial protocol: its configuration and
its state machine.

The board (:class:`Board`) speaks the serial protocol of :mod:`hexapod.backends.protocol`
(``docs/serial-protocol.md``): six legs that track their setpoints at the speed limit
(with an optional first-order lag), the stroke, the servo, the watchdog and the error
register. Every method takes the current time of a monotonic clock, so the watchdog and
the speeds are real when the board is served by :class:`Emulator`.

:class:`Emulator` serves a board with the generic
:class:`~hexapod.backends.emulator_server.EmulatorServer`: the board exposes
:meth:`Board.handle_line`, :meth:`Board.advance`, :meth:`Board.frame`,
:meth:`Board.next_event`, :meth:`Board.overlong_line` and its line terminator
(:class:`~hexapod.backends.emulator_server.EmulatedDevice`).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np

from hexapod.backends import protocol
from hexapod.backends.emulator_server import EmulatorServer, FaultConfig
from hexapod.backends.protocol import ERROR_TEXT, ErrorCode
from hexapod.exceptions import BackendError, ShapeError
from hexapod.geometry import HexapodGeometry
from hexapod.link_errors import ChecksumError, ProtocolError

logger = logging.getLogger(__name__)

__all__ = ["ARRIVED", "HALTED_ERROR", "HALTED_SPEED", "STROKE_TOL", "Board", "BoardConfig",
           "Emulator"]

#: A leg within this distance of its setpoint has arrived [m] (half the protocol resolution).
ARRIVED = 0.5e-6
#: With ``dynamics``, after ``HLT`` (until the next accepted ``MOV`` or ``SVO``): every leg
#: within this of where it was halted [m] ...
HALTED_ERROR = 20e-6
#: ... and slower than this [m/s] reports ``moving=0`` (the position loop then settles the
#: last micrometres over one to three seconds; a host confirming a halt need not wait).
HALTED_SPEED = 1e-4
#: Tolerance of the stroke check [m] (setpoints are read with 1 um resolution).
STROKE_TOL = 1e-9


# ============================================================================ configuration
@dataclass(frozen=True)
class BoardConfig:
    """What the emulated board is.

    Attributes:
        stroke: Leg length limits (q_min, q_max) [m].
        max_speed: Hardware leg speed limit [m/s] (``VEL`` may lower it, not raise it).
        lengths: Initial leg lengths (6,) [m]; mid-stroke if None.
        lag: Time constant of the first-order lag of each leg [s] (0: a leg moves at the
            speed limit until it reaches its setpoint).
        watchdog: Initial watchdog period [s] (``WDT`` changes it).
        identity: The ``*IDN?`` text.
        dynamics: The TRUE robot whose mass and drives the axes move
            (:mod:`hexapod.backends.emulator_dynamics`; ``lag`` is then unused), or None.
        physics_dt: Physics step of ``dynamics`` [s].
    """

    stroke: tuple[float, float] = (0.345, 0.485)
    max_speed: float = 0.05
    lengths: tuple[float, ...] | None = None
    lag: float = 0.0
    watchdog: float = protocol.WATCHDOG_DEFAULT_MS / 1000.0
    identity: str = "hexapod-emulator 0.1.0"
    dynamics: HexapodGeometry | None = None
    physics_dt: float = 1e-3

    def __post_init__(self) -> None:
        lo, hi = (float(x) for x in self.stroke)
        if not (math.isfinite(lo) and math.isfinite(hi) and 0 < lo < hi):
            raise BackendError(f"emulator stroke must satisfy 0 < q_min < q_max, got {self.stroke}")
        if not (math.isfinite(self.max_speed) and self.max_speed > 0):
            raise BackendError(f"emulator max_speed must be positive, got {self.max_speed} m/s")
        if not (math.isfinite(self.lag) and self.lag >= 0):
            raise BackendError(f"emulator lag must be >= 0, got {self.lag} s")
        try:  # the reply to *IDN? must be a line of the protocol
            protocol.frame(f"IDN {self.identity}")
        except ProtocolError as exc:
            raise BackendError(f"emulator identity must be printable ASCII that fits a "
                               f"{protocol.MAX_LINE}-byte line with 'IDN ' and its checksum "
                               f"({protocol.MAX_LINE - 8} characters at most), got "
                               f"{len(self.identity)} characters ({exc.problem})") from None
        ms = self.watchdog * 1000.0
        if not protocol.WATCHDOG_MIN_MS <= ms <= protocol.WATCHDOG_MAX_MS:
            raise BackendError(
                f"emulator watchdog must be {protocol.WATCHDOG_MIN_MS} to "
                f"{protocol.WATCHDOG_MAX_MS} ms, got {ms:g} ms"
            )
        if self.lengths is not None:
            q = np.asarray(self.lengths, dtype=float)
            if q.shape != (6,) or not np.all(np.isfinite(q)):
                raise ShapeError("lengths", "6 finite leg lengths [m]", self.lengths)
            if np.any(q < lo - STROKE_TOL) or np.any(q > hi + STROKE_TOL):
                raise BackendError(
                    f"emulator initial lengths {np.round(q * 1e3, 3).tolist()} mm outside the "
                    f"stroke [{lo * 1e3:.3f}, {hi * 1e3:.3f}] mm"
                )
            object.__setattr__(self, "lengths", tuple(float(x) for x in q))
        object.__setattr__(self, "stroke", (lo, hi))

    @classmethod
    def from_geometry(
        cls, geometry: HexapodGeometry, lengths: np.ndarray | None = None, **changes: object
    ) -> BoardConfig:
        """A board with the stroke and speed limit of a geometry.

        Args:
            geometry: The robot (its ``stroke`` [m] and ``max_speed`` [m/s] are used).
            lengths: Initial leg lengths [m] (mid-stroke if None).
            changes: Other :class:`BoardConfig` fields (``lag``, ``watchdog``, ``identity``).
        """
        q = None if lengths is None else tuple(np.asarray(lengths, dtype=float).tolist())
        cfg = cls(stroke=geometry.stroke, max_speed=geometry.max_speed, lengths=q,
                  identity=f"hexapod-emulator 0.1.0 {geometry.name}")
        return replace(cfg, **changes)  # type: ignore[arg-type]


# ============================================================================ the board
class Board:
    """The controller board: legs, servo, watchdog and error register.

    Every method takes the current time ``now`` [s] of a monotonic clock; the legs
    are advanced exactly (in closed form) to that time before the command acts.

    Args:
        config: What the board is.
        now: The current time [s].
    """

    def __init__(self, config: BoardConfig, now: float) -> None:
        self.config = config
        lo, hi = config.stroke
        q0 = np.full(6, 0.5 * (lo + hi)) if config.lengths is None else np.array(config.lengths)
        #: True leg lengths [m].
        self.lengths = q0.astype(float)
        #: Leg setpoints [m].
        self.setpoints = self.lengths.copy()
        #: Current speed limit [m/s].
        self.speed = config.max_speed
        #: Watchdog period [s].
        self.watchdog = config.watchdog
        self.servo = False
        self.watchdog_latched = False
        self.error = ErrorCode.NONE
        self.error_text = ERROR_TEXT[ErrorCode.NONE]
        #: A latched drive fault (code, text), or None (fault injection).
        self.drive_fault: tuple[int, str] | None = None
        #: Added to the first leg's reported length [m] (fault injection).
        self.glitch = 0.0
        self.commands = 0
        self.last_command = ""
        self._last_mov = now
        self._t = now
        self._axes = None
        self._halted = False  # HLT received, no MOV or SVO since (the band of moving)
        if config.dynamics is not None:
            from hexapod.backends.emulator_dynamics import DynamicAxes

            self._axes = DynamicAxes(config.dynamics, self.lengths, config.physics_dt)

    # ---------------------------------------------------------------- physics
    @property
    def moving(self) -> bool:
        """At least one leg is away from its setpoint (with ``dynamics``: by more than
        :data:`ARRIVED`, or still moving faster than 1 um/s; after ``HLT``, by more than
        :data:`HALTED_ERROR` or faster than :data:`HALTED_SPEED`)."""
        if self._axes is not None:
            error, speed = (HALTED_ERROR, HALTED_SPEED) if self._halted else (ARRIVED, 1e-6)
            return bool(np.any(np.abs(self.setpoints - self.lengths) > error)
                        or np.any(np.abs(self._axes.leg_velocities()) > speed))
        return bool(np.any(self.setpoints != self.lengths))

    def trip_time(self) -> float | None:
        """When the watchdog will trip if no valid MOV arrives [s], None when disarmed."""
        if not self.servo or self.watchdog_latched:
            return None
        return self._last_mov + self.watchdog

    def advance(self, now: float) -> None:
        """Move the legs and run the watchdog up to ``now`` [s]."""
        trip = self.trip_time()
        if trip is not None and trip <= now:
            self._move(trip)
            self.setpoints = self.lengths.copy()
            self._halted = True  # stopped like an HLT
            self.watchdog_latched = True
            self._set_error(ErrorCode.WATCHDOG, f"watchdog: no valid MOV within "
                                                f"{self.watchdog * 1e3:.0f} ms")
            logger.info("watchdog tripped after %.0f ms", self.watchdog * 1e3)
        self._move(now)

    def _move(self, now: float) -> None:
        dt = now - self._t
        if dt <= 0:
            return
        self._t = now
        if self._axes is not None:
            self.lengths = self._axes.move(self.setpoints, self.speed, dt)
            return
        err = self.setpoints - self.lengths
        dist = np.abs(err)
        v, tau = self.speed, self.config.lag
        if tau <= 0:
            left = np.maximum(dist - v * dt, 0.0)
        else:
            # saturated at v until |err| = v tau, then exponential with time constant tau
            t_sat = np.maximum((dist - v * tau) / v, 0.0)
            left = np.where(dt <= t_sat, dist - v * dt,
                            np.minimum(dist, v * tau) * np.exp(-(dt - t_sat) / tau))
            left[left < ARRIVED] = 0.0
        self.lengths = self.setpoints - np.sign(err) * left

    # ---------------------------------------------------------------- errors
    def _set_error(self, code: ErrorCode, text: str | None = None) -> None:
        self.error = code
        self.error_text = text or ERROR_TEXT[code]

    def _err(self, code: ErrorCode, detail: str = "") -> str:
        text = ERROR_TEXT[code] + (f": {detail}" if detail else "")
        self._set_error(code, text)
        return f"ERR {int(code)} {text}"

    def inject_glitch(self, offset: float) -> None:
        """From now on report the first leg ``offset`` [m] longer than it is."""
        self.glitch = float(offset)

    def inject_drive_fault(self, code: int) -> None:
        """Latch a drive fault of ``code`` (its legs hold where they are)."""
        self.drive_fault = (int(code), "drive fault (fault injection)")
        self.setpoints = self.lengths.copy()

    def pending_error(self) -> tuple[int, str]:
        """What ``ERR?`` would return: a latched drive fault, then the latched watchdog,
        then the last error."""
        if self.drive_fault is not None:
            return self.drive_fault
        if self.watchdog_latched:
            return int(ErrorCode.WATCHDOG), ERROR_TEXT[ErrorCode.WATCHDOG]
        return int(self.error), self.error_text

    # ---------------------------------------------------------------- served device
    #: Every line (command or reply) ends with this byte.
    terminator: ClassVar[bytes] = b"\n"
    #: Longest line accepted before the terminator [bytes].
    max_line: ClassVar[int] = protocol.MAX_LINE

    def frame(self, reply: str) -> bytes:
        """The bytes of a reply payload on the wire (checksum and terminator added)."""
        return protocol.frame(reply)

    def next_event(self) -> float | None:
        """When the board must be advanced without a command (its watchdog) [s], or None."""
        return self.trip_time()

    def overlong_line(self) -> str:
        """The reply to a line longer than :attr:`max_line` (it is discarded)."""
        return self._err(ErrorCode.SYNTAX, "line too long")

    # ---------------------------------------------------------------- commands
    def handle_line(self, line: bytes, now: float) -> str:
        """Answer one received line (checksum included, terminator optional).

        Returns:
            The reply payload (to be framed).
        """
        self.advance(now)
        self.commands += 1
        try:
            payload = protocol.unframe(line)
        except ChecksumError:
            self.last_command = "<bad checksum>"
            return self._err(ErrorCode.CHECKSUM)
        except ProtocolError:
            self.last_command = "<not ascii>"
            return self._err(ErrorCode.SYNTAX, "not printable ASCII")
        self.last_command = payload
        return self.handle(payload, now)

    def handle(self, payload: str, now: float) -> str:
        """Answer one command payload (checksum already checked).

        Returns:
            The reply payload.
        """
        self.advance(now)
        words = payload.split()
        if not words:
            return self._err(ErrorCode.SYNTAX, "empty command")
        name, args = words[0], words[1:]
        handler = self._handlers.get(name)
        if handler is None:
            return self._err(ErrorCode.UNKNOWN_COMMAND, name)
        return handler(self, args, now)

    def _query(self, args: list[str], name: str) -> str | None:
        return self._err(ErrorCode.SYNTAX, f"{name} takes no argument") if args else None

    def _idn(self, args: list[str], now: float) -> str:
        return self._query(args, "*IDN?") or f"IDN {self.config.identity}"

    def _svo(self, args: list[str], now: float) -> str:
        if len(args) != 1 or args[0] not in ("0", "1"):
            return self._err(ErrorCode.SYNTAX, "SVO 0 or SVO 1")
        on = args[0] == "1"
        self.setpoints = self.lengths.copy()  # servo on or off: hold where it is
        self._halted = False
        if on and not self.servo:
            self._last_mov = now  # the watchdog starts now
        self.servo = on
        return "OK"

    def _mov(self, args: list[str], now: float) -> str:
        if len(args) != 6:
            return self._err(ErrorCode.SYNTAX, f"MOV takes 6 lengths, got {len(args)}")
        try:
            q = np.array([protocol.mm_to_m(protocol.parse_number(a)) for a in args])
        except ValueError:
            return self._err(ErrorCode.SYNTAX, "a length is not a number")
        if not self.servo:
            return self._err(ErrorCode.SERVO_OFF)
        if self.drive_fault is not None:
            return "ERR {} {}".format(*self.drive_fault)
        if self.watchdog_latched:
            return self._err(ErrorCode.WATCHDOG, "latched, read ERR? to clear")
        lo, hi = self.config.stroke
        bad = np.flatnonzero((q < lo - STROKE_TOL) | (q > hi + STROKE_TOL))
        if len(bad):
            i = int(bad[0])
            return self._err(ErrorCode.OUTSIDE_STROKE,
                             f"l{i + 1}={args[i]} not in [{lo * 1e3:.3f}, {hi * 1e3:.3f}]")
        self.setpoints = np.clip(q, lo, hi)
        self._halted = False
        self._last_mov = now
        return "OK"

    def _pos(self, args: list[str], now: float) -> str:
        shown = self.lengths + np.array([self.glitch, 0, 0, 0, 0, 0]) if self.glitch else \
            self.lengths
        return self._query(args, "POS?") or "POS " + protocol.format_lengths(shown)

    def _sta(self, args: list[str], now: float) -> str:
        code, _ = self.pending_error()
        return self._query(args, "STA?") or (
            f"STA servo={int(self.servo)} moving={int(self.moving)} error={code} "
            f"watchdog={int(self.watchdog_latched)}"
        )

    def _lim(self, args: list[str], now: float) -> str:
        lo, hi = self.config.stroke
        return self._query(args, "LIM?") or (
            f"LIM {protocol.format_mm(lo)} {protocol.format_mm(hi)} "
            f"{protocol.format_mm(self.speed)}"
        )

    def _vel(self, args: list[str], now: float) -> str:
        if len(args) != 1:
            return self._err(ErrorCode.SYNTAX, "VEL <mm/s>")
        try:
            v = protocol.mm_to_m(protocol.parse_number(args[0]))
        except ValueError:
            return self._err(ErrorCode.SYNTAX, "speed is not a number")
        vmax = self.config.max_speed
        if not 0 < v <= vmax + STROKE_TOL:
            return self._err(ErrorCode.SPEED_RANGE,
                             f"{args[0]} not in (0, {protocol.format_mm(vmax)}]")
        self.speed = min(v, vmax)
        return "OK"

    def _wdt(self, args: list[str], now: float) -> str:
        lo, hi = protocol.WATCHDOG_MIN_MS, protocol.WATCHDOG_MAX_MS
        if len(args) != 1 or not args[0].isdigit() or not lo <= int(args[0]) <= hi:
            return self._err(ErrorCode.SYNTAX, f"WDT takes an integer from {lo} to {hi} ms")
        self.watchdog = int(args[0]) / 1000.0
        self._last_mov = now
        return "OK"

    def _hlt(self, args: list[str], now: float) -> str:
        if args:
            return self._err(ErrorCode.SYNTAX, "HLT takes no argument")
        self.setpoints = self.lengths.copy()
        self._halted = True
        self._set_error(ErrorCode.HALTED)
        logger.info("HLT: legs halted at %s mm", np.round(self.lengths * 1e3, 3).tolist())
        return "OK"

    def _err_query(self, args: list[str], now: float) -> str:
        if args:
            return self._err(ErrorCode.SYNTAX, "ERR? takes no argument")
        code, text = self.pending_error()
        if self.drive_fault is not None:  # read first, cleared alone
            self.drive_fault = None
            return f"ERR {code} {text}"
        self.watchdog_latched = False
        self._set_error(ErrorCode.NONE)
        self._last_mov = now  # the watchdog starts again
        return f"ERR {code} {text}"

    _handlers: ClassVar[dict[str, Callable[[Board, list[str], float], str]]] = {
        "*IDN?": _idn,
        "SVO": _svo,
        "MOV": _mov,
        "POS?": _pos,
        "STA?": _sta,
        "LIM?": _lim,
        "VEL": _vel,
        "WDT": _wdt,
        "HLT": _hlt,
        "ERR?": _err_query,
    }


class Emulator(EmulatorServer[Board]):
    """The project's controller board served on a pseudo-terminal or a loopback TCP port.

    Args:
        config: The board (DeltaLab strokes and speed, mid-stroke, if None).
        faults, transport, host, port, allow_remote, line_rate: As for
            :class:`~hexapod.backends.emulator_server.EmulatorServer`.

    Example:
        >>> with Emulator(BoardConfig.from_geometry(deltalab())).start() as emu:
        ...     robot = SerialRobot(emu.url)
    """

    def __init__(
        self,
        config: BoardConfig | None = None,
        faults: FaultConfig | None = None,
        *,
        transport: str = "pty",
        host: str = "127.0.0.1",
        port: int = 0,
        allow_remote: bool = False,
        line_rate: float = 0.0,
    ) -> None:
        self.config = config or BoardConfig()
        super().__init__(Board(self.config, time.monotonic()), faults, transport=transport,
                         host=host, port=port, allow_remote=allow_remote, line_rate=line_rate)

    def true_lengths(self) -> np.ndarray:
        """The board's true leg lengths now (6,) [m]."""
        with self._lock:
            self.board.advance(time.monotonic())
            return self.board.lengths.copy()

    def status(self) -> protocol.Status:
        """The board's status now (as ``STA?`` would report it, without using the link)."""
        with self._lock:
            b = self.board
            b.advance(time.monotonic())
            return protocol.Status(b.servo, b.moving, b.pending_error()[0], b.watchdog_latched)
