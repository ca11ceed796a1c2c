"""A generic line-oriented device server on a pseudo-terminal or a loopback TCP port.

:class:`EmulatorServer` serves any emulated device (:class:`EmulatedDevice`: an object
with ``handle_line(line, now) -> reply``, ``advance(now)``, ``frame(reply) -> bytes``,
``next_event()``, ``overlong_line()`` and its line ``terminator``) on a real
pseudo-terminal (``.device`` is the slave path that pyserial opens) or on a loopback TCP
port (``socket://127.0.0.1:PORT``), in a thread (``start()``/``stop()``) or in the
foreground (``serve_forever()``), and injects seeded faults on demand
(:class:`~hexapod.backends.emulator_faults.FaultConfig`, re-exported here): latency,
dropped replies, garbled bytes, a silent device, a disconnection. A reply that frames
to no bytes (a set command of a protocol that answers only queries, like PI's GCS)
sends nothing.

:class:`~hexapod.backends.emulator_board.Emulator` is the server of the project's own
controller board (:class:`~hexapod.backends.emulator_board.Board`);
:class:`~hexapod.backends.gcs_emulator.GcsEmulator` serves an emulated PI GCS hexapod
controller with the same machinery.
"""

from __future__ import annotations

import contextlib
import ipaddress
import logging
import math
import os
import random
import select
import socket
import threading
import time
import tty
from collections import deque
from dataclasses import dataclass
from types import TracebackType
from typing import ClassVar, Generic, Protocol, Self, TypeVar

from hexapod.backends.emulator_faults import FaultConfig, FaultState, garble
from hexapod.exceptions import BackendError

logger = logging.getLogger(__name__)

__all__ = ["DISCONNECT_GRACE", "EmulatedDevice", "EmulatorServer", "FaultConfig"]

#: Time left to the host to read the last reply before a disconnection fault [s].
DISCONNECT_GRACE = 0.02


class EmulatedDevice(Protocol):
    """What :class:`EmulatorServer` serves: a line-oriented device driven by a clock.

    Every method takes the current time ``now`` [s] of a monotonic clock.
    """

    #: The byte sequence that ends every received line.
    terminator: ClassVar[bytes]
    #: Longest line accepted before the terminator [bytes].
    max_line: ClassVar[int]

    def handle_line(self, line: bytes, now: float) -> str:
        """Act on one received line (terminator included) and return the reply payload."""
        ...

    def advance(self, now: float) -> None:
        """Advance the device's state (motion, timers) to ``now`` [s]."""
        ...

    def frame(self, reply: str) -> bytes:
        """The bytes of a reply payload on the wire (b"" sends nothing)."""
        ...

    def next_event(self) -> float | None:
        """When the device must be advanced without a command [s] (None: no such time)."""
        ...

    def overlong_line(self) -> str:
        """The reply to a line longer than :attr:`max_line` (the line is discarded)."""
        ...


D = TypeVar("D", bound=EmulatedDevice)


@dataclass
class _Reply:
    due: float
    data: bytes


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


class EmulatorServer(Generic[D]):
    """An emulated device served on a pseudo-terminal or a loopback TCP port.

    Args:
        board: The device to serve (an :class:`EmulatedDevice`).
        faults: Faults to inject (none if None).
        transport: ``"pty"`` or ``"tcp"``.
        host: TCP address to listen on (loopback only unless ``allow_remote``).
        port: TCP port (0: any free port, see :attr:`url`).
        allow_remote: Allow a non-loopback ``host``.
        line_rate: If positive, emulate the transmission time of the lines at this baud
            rate (10 bits a byte): each reply is delayed by the time it takes the command
            and the reply to cross the link [baud]. 0: instantaneous.
    """

    def __init__(
        self,
        board: D,
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
        #: The served device.
        self.board = board
        self.transport = transport
        self.line_rate = float(line_rate)
        self._host, self._port = host, port
        self._lock = threading.RLock()
        self._faults = FaultState()
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
        #: Whether the rest of a line that overflowed the buffer is being discarded.
        self._discarding = False
        self._opened = False
        self._closed = False
        #: Connections closed by the ``disconnect_after`` fault.
        self.disconnections = 0
        #: Connections accepted (TCP) so far.
        self.connections = 0
        self.device = ""
        self.url = ""

    # ---------------------------------------------------------------- API
    def set_faults(self, faults: FaultConfig) -> None:
        """Inject other faults from now on (re-seeds the generator, restarts the counts)."""
        with self._lock:
            self._faults = FaultState(faults, random.Random(faults.seed))

    @property
    def faults(self) -> FaultConfig:
        """The faults being injected."""
        return self._faults.config

    def open(self) -> Self:
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
            self.device = f"{host}:{port}" if family == socket.AF_INET else f"[{host}]:{port}"
        self.url = self.client_url()
        self._opened = True
        logger.info("emulator serving on %s", self.url)
        return self

    def client_url(self) -> str:
        """The address a client opens (printed by ``hexapod-emulator`` and logged): the
        pty's path, or ``socket://HOST:PORT`` (a device whose clients name it otherwise
        overrides this)."""
        return self.device if self.transport == "pty" else f"socket://{self.device}"

    def start(self) -> Self:
        """Open (if needed) and serve in a daemon thread; returns self."""
        self.open()
        if self._thread is None:
            self._thread = threading.Thread(target=self.serve_forever, name="hexapod-emulator",
                                            daemon=True)
            self._thread.start()
        return self

    def request_stop(self) -> None:
        """Ask the serving loop to end (safe in a signal handler: no join, no close)."""
        self._stop.set()
        with contextlib.suppress(OSError):
            os.write(self._wake_w, b"x")

    def stop(self, timeout: float = 2.0) -> None:
        """Stop serving, join the thread and close every file descriptor."""
        self.request_stop()
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

    def __enter__(self) -> Self:
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
            trip = self.board.next_event()
        timeout = 0.05
        if self._faults.disconnect_pending:
            timeout = 0.005
        if self._replies:
            timeout = min(timeout, self._replies[0].due - now)
        if trip is not None:
            timeout = min(timeout, trip - now)
        stalled = self._faults.stall_until > now
        if stalled:  # frozen: nothing read, executed or sent until the stall ends
            timeout = self._faults.stall_until - now
        fds: list[int] = [self._wake_r]
        conn = None if stalled else self._conn_fd()
        if conn is not None:
            fds.append(conn)
        if self._listener is not None:  # a second client is refused, not left hanging
            fds.append(self._listener.fileno())
        ready, _, _ = select.select(fds, [], [], max(timeout, 0.0))
        if self._wake_r in ready:
            with contextlib.suppress(OSError):
                os.read(self._wake_r, 64)
        if self._listener is not None and self._listener.fileno() in ready:
            self._accept(self._listener)
        if conn is not None and conn in ready:
            data = self._read(conn)
            if data is None:
                return self._drop_connection("peer closed the connection")
            self._inbuf += data
        if stalled and self._faults.stall_until <= time.monotonic():
            logger.info("emulator: stall over (fault injection), %d bytes waiting",
                        len(self._inbuf))
        if self._faults.stall_until <= time.monotonic():
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

    def _accept(self, listener: socket.socket) -> None:
        """Take a new TCP client, or refuse it (closed at once) while one is served: the
        second client reads end-of-file, never a hanging connection."""
        client, addr = listener.accept()
        if self._client is not None:
            logger.info("emulator: refused a connection from %s (busy: one client at a "
                        "time)", addr)
            with contextlib.suppress(OSError):
                client.close()
            return
        client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        client.setblocking(False)
        self._client = client
        self._inbuf.clear()
        self._discarding = False
        self.connections += 1
        logger.info("emulator: connection from %s", addr)

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
        self._discarding = False
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
        """Serve the whole lines received. A line longer than the board's
        :attr:`Board.max_line` is discarded whole and answered as the board answers one
        (the rest of a line that filled the buffer too, up to its terminator: none of it
        is a command), with the faults of any other command."""
        term = self.board.terminator
        while self._faults.stall_until <= time.monotonic():
            end = self._inbuf.find(term)
            if end < 0:
                if len(self._inbuf) > self.board.max_line:
                    self._inbuf.clear()
                    if not self._discarding:
                        self._discarding = True
                        self._command(b"", overlong=True)
                return
            line = bytes(self._inbuf[: end + len(term)])
            del self._inbuf[: end + len(term)]
            if self._discarding:  # the end of a line already answered
                self._discarding = False
            else:
                self._command(line, overlong=end + len(term) > self.board.max_line)

    def _command(self, line: bytes, overlong: bool = False) -> None:
        fs = self._faults
        f = fs.config
        if fs.disconnect_pending:
            return  # the cable is being pulled
        if f.garble_rate and fs.rng.random() < f.garble_rate and not overlong:
            line = garble(line, fs.rng, self.board.terminator)
        with self._lock:
            self._inject(fs.commands + 1)
            reply = (self.board.overlong_line() if overlong
                     else self.board.handle_line(line, time.monotonic()))
        fs.commands += 1
        data = self.board.frame(reply)
        logger.debug("emulator: received %r, answers %r", line, data)
        if data:  # a command with a reply (GCS answers only queries)
            if f.silent_after is not None and fs.commands > f.silent_after:
                return
            if f.drop_rate and fs.rng.random() < f.drop_rate:
                logger.debug("emulator: dropping the reply %r", data)
                return
            if f.garble_rate and fs.rng.random() < f.garble_rate:
                data = garble(data, fs.rng, self.board.terminator)
            self._queue(data, max(len(line), self.board.max_line if overlong else 0))
        if f.disconnect_after is not None and fs.commands >= f.disconnect_after:
            fs.disconnect_pending = True
        if f.stall_after is not None and fs.commands == f.stall_after:
            fs.stall_until = time.monotonic() + f.stall_s
            logger.info("emulator: stalling for %.0f ms (fault injection)", f.stall_s * 1e3)

    def _inject(self, command: int) -> None:
        """Set the board's faults that start at this command (1 for the first): a glitching
        position reading, a latched drive fault (boards that have them)."""
        f = self._faults.config
        # the glitch starts after N commands (with command N + 1), the drive fault at N
        starts = ((None if f.glitch_after is None else f.glitch_after + 1, "glitch", f.glitch),
                  (f.drive_fault_after, "drive_fault", f.drive_fault_code))
        for start, name, value in starts:
            if command == start:
                inject = getattr(self.board, f"inject_{name}", None)
                if inject is None:
                    logger.warning("emulator: this device has no %s fault", name)
                else:
                    inject(value)
                    logger.info("emulator: %s %r from command %d (fault injection)", name,
                                value, command)

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
