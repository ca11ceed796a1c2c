"""An emulator of the hexapod's controller board, on a pseudo-terminal or a loopback socket.

The board (:class:`Board`) is a state machine that speaks the serial protocol of
:mod:`hexapod.backends.protocol` (``docs/serial-protocol.md``): six legs that track
their setpoints at the speed limit (with an optional first-order lag), the stroke,
the servo, the watchdog and the error register. Its time is the real (monotonic)
clock, so the watchdog and the speeds are real.

:class:`Emulator` serves a board on a real pseudo-terminal (``.device`` is the slave
path that pyserial opens) or on a loopback TCP port (``socket://127.0.0.1:PORT``),
in a thread (``start()``/``stop()``) or in the foreground (``serve_forever()``), and
injects seeded faults on demand (:class:`FaultConfig`): latency, dropped replies,
garbled bytes, a silent device, a disconnection.

The console script ``hexapod-emulator`` (:func:`main`) prints the device path (or
socket URL) as its first line on stdout, then serves until Ctrl-C.
"""

from __future__ import annotations

import argparse
import contextlib
import ipaddress
import logging
import math
import os
import random
import select
import signal
import socket
import subprocess
import sys
import threading
import time
import tty
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import FrameType, TracebackType
from typing import ClassVar

import numpy as np

from hexapod.backends import protocol
from hexapod.backends.protocol import ERROR_TEXT, ErrorCode
from hexapod.exceptions import BackendError, ChecksumError, ProtocolError, ShapeError
from hexapod.geometry import HexapodGeometry

logger = logging.getLogger(__name__)

__all__ = ["Board", "BoardConfig", "Emulator", "EmulatorProcess", "FaultConfig", "main"]

#: A leg within this distance of its setpoint has arrived [m] (half the protocol resolution).
ARRIVED = 0.5e-6
#: Time left to the host to read the last reply before a disconnection fault [s].
DISCONNECT_GRACE = 0.02
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
    """

    stroke: tuple[float, float] = (0.345, 0.485)
    max_speed: float = 0.05
    lengths: tuple[float, ...] | None = None
    lag: float = 0.0
    watchdog: float = protocol.WATCHDOG_DEFAULT_MS / 1000.0
    identity: str = "hexapod-emulator 0.1.0"

    def __post_init__(self) -> None:
        lo, hi = (float(x) for x in self.stroke)
        if not (math.isfinite(lo) and math.isfinite(hi) and 0 < lo < hi):
            raise BackendError(f"emulator stroke must satisfy 0 < q_min < q_max, got {self.stroke}")
        if not (math.isfinite(self.max_speed) and self.max_speed > 0):
            raise BackendError(f"emulator max_speed must be positive, got {self.max_speed} m/s")
        if not (math.isfinite(self.lag) and self.lag >= 0):
            raise BackendError(f"emulator lag must be >= 0, got {self.lag} s")
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
        seed: Seed of the fault generator.

    Counts of commands start when the faults are set (:meth:`Emulator.set_faults`).
    """

    latency: float = 0.0
    jitter: float = 0.0
    drop_rate: float = 0.0
    garble_rate: float = 0.0
    silent_after: int | None = None
    disconnect_after: int | None = None
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("latency", "jitter"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise BackendError(f"fault {name} must be >= 0 s, got {value}")
        for name in ("drop_rate", "garble_rate"):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise BackendError(f"fault {name} must be a probability, got {value}")
        for name in ("silent_after", "disconnect_after"):
            value = getattr(self, name)
            if value is not None and value < 0:
                raise BackendError(f"fault {name} must be >= 0 commands, got {value}")


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
        self.commands = 0
        self.last_command = ""
        self._last_mov = now
        self._t = now

    # ---------------------------------------------------------------- physics
    @property
    def moving(self) -> bool:
        """At least one leg is away from its setpoint."""
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

    def pending_error(self) -> tuple[int, str]:
        """What ``ERR?`` would return: the latched watchdog first, then the last error."""
        if self.watchdog_latched:
            return int(ErrorCode.WATCHDOG), ERROR_TEXT[ErrorCode.WATCHDOG]
        return int(self.error), self.error_text

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
        if self.watchdog_latched:
            return self._err(ErrorCode.WATCHDOG, "latched, read ERR? to clear")
        lo, hi = self.config.stroke
        bad = np.flatnonzero((q < lo - STROKE_TOL) | (q > hi + STROKE_TOL))
        if len(bad):
            i = int(bad[0])
            return self._err(ErrorCode.OUTSIDE_STROKE,
                             f"l{i + 1}={args[i]} not in [{lo * 1e3:.3f}, {hi * 1e3:.3f}]")
        self.setpoints = np.clip(q, lo, hi)
        self._last_mov = now
        return "OK"

    def _pos(self, args: list[str], now: float) -> str:
        return self._query(args, "POS?") or "POS " + protocol.format_lengths(self.lengths)

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
        self._set_error(ErrorCode.HALTED)
        return "OK"

    def _err_query(self, args: list[str], now: float) -> str:
        if args:
            return self._err(ErrorCode.SYNTAX, "ERR? takes no argument")
        code, text = self.pending_error()
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


# ============================================================================ the server
@dataclass
class _Reply:
    due: float
    data: bytes


@dataclass
class _FaultState:
    config: FaultConfig = field(default_factory=FaultConfig)
    rng: random.Random = field(default_factory=lambda: random.Random(0))
    commands: int = 0
    disconnect_pending: bool = False
    disconnect_at: float = math.inf


def _check_loopback(host: str, allow_remote: bool) -> None:
    try:
        infos = socket.getaddrinfo(host, None, type=socket.SOCK_STREAM)
    except socket.gaierror as exc:
        raise BackendError(f"emulator: cannot resolve '{host}': {exc}") from None
    remote = [i[4][0] for i in infos if not ipaddress.ip_address(i[4][0]).is_loopback]
    if remote and not allow_remote:
        raise BackendError(
            f"emulator: refusing to listen on non-loopback address '{host}' ({remote[0]}); "
            "use a loopback address (127.0.0.1) or force it (allow_remote / --allow-remote)"
        )


class Emulator:
    """A controller board served on a pseudo-terminal or a loopback TCP port.

    Args:
        config: The board (DeltaLab strokes and speed, mid-stroke, if None).
        faults: Faults to inject (none if None).
        transport: ``"pty"`` or ``"tcp"``.
        host: TCP address to listen on (loopback only unless ``allow_remote``).
        port: TCP port (0: any free port, see :attr:`url`).
        allow_remote: Allow a non-loopback ``host``.
        line_rate: If positive, emulate the transmission time of the lines at this baud
            rate (10 bits a byte): each reply is delayed by the time it takes the command
            and the reply to cross the link [baud]. 0: instantaneous.

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
        if transport not in ("pty", "tcp"):
            raise BackendError(f"emulator transport must be 'pty' or 'tcp', got '{transport}'")
        if transport == "tcp":
            _check_loopback(host, allow_remote)
        if not (math.isfinite(line_rate) and line_rate >= 0):
            raise BackendError(f"emulator line_rate must be >= 0 baud, got {line_rate}")
        self.config = config or BoardConfig()
        self.transport = transport
        self.line_rate = float(line_rate)
        self._host, self._port = host, port
        self._lock = threading.RLock()
        self.board = Board(self.config, time.monotonic())
        self._faults = _FaultState()
        self.set_faults(faults or FaultConfig())
        self._stop = threading.Event()
        self._stopped = threading.Event()
        self._thread: threading.Thread | None = None
        self._master: int | None = None
        self._slave: int | None = None
        self._listener: socket.socket | None = None
        self._client: socket.socket | None = None
        self._wake_r, self._wake_w = os.pipe()
        self._replies: deque[_Reply] = deque()
        self._inbuf = bytearray()
        self._opened = False
        self._closed = False
        #: Connections closed by the ``disconnect_after`` fault.
        self.disconnections = 0
        self.device = ""
        self.url = ""

    # ---------------------------------------------------------------- API
    def set_faults(self, faults: FaultConfig) -> None:
        """Inject other faults from now on (re-seeds the generator, restarts the counts)."""
        with self._lock:
            self._faults = _FaultState(faults, random.Random(faults.seed))

    @property
    def faults(self) -> FaultConfig:
        """The faults being injected."""
        return self._faults.config

    def open(self) -> Emulator:
        """Create the pseudo-terminal or the listening socket (sets :attr:`device`, :attr:`url`)."""
        if self._opened:
            return self
        if self.transport == "pty":
            master, slave = os.openpty()
            tty.setraw(slave)
            os.set_blocking(master, False)
            self._master, self._slave = master, slave
            self.device = os.ttyname(slave)
            self.url = self.device
        else:
            family = socket.AF_INET6 if ":" in self._host else socket.AF_INET
            srv = socket.socket(family, socket.SOCK_STREAM)
            srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            srv.bind((self._host, self._port))
            srv.listen(1)
            self._listener = srv
            host, port = srv.getsockname()[:2]
            self.device = f"{host}:{port}"
            self.url = f"socket://{host}:{port}" if family == socket.AF_INET else \
                f"socket://[{host}]:{port}"
        self._opened = True
        logger.info("emulator serving on %s", self.url)
        return self

    def start(self) -> Emulator:
        """Open (if needed) and serve in a daemon thread; returns self."""
        self.open()
        if self._thread is None:
            self._thread = threading.Thread(target=self.serve_forever, name="hexapod-emulator",
                                            daemon=True)
            self._thread.start()
        return self

    def stop(self, timeout: float = 2.0) -> None:
        """Stop serving, join the thread and close every file descriptor."""
        self._stop.set()
        with contextlib.suppress(OSError):
            os.write(self._wake_w, b"x")
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout)
        self._close_all()

    @property
    def running(self) -> bool:
        """The server is serving (not stopped, not disconnected for good)."""
        return self._opened and not self._stopped.is_set()

    def wait_stopped(self, timeout: float | None = None) -> bool:
        """Wait until the server stops (e.g. after a pty disconnection); True if it did."""
        return self._stopped.wait(timeout)

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

    def __enter__(self) -> Emulator:
        return self.start()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.stop()

    # ---------------------------------------------------------------- serving
    def serve_forever(self) -> None:
        """Serve until :meth:`stop` (or, on a pty, until a ``disconnect_after`` fault)."""
        self.open()
        try:
            while not self._stop.is_set():
                if not self._serve_once():
                    break
        except Exception:
            logger.exception("emulator crashed")
            raise
        finally:
            self._stopped.set()
            if self._thread is None:
                self._close_all()

    def _conn_fd(self) -> int | None:
        if self.transport == "pty":
            return self._master
        return self._client.fileno() if self._client is not None else None

    def _serve_once(self) -> bool:
        now = time.monotonic()
        with self._lock:
            self.board.advance(now)
            trip = self.board.trip_time()
        timeout = 0.05
        if self._faults.disconnect_pending:
            timeout = 0.005
        if self._replies:
            timeout = min(timeout, self._replies[0].due - now)
        if trip is not None:
            timeout = min(timeout, trip - now)
        fds: list[int] = [self._wake_r]
        conn = self._conn_fd()
        if conn is not None:
            fds.append(conn)
        elif self._listener is not None:
            fds.append(self._listener.fileno())
        ready, _, _ = select.select(fds, [], [], max(timeout, 0.0))
        if self._wake_r in ready:
            with contextlib.suppress(OSError):
                os.read(self._wake_r, 64)
        if self._listener is not None and self._listener.fileno() in ready:
            client, addr = self._listener.accept()
            client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            client.setblocking(False)
            self._client = client
            self._inbuf.clear()
            logger.info("emulator: connection from %s", addr)
        if conn is not None and conn in ready:
            data = self._read(conn)
            if data is None:
                return self._drop_connection("peer closed the connection")
            self._inbuf += data
            self._process_input()
        self._send_due()
        fs = self._faults
        if fs.disconnect_pending and not self._replies and fs.disconnect_at == math.inf:
            # let the host read the last reply: closing a pty master discards unread data
            fs.disconnect_at = time.monotonic() + DISCONNECT_GRACE
        if fs.disconnect_pending and time.monotonic() >= fs.disconnect_at:
            fs.disconnect_pending = False
            fs.disconnect_at = math.inf
            self.disconnections += 1
            logger.info("emulator: disconnecting (fault injection)")
            return self._drop_connection("fault injection")
        return True

    def _read(self, fd: int) -> bytes | None:
        try:
            if self.transport == "pty":
                data = os.read(fd, 4096)
            else:
                if self._client is None:
                    return None
                data = self._client.recv(4096)
        except (BlockingIOError, InterruptedError):
            return b""
        except OSError:
            return None
        return data or None

    def _drop_connection(self, why: str) -> bool:
        """Close the connection; a pty cannot come back (the server stops), a TCP server
        accepts the next connection. Returns whether to go on serving."""
        self._replies.clear()
        self._inbuf.clear()
        if self.transport == "pty":
            logger.info("emulator: pty closed (%s)", why)
            self._close_pty()
            return False
        if self._client is not None:
            with contextlib.suppress(OSError):
                self._client.close()
            self._client = None
            logger.info("emulator: connection closed (%s)", why)
        return True

    def _process_input(self) -> None:
        while True:
            nl = self._inbuf.find(b"\n")
            if nl < 0:
                if len(self._inbuf) > protocol.MAX_LINE:
                    self._inbuf.clear()
                    with self._lock:
                        reply = self.board._err(ErrorCode.SYNTAX, "line too long")
                    self._queue(protocol.frame(reply), protocol.MAX_LINE)
                return
            line = bytes(self._inbuf[: nl + 1])
            del self._inbuf[: nl + 1]
            self._command(line)

    def _command(self, line: bytes) -> None:
        fs = self._faults
        f = fs.config
        if fs.disconnect_pending:
            return  # the cable is being pulled
        if f.garble_rate and fs.rng.random() < f.garble_rate:
            line = self._garble(line, fs.rng)
        with self._lock:
            reply = self.board.handle_line(line, time.monotonic())
        fs.commands += 1
        data = protocol.frame(reply)
        if f.silent_after is not None and fs.commands > f.silent_after:
            return
        if f.drop_rate and fs.rng.random() < f.drop_rate:
            logger.debug("emulator: dropping the reply %r", data)
            return
        if f.garble_rate and fs.rng.random() < f.garble_rate:
            data = self._garble(data, fs.rng)
        self._queue(data, len(line))
        if f.disconnect_after is not None and fs.commands >= f.disconnect_after:
            fs.disconnect_pending = True

    @staticmethod
    def _garble(line: bytes, rng: random.Random) -> bytes:
        """Replace one byte (never the terminator) by another printable one."""
        body = bytearray(line.rstrip(b"\n"))
        if not body:
            return line
        i = rng.randrange(len(body))
        choices = [c for c in range(0x21, 0x7F) if c != body[i]]
        body[i] = rng.choice(choices)
        return bytes(body) + line[len(body):]

    def _queue(self, data: bytes, received: int) -> None:
        f = self._faults.config
        now = time.monotonic()
        delay = f.latency + (self._faults.rng.uniform(0.0, f.jitter) if f.jitter else 0.0)
        due = now + delay
        if self.line_rate > 0:
            due += 10.0 * received / self.line_rate
        if self._replies:
            due = max(due, self._replies[-1].due)
        if self.line_rate > 0:
            due += 10.0 * len(data) / self.line_rate
        self._replies.append(_Reply(due, data))

    def _send_due(self) -> None:
        now = time.monotonic()
        while self._replies and self._replies[0].due <= now:
            data = self._replies.popleft().data
            try:
                if self.transport == "pty":
                    if self._master is not None:
                        os.write(self._master, data)
                elif self._client is not None:
                    self._client.sendall(data)
            except BlockingIOError:
                logger.warning("emulator: host not reading, reply dropped")
            except OSError as exc:
                logger.info("emulator: write failed (%s)", exc)

    def _close_pty(self) -> None:
        for name in ("_master", "_slave"):
            fd = getattr(self, name)
            if fd is not None:
                with contextlib.suppress(OSError):
                    os.close(fd)
                setattr(self, name, None)

    def _close_all(self) -> None:
        if self._closed:
            return
        if self._thread is not None and self._thread.is_alive():
            return  # the thread closes on its way out
        self._closed = True
        self._close_pty()
        for sock in (self._client, self._listener):
            if sock is not None:
                with contextlib.suppress(OSError):
                    sock.close()
        self._client = self._listener = None
        for fd in (self._wake_r, self._wake_w):
            with contextlib.suppress(OSError):
                os.close(fd)
        self._stopped.set()


# ============================================================================ in a process
def config_to_args(config: BoardConfig, faults: FaultConfig | None = None) -> list[str]:
    """Command-line options of ``hexapod-emulator`` that describe a board and its faults."""
    c = config
    args = ["--stroke", protocol.format_mm(c.stroke[0]), protocol.format_mm(c.stroke[1]),
            "--speed", protocol.format_mm(c.max_speed), "--lag", repr(c.lag),
            "--watchdog", str(round(c.watchdog * 1e3)), "--identity", c.identity]
    if c.lengths is not None:
        args += ["--lengths", *(protocol.format_mm(x) for x in c.lengths)]
    if faults is not None:
        f = faults
        args += ["--latency", repr(f.latency * 1e3), "--jitter", repr(f.jitter * 1e3),
                 "--drop", repr(f.drop_rate), "--garble", repr(f.garble_rate),
                 "--seed", str(f.seed)]
        if f.silent_after is not None:
            args += ["--silent-after", str(f.silent_after)]
        if f.disconnect_after is not None:
            args += ["--disconnect-after", str(f.disconnect_after)]
    return args


class EmulatorProcess:
    """``hexapod-emulator`` in a child process (its own interpreter, so its timing does
    not share the host's GIL), started with ``python -m hexapod.backends.emulator``.

    Args:
        config: The board (default board if None).
        faults: Faults to inject.
        transport: ``"pty"`` or ``"tcp"`` (loopback, any free port).
        line_rate: Emulated line rate [baud] (0: instantaneous).
        startup_timeout: Longest wait for the device line [s].

    Attributes:
        url: The device path or ``socket://`` URL printed by the emulator.
    """

    def __init__(self, config: BoardConfig | None = None, faults: FaultConfig | None = None,
                 *, transport: str = "pty", line_rate: float = 0.0,
                 startup_timeout: float = 30.0) -> None:
        where = ["--pty"] if transport == "pty" else ["--tcp", "127.0.0.1:0"]
        args = [sys.executable, "-m", "hexapod.backends.emulator", *where,
                *config_to_args(config or BoardConfig(), faults), "--line-rate", repr(line_rate)]
        self.proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True)
        if self.proc.stdout is None:
            raise BackendError("hexapod-emulator: no stdout")
        ready, _, _ = select.select([self.proc.stdout], [], [], startup_timeout)
        line = self.proc.stdout.readline().strip() if ready else ""
        if not line:
            self.stop()
            err = self.proc.stderr.read() if self.proc.stderr is not None else ""
            raise BackendError(f"hexapod-emulator did not start: {err.strip()[-500:]}")
        self.url = line
        self.device = line

    @property
    def running(self) -> bool:
        """The process is alive."""
        return self.proc.poll() is None

    def stop(self, timeout: float = 5.0) -> int | None:
        """Terminate the process (SIGTERM, then SIGKILL) and return its exit status."""
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        for stream in (self.proc.stdout, self.proc.stderr):
            if stream is not None:
                stream.close()
        return self.proc.returncode

    def __enter__(self) -> EmulatorProcess:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.stop()


# ============================================================================ command line
def _parse_tcp(text: str) -> tuple[str, int]:
    host, sep, port = text.rpartition(":")
    if not sep or not port.isdigit():
        raise argparse.ArgumentTypeError(f"expected HOST:PORT, got '{text}'")
    return host.strip("[]") or "127.0.0.1", int(port)


def _load_geometry(name: str) -> HexapodGeometry:
    from hexapod.geometry import preset

    if name.endswith(".toml") or Path(name).is_file():
        return HexapodGeometry.from_toml(name)
    return preset(name)


def build_parser() -> argparse.ArgumentParser:
    """The ``hexapod-emulator`` argument parser."""
    p = argparse.ArgumentParser(
        prog="hexapod-emulator",
        description="Emulate the hexapod's controller board (docs/serial-protocol.md) on a "
                    "pseudo-terminal or a loopback TCP port. Prints the device path (or "
                    "socket URL) as the first line on stdout, then serves until Ctrl-C.",
    )
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--pty", action="store_true", help="serve on a new pseudo-terminal")
    where.add_argument("--tcp", type=_parse_tcp, metavar="HOST:PORT",
                       help="serve on a TCP port (loopback only; port 0: any free port)")
    p.add_argument("--allow-remote", action="store_true",
                   help="allow a non-loopback --tcp address (the robot then obeys the network)")
    robot = p.add_argument_group("robot")
    robot.add_argument("--geometry", default="deltalab",
                       help="geometry preset name or TOML file (stroke and speed; "
                            "default: deltalab)")
    robot.add_argument("--stroke", type=float, nargs=2, metavar=("MIN", "MAX"),
                       help="stroke limits [mm] (default: from the geometry)")
    robot.add_argument("--speed", type=float, metavar="MM_S",
                       help="leg speed limit [mm/s] (default: from the geometry)")
    robot.add_argument("--lengths", type=float, nargs="+", metavar="MM",
                       help="initial leg lengths [mm]: one for all legs or six "
                            "(default: mid-stroke)")
    robot.add_argument("--lag", type=float, default=0.0, metavar="S",
                       help="first-order lag time constant of each leg [s] (default 0)")
    robot.add_argument("--identity", help="the *IDN? text (default: emulator and geometry name)")
    robot.add_argument("--watchdog", type=int, default=protocol.WATCHDOG_DEFAULT_MS,
                       metavar="MS", help="initial watchdog period [ms] (default 100)")
    faults = p.add_argument_group("fault injection (seeded)")
    faults.add_argument("--latency", type=float, default=0.0, metavar="MS",
                        help="delay added to every reply [ms]")
    faults.add_argument("--jitter", type=float, default=0.0, metavar="MS",
                        help="extra uniform delay in [0, JITTER] per reply [ms]")
    faults.add_argument("--drop", type=float, default=0.0, metavar="P",
                        help="probability of dropping a reply")
    faults.add_argument("--garble", type=float, default=0.0, metavar="P",
                        help="probability of corrupting one byte of a command or a reply")
    faults.add_argument("--silent-after", type=int, metavar="N",
                        help="stop replying after N commands (still executing them)")
    faults.add_argument("--disconnect-after", type=int, metavar="N",
                        help="close the connection after replying to N commands")
    faults.add_argument("--seed", type=int, default=0, help="seed of the faults (default 0)")
    p.add_argument("--line-rate", type=float, default=0.0, metavar="BAUD",
                   help="emulate the transmission time of the lines at this baud rate "
                        "(e.g. 115200; default 0: instantaneous)")
    p.add_argument("--log-level", default="WARNING",
                   choices=["DEBUG", "INFO", "WARNING", "ERROR"], help="logging level (stderr)")
    return p


def config_from_args(args: argparse.Namespace) -> tuple[BoardConfig, FaultConfig]:
    """The board and faults described by parsed command-line arguments."""
    geometry = _load_geometry(args.geometry)
    stroke = geometry.stroke if args.stroke is None else (args.stroke[0] / 1e3,
                                                          args.stroke[1] / 1e3)
    speed = geometry.max_speed if args.speed is None else args.speed / 1e3
    lengths = None
    if args.lengths is not None:
        if len(args.lengths) not in (1, 6):
            raise BackendError(f"--lengths takes 1 or 6 values, got {len(args.lengths)}")
        lengths = tuple(np.broadcast_to(np.array(args.lengths) / 1e3, (6,)).tolist())
    board = BoardConfig(stroke=stroke, max_speed=speed, lengths=lengths, lag=args.lag,
                        watchdog=args.watchdog / 1e3,
                        identity=args.identity or f"hexapod-emulator 0.1.0 {geometry.name}")
    faults = FaultConfig(latency=args.latency / 1e3, jitter=args.jitter / 1e3,
                         drop_rate=args.drop, garble_rate=args.garble,
                         silent_after=args.silent_after, disconnect_after=args.disconnect_after,
                         seed=args.seed)
    return board, faults


def main(argv: Sequence[str] | None = None) -> int:
    """Console script ``hexapod-emulator``: serve a board until Ctrl-C or SIGTERM.

    Returns:
        The exit status (0 on a normal stop, 2 on a bad option).
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=args.log_level, stream=sys.stderr,
                        format="%(asctime)s %(name)s %(levelname)s: %(message)s")
    try:
        board, faults = config_from_args(args)
        if args.tcp is not None:
            emu = Emulator(board, faults, transport="tcp", host=args.tcp[0], port=args.tcp[1],
                           allow_remote=args.allow_remote, line_rate=args.line_rate)
        else:
            emu = Emulator(board, faults, transport="pty", line_rate=args.line_rate)
        emu.open()
    except (BackendError, OSError, ValueError) as exc:
        print(f"hexapod-emulator: error: {exc}", file=sys.stderr)
        return 2

    def _terminate(signum: int, frame: FrameType | None) -> None:
        emu._stop.set()
        with contextlib.suppress(OSError):
            os.write(emu._wake_w, b"x")

    signal.signal(signal.SIGTERM, _terminate)
    print(emu.url, flush=True)
    try:
        emu.serve_forever()
    except KeyboardInterrupt:
        pass
    finally:
        emu.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
