"""The link layer of :class:`~hexapod.backends.serial.SerialRobot`: framed exchanges.

:class:`SerialLink` holds what talks to the port itself: writing a framed command,
reading one reply line before a deadline, the checked exchange with its bounded
retries (a garbled exchange, an unexpected reply) and the two halts that work on the
raw link (``HLT`` once, and ``HLT`` with ``ERR?`` until the board confirms). The
robot (:mod:`hexapod.backends.serial`) opens the port, keeps the state these methods
use and builds the queries and the motion on them.
"""

from __future__ import annotations

import logging
import termios
import time
from collections.abc import Callable
from typing import Any, TypeVar

import serial  # pyserial

from hexapod.backends import protocol
from hexapod.backends.base import HaltClock, HaltReport, write_failed
from hexapod.exceptions import BackendError
from hexapod.link_errors import (
    CommandRejectedError,
    ProtocolError,
    RobotFaultError,
    SerialDisconnectedError,
    SerialLinkError,
    SerialTimeoutError,
)

# the robot's logger: the link's warnings are logged as they were before the split
logger = logging.getLogger("hexapod.backends.serial")

__all__ = ["SerialLink"]

T = TypeVar("T")


class SerialLink:
    """Framed, checked exchanges over an open pyserial port (a mixin of
    :class:`~hexapod.backends.serial.SerialRobot`, which sets the attributes below)."""

    url: str
    timeout: float
    retries: int
    timeout_retries: int
    exchanges: list[float]
    retried: int
    _port: Any
    _buf: bytearray
    _closed: bool
    _halt_done: bool

    # ------------------------------------------------------------------ link
    @property
    def is_open(self) -> bool:
        """The port is open."""
        return not self._closed

    def _write(self, payload: str, line: bytes | None = None) -> None:
        try:
            self._port.write(protocol.frame(payload) if line is None else line)
        except serial.SerialTimeoutException as exc:
            raise SerialTimeoutError(self.url, payload, self.timeout) from exc
        except (serial.SerialException, OSError) as exc:
            raise SerialDisconnectedError(self.url, write_failed(exc), payload) from exc

    def _read_line(self, command: str, deadline: float) -> bytes:
        """Read one line (up to ``\\n``) before ``deadline`` (perf_counter time) [s]."""
        while True:
            nl = self._buf.find(b"\n")
            if nl >= protocol.MAX_LINE:  # a line longer than the protocol's, arrived whole
                line = bytes(self._buf[: nl + 1])
                del self._buf[: nl + 1]
                raise ProtocolError(line, "line too long", command)
            if nl >= 0:
                line = bytes(self._buf[: nl + 1])
                del self._buf[: nl + 1]
                return line
            if len(self._buf) > protocol.MAX_LINE:
                junk = bytes(self._buf)
                self._buf.clear()
                raise ProtocolError(junk, "line too long", command)
            if time.perf_counter() >= deadline:
                got = bytes(self._buf)
                self._buf.clear()
                raise SerialTimeoutError(self.url, command, self.timeout, got)
            try:
                chunk = self._port.read(max(1, self._port.in_waiting))
            except (serial.SerialException, OSError) as exc:
                text = str(exc)  # pyserial's socket:// already says "read failed: ..."
                problem = text if text.startswith("read failed") else f"read failed: {text}"
                raise SerialDisconnectedError(self.url, problem, command) from exc
            self._buf += chunk

    def _flush_input(self) -> None:
        self._buf.clear()
        try:
            self._port.reset_input_buffer()
        except (serial.SerialException, OSError, termios.error) as exc:
            # (termios.error, no OSError: tcflush on a terminal whose other side is gone)
            raise SerialDisconnectedError(self.url, f"flush failed: {exc}") from exc

    def _exchange(self, payload: str) -> str:
        """Send one command and return the checked payload of its reply.

        Retries on a garbled exchange (bad checksum, ``ERR 3``, a reply that is not
        printable ASCII or does not answer this command: see :meth:`_checked`).
        """
        if self._closed:
            raise SerialLinkError(self.url, "the port is closed", payload)
        self._halt_done = False
        framed = protocol.frame(payload)
        garbled = timeouts = 0
        while True:
            t0 = time.perf_counter()
            try:
                self._write(payload, framed)
                line = self._read_line(payload, t0 + self.timeout)
                reply = protocol.unframe(line, payload)
                if reply.startswith("ERR 3 ") and not payload.startswith("ERR?"):
                    # our command was garbled on the way: it had no effect, send it again
                    raise protocol.fault(*protocol.parse_err(reply, payload), payload)
                self.exchanges.append(time.perf_counter() - t0)
                return reply
            except (ProtocolError, CommandRejectedError) as exc:
                garbled += 1
                if garbled > self.retries:
                    raise
                logger.warning("%s: garbled exchange (%s), retry %d/%d", self.url, exc,
                               garbled, self.retries)
            except SerialTimeoutError as exc:
                timeouts += 1
                if timeouts > self.timeout_retries:
                    raise
                logger.warning("%s, retry %d/%d", exc, timeouts,
                               self.timeout_retries)
            self.retried += 1
            self._flush_input()

    def _checked(self, payload: str, parse: Callable[[str, str], T]) -> T:
        """Exchange and parse, retrying when the reply is well framed but unexpected
        (a stale or corrupted line that passed the checksum)."""
        attempts = 0
        while True:
            reply = self._exchange(payload)
            try:
                return parse(reply, payload)
            except RobotFaultError:
                raise
            except ProtocolError as exc:
                attempts += 1
                if attempts > self.retries:
                    raise
                logger.warning("%s: unexpected reply (%s), retry %d/%d", self.url, exc,
                               attempts, self.retries)
                self.retried += 1
                self._flush_input()

    # ------------------------------------------------------------------ stopping
    def _try_halt(self) -> bool | None:
        """Send HLT once, ignoring a stale reply; True if the board acknowledged it, False
        if it was sent but not acknowledged, None if it could not be written."""
        if self._closed:
            return None
        try:
            self._flush_input()
            self._write("HLT")
        except (SerialLinkError, ProtocolError) as exc:
            logger.warning("%s: HLT could not be sent (%s)", self.url, exc)
            return None
        try:
            deadline = time.perf_counter() + self.timeout
            for _ in range(4):
                try:
                    if protocol.unframe(self._read_line("HLT", deadline), "HLT") == "OK":
                        return True
                except ProtocolError:
                    continue
        except (SerialLinkError, ProtocolError) as exc:
            logger.warning("%s: HLT sent, not acknowledged within %.1f s (%s)", self.url,
                           self.timeout, exc)
        return False

    def halt_confirmed(self, timeout_s: float = 2.0) -> HaltReport:
        """Send ``HLT`` with ``ERR?`` and wait up to ``timeout_s`` [s] for the board to
        confirm: ``ERR?`` answering error 10 (halted by command) or 20 (its watchdog,
        reported first when latched, stopped the legs itself), then ``STA?`` reporting no
        leg moving; another code read on the way (a drive fault, one the protocol does not
        define) is named in the report, and the pair is sent again. Never raises.

        Replies still on their way (after a stall, those of the commands queued before
        the ``HLT``) are read and skipped, never flushed away while waiting; the pair is
        sent again every ``timeout`` [s] until confirmed (``HLT`` is idempotent), so a
        dropped reply or a latched watchdog error does not hide the halt, and an ``HLT``
        queued during a stall is confirmed as soon as the board answers again.

        Args:
            timeout_s: Longest wait [s].

        Returns:
            Confirmed when the board read back error 10 and then no leg moving.
        """
        clock = HaltClock(timeout_s)
        t0, deadline, report = clock.t0, clock.deadline, clock.report
        if self._closed:
            return clock.closed(self.url)
        sent = 0
        faults: list[str] = []  # other errors read back on the way (a drive fault)
        try:
            self._flush_input()
            halted = False
            read_back = ""
            resend = t0
            while not halted:
                now = time.perf_counter()
                if now >= deadline:
                    return report(False, f"{self.url}: HLT sent {sent} time(s), not confirmed "
                                         f"by ERR? (error 10) within {timeout_s:g} s")
                if now >= resend:
                    self._write("HLT")
                    self._write("ERR?")
                    sent += 1
                    resend = now + self.timeout
                try:
                    line = self._read_line("HLT", min(deadline, resend))
                    payload = protocol.unframe(line, "ERR?")
                except (SerialTimeoutError, ProtocolError):
                    continue
                if payload.startswith("ERR "):
                    code, said = protocol.parse_err(payload, "ERR?")
                    # 10: our HLT; 20: the watchdog (latched first) stopped the legs itself;
                    # any other (a drive fault, a code the protocol does not define: read
                    # and cleared by this ERR?): HLT and ERR? again
                    halted = code in (protocol.ErrorCode.HALTED, protocol.ErrorCode.WATCHDOG)
                    if not halted and code != protocol.ErrorCode.NONE:
                        faults.append(f"{code} {said}".strip())
                    read_back = f"ERR? {code} {said}".strip()
                    if faults and halted:
                        read_back += f" (after {', '.join(faults)})"
            moving = False
            ask = time.perf_counter()
            while True:  # the board took the HLT: are the legs still?
                now = time.perf_counter()
                if now >= deadline:
                    why = "the legs still moving" if moving else "STA? unanswered"
                    return report(False, f"{self.url}: HLT sent, {read_back}, but {why} "
                                         f"after {timeout_s:g} s")
                if now >= ask:
                    self._write("STA?")
                    ask = now + self.timeout
                try:
                    st = protocol.parse_sta(protocol.unframe(
                        self._read_line("STA?", min(deadline, ask)), "STA?"))
                except (SerialTimeoutError, ProtocolError, RobotFaultError):
                    continue  # a stale reply (an earlier ERR?'s), or none yet
                if not st.moving:
                    self._halt_done = True
                    return report(True, f"{self.url}: HLT sent, {read_back}, STA? moving=0")
                moving = True
                time.sleep(0.005)
                ask = time.perf_counter()
        except SerialLinkError as exc:
            return report(False, f"{self.url}: the link failed while halting: {exc}")
        except BackendError as exc:  # never raises: the caller is shutting down
            return report(False, f"{self.url}: halting failed: {exc}")
