"""The real robot behind the :class:`~hexapod.backends.base.Backend` interface, over pyserial.

:class:`SerialRobot` speaks the protocol of :mod:`hexapod.backends.protocol`
(``docs/serial-protocol.md``) to a controller board through
``serial.serial_for_url``: a device path (``/dev/ttyUSB0``), a ``socket://`` URL or
the pseudo-terminal of the emulator (:mod:`hexapod.backends.emulator`). The same
code drives the emulator and a real board.

One :meth:`SerialRobot.step` is one control period: send ``MOV`` with the setpoints
``q + v dt`` (clamped to the stroke and speed limits), wait for the end of the period
(a :class:`~hexapod.backends.rate.RateLimiter`), read ``POS?``. Every reply is
checked; a garbled exchange (bad checksum, unparsable or unexpected reply, ``ERR 3``)
is retried a bounded number of times; a timeout, a disconnection or an unrecoverable
error halts the robot (``HLT``) when the link still works and raises a typed
:class:`~hexapod.exceptions.BackendError`. Leaving a ``with`` block, or Ctrl-C during
an exchange, halts the robot and closes the port.

The framed exchanges themselves (and the halts on the raw link) are
:class:`~hexapod.backends.serial_link.SerialLink`'s, a mixin of :class:`SerialRobot`.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from types import TracebackType
from typing import Any, TypeVar

import numpy as np
import serial  # pyserial (absolute import: this module is hexapod.backends.serial)

from hexapod.backends import protocol
from hexapod.backends.base import (
    Backend,
    BackendStep,
    check_reading,
    clamp_velocities,
    halt_on_open,
    step_command,
)
from hexapod.backends.rate import RateLimiter
from hexapod.backends.serial_link import SerialLink
from hexapod.exceptions import BackendError, ShapeError, StrokeLimitError
from hexapod.link_errors import (
    ImplausibleReadingError,
    ProtocolError,
    RobotFaultError,
    SerialDisconnectedError,
    SerialLinkError,
    WatchdogError,
)

logger = logging.getLogger(__name__)
#: Watchdog re-arms of one ``MOV`` at most (each after a lost reply's timeout or a stall).
REARMS_IN_A_ROW = 3

__all__ = ["SerialRobot"]

T = TypeVar("T")


class SerialRobot(SerialLink, Backend):
    """A robot controller board over a serial link (or the emulator).

    On open: ``*IDN?``, ``LIM?`` (stroke and speed limit), ``ERR?`` (clears a stale
    error), ``WDT``, ``SVO 0``, ``POS?``: the legs hold where they are and the board's
    watchdog is disarmed while the host prepares its first period (which may take longer
    than the watchdog period). ``SVO 1`` (which arms the watchdog) is sent just before
    the first ``MOV``.

    Args:
        url: Device path, ``socket://127.0.0.1:PORT`` or any pyserial URL.
        baudrate: Baud rate (115200 by the protocol).
        timeout: Time to wait for each reply [s].
        watchdog: Watchdog period to set on the board [s] (20 to 1000 ms).
        retries: How many times a garbled exchange is sent again before giving up.
        timeout_retries: How many times an exchange that timed out is sent again
            (0 by default: a silent device is an error).
        rearm_watchdog: When a MOV is refused because the watchdog tripped while the
            host was idle longer than the watchdog period (e.g. between :meth:`reset`
            and the first :meth:`step`), clear it with ``ERR?`` and send the MOV again
            (logged as a warning and counted: :attr:`watchdog_trips`,
            :attr:`watchdog_rearms`). If False, or if the host was not idle that long,
            raise :class:`WatchdogError`.
        reading_tolerance: How far [m] a reported leg length may lie outside the board's
            stroke, or off the way between the leg's previous reading and the setpoint
            it was sent, before it is refused as implausible
            (:class:`~hexapod.link_errors.ImplausibleReadingError`: the robot is halted
            and no setpoint is computed from it).
        on_close: Called once after the port is closed (e.g. to stop an emulator).

    Attributes:
        identity: The board's ``*IDN?`` text.
        stroke: (q_min, q_max) [m], from ``LIM?``.
        max_speed: Leg speed limit [m/s], from ``LIM?``.
        exchanges: Round-trip times of every successful exchange [s] (for statistics).
        watchdog_trips: ``MOV`` s refused because the board's watchdog had tripped.
        watchdog_rearms: Of those, the trips cleared with ``ERR?`` (the ``MOV`` sent again).
    """

    paces_periods = True  # (its RateLimiter keeps the period)

    def __init__(
        self,
        url: str,
        *,
        baudrate: int = protocol.BAUDRATE,
        timeout: float = 0.2,
        watchdog: float = 0.1,
        retries: int = 3,
        timeout_retries: int = 0,
        rearm_watchdog: bool = True,
        reading_tolerance: float = 1e-3,
        on_close: Callable[[], None] | None = None,
    ) -> None:
        ms = watchdog * 1e3
        if not protocol.WATCHDOG_MIN_MS <= round(ms) <= protocol.WATCHDOG_MAX_MS:
            raise BackendError(f"watchdog must be 20 to 1000 ms, got {ms:g} ms")
        if timeout <= 0 or retries < 0 or timeout_retries < 0:
            raise BackendError("timeout must be positive and retries >= 0")
        if not 0 < reading_tolerance < 0.1:
            raise BackendError(f"reading_tolerance must be in (0, 100) mm, got "
                               f"{reading_tolerance * 1e3:g} mm")
        self.reading_tolerance = float(reading_tolerance)
        self.url = url
        self.timeout = float(timeout)
        self.watchdog = round(ms) / 1e3
        self.retries = int(retries)
        self.timeout_retries = int(timeout_retries)
        self.rearm_watchdog = rearm_watchdog
        self._on_close = on_close
        self._buf = bytearray()
        self._rate: RateLimiter | None = None
        #: The emulator this robot started, if any (see
        #: :func:`~hexapod.backends.serial_emulated.open_emulated_robot`).
        self.emulator: Any = None
        self._last_mov = -np.inf
        self._closed = False
        self._halt_done = False  # a confirmed halt, nothing sent since: close() skips HLT
        self.exchanges: list[float] = []
        self.retried = 0
        self.watchdog_trips = 0
        self.watchdog_rearms = 0
        self._armed = False  # SVO 1 sent: the board's watchdog runs
        try:
            self._port = serial.serial_for_url(url, baudrate=baudrate, timeout=self.timeout,
                                               write_timeout=self.timeout)
        except (serial.SerialException, OSError, ValueError) as exc:
            self._closed = True
            if on_close is not None:
                on_close()
            raise SerialLinkError(url, f"cannot open the port: {exc}") from exc
        try:
            self._port.reset_input_buffer()
            self.identity = self._first_reply(baudrate)
            limits = protocol.parse_lim(self._exchange("LIM?"))
            self.stroke = limits.stroke
            self.max_speed = limits.max_speed
            code, text = self._read_error()
            if code == protocol.ErrorCode.HALTED:  # the last session's HLT: as expected
                logger.info("%s: cleared a pending error %d (%s)", url, code, text)
            elif code:  # a fault, a watchdog trip: the user is told (clearing is not fixing)
                logger.warning("%s: the board held error %d (%s) when the session "
                               "connected: cleared with ERR?; check the robot before it "
                               "moves", url, code, text)
            protocol.parse_ok(self._exchange(protocol.wdt(self.watchdog)), "WDT")
            # servo off until the first MOV: the watchdog cannot trip before it
            protocol.parse_ok(self._exchange("SVO 0"), "SVO 0")
            self._q = self._plausible(protocol.parse_pos(self._exchange("POS?")))
        except BaseException as exc:
            halted = self._try_halt()
            exc.halt_detail = halt_on_open(url, halted)  # type: ignore[attr-defined]
            self._shutdown(halt=False)
            raise
        logger.info("%s: connected to '%s', stroke [%.3f, %.3f] mm, %.3f mm/s", url,
                    self.identity, self.stroke[0] * 1e3, self.stroke[1] * 1e3,
                    self.max_speed * 1e3)

    # ------------------------------------------------------------------ link
    def _guarded(self, action: Callable[[], T]) -> T:
        """Run an exchange; on any failure halt the robot if the link allows, then raise.

        A disconnection closes the port; Ctrl-C halts and closes the port.
        """
        try:
            return action()
        except SerialDisconnectedError:
            self._shutdown(halt=False)
            raise
        except KeyboardInterrupt:
            self._shutdown(halt=True)
            raise
        except (SerialLinkError, ProtocolError, RobotFaultError, ImplausibleReadingError):
            self._try_halt()
            raise

    def command(self, payload: str) -> str:
        """Send any command (payload without checksum) and return the reply payload.

        For diagnostics and tests; a reply ``ERR`` is returned, not raised.
        """
        return self._guarded(lambda: self._exchange(payload))

    # ------------------------------------------------------------------ queries
    def status(self) -> protocol.Status:
        """The board's status (``STA?``)."""
        return self._guarded(lambda: self._checked("STA?", protocol.parse_sta))

    def _read_error(self) -> tuple[int, str]:
        # A garbled ERR? is answered "ERR 3 checksum" without clearing anything: the
        # board then holds error 3 (or the latched watchdog), so read once more.
        code, text = self._checked("ERR?", protocol.parse_err)
        for _ in range(self.retries):
            if code != protocol.ErrorCode.CHECKSUM:
                break
            code2, text2 = self._checked("ERR?", protocol.parse_err)
            if code2 == protocol.ErrorCode.NONE:
                break
            code, text = code2, text2
        return code, text

    def read_error(self) -> tuple[int, str]:
        """Read and clear the board's pending error (``ERR?``): (code, text)."""
        return self._guarded(self._read_error)

    def measured_lengths(self) -> np.ndarray:
        """Read the leg lengths (``POS?``) (6,) [m]."""
        self._q = self._guarded(lambda: self._plausible(
            self._checked("POS?", protocol.parse_pos)))
        return self._q.copy()

    def _plausible(self, q: np.ndarray, setpoints: np.ndarray | None = None) -> np.ndarray:
        """``q`` (6,) [m] read from the board, checked (:func:`~hexapod.backends.base.
        check_reading`): inside the board's stroke and, streaming (``setpoints``: those
        sent since the last reading), on the way from the last reading to them.

        Raises:
            ImplausibleReadingError: Naming the leg, its reading and where it could be.
        """
        return check_reading(self.url, q, self._q if setpoints is not None else None,
                             setpoints, self.stroke, self.reading_tolerance)

    def set_speed(self, speed: float) -> None:
        """Set the leg speed limit (``VEL``) [m/s]."""
        def go() -> float:
            self._checked(protocol.vel(speed), protocol.parse_ok)
            return self._checked("LIM?", protocol.parse_lim).max_speed

        self.max_speed = self._guarded(go)

    def _first_reply(self, baudrate: int) -> str:
        """The board's identity (``*IDN?``), the first exchange of a session: a link
        closed at once or a reply not of the protocol is said with its likely cause.

        Raises:
            SerialDisconnectedError: Closed at once (a TCP board busy with another client).
            ProtocolError: Not a reply of the protocol (another device, another baud rate).
        """
        url = self.url
        try:
            return protocol.parse_idn(self._exchange("*IDN?"))
        except SerialDisconnectedError as exc:  # closed at once: busy, over TCP
            if not url.startswith("socket://"):
                raise
            raise SerialDisconnectedError(url, f"{exc.problem} (a TCP board serves one "
                                          "client at a time: is another session connected "
                                          "to it?)", exc.command) from exc
        except ProtocolError as exc:  # the first reply is not of the protocol
            raise ProtocolError(exc.line, f"{url}: {exc.problem}: a device that does not "
                                f"speak this protocol, or at another baud rate than "
                                f"{baudrate} (serial:URL?baud=N)?", exc.command) from exc

    # ------------------------------------------------------------------ motion
    def _arm(self) -> None:
        """``SVO 1`` before the first ``MOV``: the legs hold where they are, and the
        board's watchdog starts now, one exchange before the ``MOV`` that feeds it."""
        if not self._armed:
            self._checked("SVO 1", protocol.parse_ok)
            self._armed = True
            self._last_mov = time.perf_counter()

    def _send_mov(self, setpoints: np.ndarray) -> None:
        """Send a ``MOV``; a refusal by the tripped watchdog after the host was idle for
        longer than its period (a stall, a lost reply's timeout) is cleared with ``ERR?``
        and the ``MOV`` sent again, as often as that holds, at most
        :data:`REARMS_IN_A_ROW` times for one ``MOV`` (a second lost reply in the same
        period ended the session)."""
        self._arm()
        payload = protocol.mov(setpoints)
        for rearm in range(REARMS_IN_A_ROW + 1):
            try:
                self._checked(payload, protocol.parse_ok)
                break
            except WatchdogError:
                self.watchdog_trips += 1
                idle = time.perf_counter() - self._last_mov
                if (not self.rearm_watchdog or idle <= self.watchdog
                        or rearm == REARMS_IN_A_ROW):
                    raise
                code, text = self._read_error()
                self.watchdog_rearms += 1
                logger.warning("%s: the board's watchdog tripped (no MOV for %.0f ms, more "
                               "than its %.0f ms; the legs held): cleared with ERR? (%d %s) "
                               "and the MOV sent again (trip %d)", self.url, idle * 1e3,
                               self.watchdog * 1e3, code, text, self.watchdog_trips)
        self._last_mov = time.perf_counter()

    def _check_lengths(self, lengths: np.ndarray) -> np.ndarray:
        q = np.asarray(lengths, dtype=float)
        if q.shape != (6,) or not np.all(np.isfinite(q)):
            raise ShapeError("lengths", "6 finite leg lengths [m]", q)
        for i, x in enumerate(q):
            if not self.stroke[0] - 1e-9 <= x <= self.stroke[1] + 1e-9:
                raise StrokeLimitError(i, float(x), *self.stroke)
        return np.clip(q, *self.stroke)

    def move(self, lengths: np.ndarray, wait: bool = True, tolerance: float = 2e-6,
             timeout: float | None = None) -> np.ndarray:
        """Move to absolute leg lengths [m] and (if ``wait``) until the legs stop.

        While waiting, the MOV is sent again at a fraction of the watchdog period, so
        the watchdog does not trip.

        Args:
            lengths: (6,) setpoints [m], inside the stroke.
            wait: Wait until the board reports ``moving=0``.
            tolerance: Largest accepted distance to the setpoint at the end [m].
            timeout: Longest wait [s] (default: the longest leg travel at the speed
                limit, times 2, plus 1 s).

        Returns:
            The measured lengths [m].
        """
        target = self._check_lengths(lengths)

        def go() -> np.ndarray:
            if not self._checked("STA?", protocol.parse_sta).servo:
                self._armed = False  # (off: SVO 0 sent) the MOV's SVO 1, once
            self._send_mov(target)
            if not wait:
                return self._q.copy()
            q = self._checked("POS?", protocol.parse_pos)
            limit = timeout if timeout is not None else (
                2.0 * float(np.max(np.abs(target - q))) / self.max_speed + 1.0)
            deadline = time.perf_counter() + limit
            poll = min(0.02, self.watchdog / 3)
            while True:
                st = self._checked("STA?", protocol.parse_sta)
                q = self._checked("POS?", protocol.parse_pos)
                if not st.moving:
                    break
                if time.perf_counter() > deadline:
                    raise BackendError(f"{self.url}: the legs did not reach their setpoints "
                                       f"within {limit:.1f} s (at {np.round(q * 1e3, 3)} mm)")
                time.sleep(poll)
                self._send_mov(target)  # keep the watchdog fed
            if np.max(np.abs(q - target)) > tolerance:
                raise BackendError(f"{self.url}: legs stopped at {np.round(q * 1e3, 3)} mm, "
                                   f"away from {np.round(target * 1e3, 3)} mm")
            return q

        self._q = self._guarded(go)
        self._rate = None
        return self._q.copy()

    def reset(self, lengths: np.ndarray | None = None) -> np.ndarray:
        """Clear a pending error, move to ``lengths`` [m] (if given), return the measured lengths.

        Raises:
            StrokeLimitError: A length is outside the stroke (nothing is sent).
        """
        if lengths is not None:
            self._check_lengths(lengths)
        code, text = self.read_error()
        if code:
            logger.info("%s: reset cleared error %d (%s)", self.url, code, text)
        self._rate = None
        if lengths is None:
            return self.measured_lengths()
        return self.move(lengths)

    def step(self, velocities: np.ndarray, dt: float) -> BackendStep:
        """One control period: MOV to ``q + v dt`` (clamped), wait for the period, POS?.

        The period is kept by a :class:`RateLimiter` across calls: call ``step`` again
        within ``dt`` of its return to keep the rate.

        Args:
            velocities: (6,) leg velocities [m/s].
            dt: Control period [s].

        Returns:
            The measured lengths at the end of the period, the applied velocities, the
            clamped legs, the time spent communicating (``round_trip_s``) and whether the
            period was missed. ``extras``: ``mov_rtt_s``, ``pos_rtt_s``, ``slack_s``,
            ``retries``.
        """
        v = step_command(velocities, dt)
        rate = self._rate = RateLimiter.keeping(self._rate, dt, f"SerialRobot({self.url})")
        q = self._q
        vc, clamped = clamp_velocities(q, v, dt, self.stroke, self.max_speed)
        setpoints = np.clip(q + vc * dt, *self.stroke)
        retried = self.retried

        def period() -> tuple[float, float, float]:
            t0 = time.perf_counter()
            self._send_mov(setpoints)
            t1 = time.perf_counter()
            slack = rate.sleep_after(t0)  # the first period starts with its MOV
            t2 = time.perf_counter()
            self._q = self._plausible(self._checked("POS?", protocol.parse_pos), setpoints)
            return t1 - t0, time.perf_counter() - t2, slack

        mov_rtt, pos_rtt, slack = self._guarded(period)
        return BackendStep(
            lengths=self._q.copy(),
            applied_velocities=vc,
            clamped=clamped,
            round_trip_s=mov_rtt + pos_rtt,
            missed_period=slack < 0,
            extras={"mov_rtt_s": mov_rtt, "pos_rtt_s": pos_rtt, "slack_s": slack,
                    "retries": float(self.retried - retried)},
        )

    # ------------------------------------------------------------------ stopping
    def halt(self) -> None:
        """Stop every leg where it is (``HLT``); never raises if the link is dead."""
        if not self._try_halt() and not self._closed:
            logger.warning("%s: HLT not acknowledged", self.url)

    def _shutdown(self, halt: bool) -> None:
        if halt and not self._halt_done:  # a confirmed halt is not sent again
            self._try_halt()
        if self._closed:
            return
        self._closed = True
        try:
            self._port.close()
        except (serial.SerialException, OSError) as exc:
            logger.warning("%s: close failed: %s", self.url, exc)
        if self._on_close is not None:
            self._on_close()

    def close(self) -> None:
        """Halt the robot (if the link works) and close the port. Idempotent."""
        self._shutdown(halt=True)

    def __enter__(self) -> SerialRobot:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self._shutdown(halt=True)

    def stats(self) -> dict[str, Any]:
        """Round-trip statistics of the exchanges so far: count, median and p99 [s]."""
        rtt = np.array(self.exchanges)
        if rtt.size == 0:
            return {"exchanges": 0}
        return {"exchanges": int(rtt.size), "median_s": float(np.median(rtt)),
                "p99_s": float(np.percentile(rtt, 99)), "max_s": float(rtt.max()),
                "retries": self.retried, "watchdog_trips": self.watchdog_trips,
                "watchdog_rearms": self.watchdog_rearms}
