"""A commercial hexapod whose controller speaks PI's GCS (C-887 family), as a backend.

Such a controller never takes a leg length: it is commanded in Cartesian coordinates
(X, Y, Z [mm], U, V, W [deg] about its pivot point, :mod:`hexapod.backends.gcs_pose`)
and realises them with its own kinematic model. :class:`GcsHexapod` turns the
controllers' leg velocities into that language, period by period:

1. the commanded leg velocities, clamped to the stroke and the speed limit
   (:func:`~hexapod.backends.base.clamp_velocities`), are integrated from the measured
   lengths to target lengths;
2. the NOMINAL model's forward kinematics (warm-started from the last measured pose)
   gives the target pose, sent as one ``MOV X .. Y .. Z .. U .. V .. W ..`` followed by
   ``ERR?`` (pipelined: one round trip). Near the edge of the workspace (a target leg
   within ``vmo_margin`` of a stroke end) ``VMO?`` asks first whether the controller's
   own model can reach it; if not, the robot holds (every leg reported clamped);
3. at the end of the period ``POS?`` (and ``ERR?``) gives the measured pose, turned into
   leg lengths with the nominal inverse kinematics: that is what the controllers see.

At connect: ``*IDN?``, ``ERR?`` (a stale error is cleared), ``SPI?`` (or ``SPI`` when a
pivot point is configured), ``VLS`` (the platform velocity that lets the legs reach
their speed limit, see :func:`platform_velocity`), ``POS?``. A controller error, a
timeout, a closed connection or an unexpected answer raises a typed exception
(:mod:`hexapod.exceptions`: ``GcsControllerError``, ``GcsTimeoutError``,
``GcsDisconnectedError``, ``GcsReplyError``) after ``HLT`` when the link still works;
Ctrl-C during an exchange, :meth:`GcsHexapod.close` and leaving a ``with`` block halt the
robot. PI's own client library is not used: the GCS subset is spoken by
:mod:`hexapod.backends.gcs_protocol`.
"""

from __future__ import annotations

import logging
import math
import time
from collections import deque
from collections.abc import Callable
from typing import Any, TypeVar

import numpy as np

from hexapod.backends import gcs_protocol as gp
from hexapod.backends.base import (
    Backend,
    BackendStep,
    HaltClock,
    HaltReport,
    check_reading,
    clamp_velocities,
    halt_on_open,
    started,
    step_command,
)
from hexapod.backends.gcs_config import GcsOptions, platform_velocity
from hexapod.backends.gcs_link import Transport, open_transport
from hexapod.backends.gcs_pose import PoseConvention, from_wire, to_wire
from hexapod.backends.rate import RateLimiter
from hexapod.exceptions import BackendError, BackendPluginError, ShapeError, StrokeLimitError
from hexapod.fk import forward_kinematics
from hexapod.geometry import HexapodGeometry
from hexapod.kinematics import inverse_kinematics
from hexapod.link_errors import (
    GcsControllerError,
    GcsDisconnectedError,
    GcsLinkError,
    GcsReplyError,
    GcsTimeoutError,
)

logger = logging.getLogger(__name__)

#: How far [m] a leg of the reported pose may lie off the way between its last reading and
#: the target sent (the controller's own path between two poses bends the legs' by far
#: less) before the reading is refused (:func:`~hexapod.backends.base.check_reading`).
READING_TOLERANCE = 1e-3

__all__ = ["GcsHexapod", "GcsOptions", "platform_velocity"]

T = TypeVar("T")


class GcsHexapod(Backend):
    """A hexapod behind a PI GCS controller, over TCP or a serial link.

    Args:
        url: ``tcp://HOST:PORT`` or ``serial:URL`` (a pyserial URL: ``/dev/ttyUSB0``,
            a pty, ``socket://...``).
        geometry: The NOMINAL robot: forward and inverse kinematics, stroke, speed limit.
        options: How to talk to the controller.
        on_close: Called once after the link is closed (e.g. to stop an emulator).

    Attributes:
        identity: The controller's ``*IDN?`` answer.
        velocity: The system velocity set (``VLS``) [m/s].
        exchanges: Round-trip times of the last 100 000 exchanges [s].
        vmo_checks: ``VMO?`` asked; ``vmo_refusals``: answered 0 (the robot held).
    """

    paces_periods = True  # (its RateLimiter keeps the period)

    def __init__(self, url: str, geometry: HexapodGeometry,
                 options: GcsOptions | None = None,
                 on_close: Callable[[], None] | None = None) -> None:
        self.url = url
        self.geometry = geometry
        self.options = options or GcsOptions()
        self.stroke = geometry.stroke
        self.max_speed = geometry.max_speed
        self.timeout = self.options.timeout
        self._on_close = on_close
        self._closed = False
        self._halt_done = False  # a confirmed halt, nothing sent since: close() skips HLT
        self._rate: RateLimiter | None = None
        self.exchanges: deque[float] = deque(maxlen=100_000)
        self.vmo_checks = self.vmo_refusals = 0
        #: The last exchanges' text (``>`` sent, ``<`` received), for a transcript.
        self.transcript: list[str] | None = None
        self.emulator: Any = None
        self.convention = PoseConvention.for_geometry(
            geometry, None, self.options.rotation_order, self.options.zero_height)
        try:
            self._link: Transport = open_transport(url, self.timeout, self.options.baudrate)
        except GcsLinkError:
            self._closed = True
            if on_close is not None:
                on_close()
            raise
        try:
            self._connect()
        except GcsDisconnectedError:
            # closed before or while answering (busy with another client, refused): the
            # link is gone, an HLT could not be sent (it would only fail on a broken pipe)
            self._shutdown(halt=False)
            raise
        except BaseException as exc:
            halted = self._try_halt()
            exc.halt_detail = halt_on_open(url, halted)  # type: ignore[attr-defined]
            self._shutdown(halt=False)
            raise
        logger.info("%s: connected to '%s', VLS %.1f mm/s", url, self.identity,
                    self.velocity * 1e3)

    def _connect(self) -> None:
        try:
            self.identity = self._query_text("*IDN?")
        except GcsDisconnectedError as exc:
            raise GcsDisconnectedError(
                self.url, "the controller closed the connection before answering *IDN?: it "
                "is busy with another client (a PI controller serves one TCP client at a "
                "time: close PIMikroMove or the other program) or refused the connection"
            ) from exc
        except GcsTimeoutError as exc:
            raise GcsTimeoutError(self.url, "*IDN?", exc.timeout, exc.received) from exc
        code = gp.parse_int_answer(self._exchange("ERR?", 1)[0], "ERR?")
        if code:
            logger.info("%s: cleared a pending error %d (%s)", self.url, code,
                        gp.error_text(code))
        if self.options.pivot is not None:
            pivot = np.asarray(self.options.pivot)
            self._set(gp.command("SPI", dict(zip(gp.PIVOT_AXES, (pivot * 1e3).tolist(),
                                                 strict=True))))
        values = self._query_axes("SPI?", gp.PIVOT_AXES)
        self.convention = self.convention.with_pivot(
            np.array([values[a] for a in gp.PIVOT_AXES]) * 1e-3)
        self._read_pose()
        self.velocity = self.options.velocity or math.ceil(
            platform_velocity(self.geometry, self.convention, self._coords) * 1e3) / 1e3
        try:
            self._set(f"VLS {gp.format_number(self.velocity * 1e3)}")
        except GcsControllerError as exc:
            self.velocity = gp.parse_float_answer(self._exchange("VLS?", 1)[0]) * 1e-3
            logger.warning("%s: VLS refused (%s); the controller keeps %.1f mm/s and the "
                           "platform may lag the commands", self.url, exc, self.velocity * 1e3)

    # ------------------------------------------------------------------ exchanges
    def _exchange(self, text: str, answers: int) -> list[bytes]:
        """Send one or more pipelined lines (``text`` joined by LF) and read ``answers``."""
        if self._closed:
            raise GcsDisconnectedError(self.url, "the link is closed", text)
        t0 = time.perf_counter()
        self._halt_done = False
        self._link.write(gp.encode(*text.split("\n")), text)
        if self.transcript is not None:
            self.transcript += [f"> {ln}" for ln in text.split("\n")]
        out = [self._read(text, t0 + self.timeout) for _ in range(answers)]
        self.exchanges.append(time.perf_counter() - t0)
        return out

    def _read(self, command: str, deadline: float | None = None) -> bytes:
        answer = self._link.read_answer(
            command, time.perf_counter() + self.timeout if deadline is None else deadline)
        if self.transcript is not None:
            self.transcript += [f"< {ln}" for ln in gp.answer_lines(answer)]
        return answer

    def _check(self, answer: bytes, command: str) -> None:
        code = gp.parse_int_answer(answer, "ERR?")
        if code:
            raise gp.controller_error(code, command, self.url)

    def _set(self, command: str) -> None:
        """A set command and its ``ERR?``, pipelined (one round trip)."""
        self._check(self._exchange(f"{command}\nERR?", 1)[0], command)

    def _query_axes(self, command: str, axes: tuple[str, ...]) -> dict[str, float]:
        """A query answered ``AXIS=VALUE`` per axis, and its ``ERR?`` (one round trip)."""
        first = self._exchange(f"{command}\nERR?", 1)[0]
        if b"=" not in first:  # the query was refused: this is ERR?'s answer
            self._check(first, command)
            raise GcsReplyError(first, "no answer", command)
        values = gp.parse_axis_answer(first, axes, command)
        self._check(self._read("ERR?"), command)
        return values

    def _query_text(self, command: str) -> str:
        """A one-line query; if it stays unanswered, ``ERR?`` says why."""
        try:
            return gp.answer_lines(self._exchange(command, 1)[0])[0]
        except GcsTimeoutError:
            self._check(self._exchange("ERR?", 1)[0], command)
            raise

    def _vmo(self, coords: np.ndarray) -> bool:
        command = gp.command("VMO?", to_wire(coords))
        self.vmo_checks += 1
        answer = self._query_text(command)
        if answer not in ("0", "1"):
            raise GcsReplyError(answer, "VMO? answers 0 or 1", command)
        return answer == "1"

    def _read_pose(self) -> np.ndarray:
        self._coords = from_wire(self._query_axes("POS?", gp.AXES))
        R, t = self.convention.pose(self._coords)
        self._pose = (R, t)
        self._q = inverse_kinematics(self.geometry, R, t)
        return self._q.copy()

    def _guarded(self, action: Callable[[], T]) -> T:
        """Run exchanges; on any failure halt the robot if the link allows, then raise."""
        try:
            return action()
        except GcsDisconnectedError:
            self._shutdown(halt=False)
            raise
        except KeyboardInterrupt:
            self._shutdown(halt=True)
            raise
        except Exception:  # a controller error, a timeout, a bad answer, a failed FK
            self._try_halt()
            raise

    def command(self, text: str) -> list[str]:
        """Send any line and return the lines of its answer (queries) or [] (set
        commands, whose ``ERR?`` is checked). For diagnostics and tests.

        Raises:
            GcsControllerError: ``ERR?`` reported an error (the robot is halted).
        """
        if not text.split()[0].endswith("?"):
            self._guarded(lambda: self._set(text))
            return []

        def query() -> list[str]:
            answer, err = self._exchange(f"{text}\nERR?", 2)
            self._check(err, text)
            return gp.answer_lines(answer)

        return self._guarded(query)

    # ------------------------------------------------------------------ Backend
    def measured_lengths(self) -> np.ndarray:
        """Leg lengths of the measured pose (``POS?``, nominal IK) (6,) [m]."""
        return self._guarded(self._read_pose)

    def pose(self) -> tuple[np.ndarray, np.ndarray]:
        """The platform pose the controller reports (``POS?``): rotation, translation [m]."""
        self.measured_lengths()
        return self._pose[0].copy(), self._pose[1].copy()

    def _coords_of(self, lengths: np.ndarray) -> np.ndarray:
        sol = forward_kinematics(self.geometry, lengths, guess=self._pose, check_stroke=False)
        return self.convention.coords(sol.rotation, sol.translation)

    def _near_edge(self, lengths: np.ndarray) -> bool:
        lo, hi = self.stroke
        m = self.options.vmo_margin
        return bool(np.any(lengths < lo + m) or np.any(lengths > hi - m))

    def move(self, lengths: np.ndarray, timeout: float | None = None) -> np.ndarray:
        """Move to leg lengths [m] (nominal model), wait until on target (``ONT?``).

        Raises:
            StrokeLimitError: A length outside the nominal stroke (nothing is sent).
            GcsOutOfLimitsError: The controller's model cannot reach the pose (``VMO?``
                answered 0, or ``MOV`` refused with error 7): nothing moved.
        """
        q = np.asarray(lengths, dtype=float)
        if q.shape != (6,) or not np.all(np.isfinite(q)):
            raise ShapeError("lengths", "6 finite leg lengths [m]", q)
        for i, x in enumerate(q):
            if not self.stroke[0] - 1e-9 <= x <= self.stroke[1] + 1e-9:
                raise StrokeLimitError(i, float(x), *self.stroke)

        def go() -> np.ndarray:
            target = self._coords_of(q)
            if not self._vmo(target):
                raise gp.controller_error(gp.GcsError.POS_OUT_OF_LIMITS,
                                          gp.command("VMO?", to_wire(target)), self.url)
            self._set(gp.command("MOV", to_wire(target)))
            d = target - self._coords
            limit = timeout if timeout is not None else 1.0 + 2.0 * max(
                float(np.linalg.norm(d[:3])) / self.velocity,
                float(np.linalg.norm(np.rad2deg(d[3:]))) / (self.velocity * 1e3),
                float(np.max(np.abs(q - self._q))) / self.max_speed)
            deadline = time.perf_counter() + limit
            while not all(self._query_axes("ONT?", gp.AXES).values()):
                if time.perf_counter() > deadline:
                    raise BackendError(f"{self.url}: not on target within {limit:.1f} s")
                time.sleep(0.01)
            return self._read_pose()

        out = self._guarded(go)
        self._rate = None
        return out

    def reset(self, lengths: np.ndarray | None = None) -> np.ndarray:
        """Clear a stored error, move to ``lengths`` [m] (if given), return the measured
        lengths (nominal IK of ``POS?``)."""
        code = self._guarded(lambda: gp.parse_int_answer(self._exchange("ERR?", 1)[0]))
        if code:
            logger.info("%s: reset cleared error %d (%s)", self.url, code, gp.error_text(code))
        self._rate = None
        if lengths is None:
            return self.measured_lengths()
        return self.move(lengths)

    def step(self, velocities: np.ndarray, dt: float) -> BackendStep:
        """One control period: ``MOV`` to the pose of ``q + v dt`` (clamped), wait for
        the end of the period (a :class:`~hexapod.backends.rate.RateLimiter`), ``POS?``.

        Returns:
            The measured lengths, the applied velocities (zero when ``VMO?`` refused the
            target: the robot held), the clamped legs, the communication time
            (``round_trip_s``) and whether the period was missed. ``extras``:
            ``mov_rtt_s``, ``pos_rtt_s``, ``vmo_rtt_s``, ``slack_s``, ``vmo_refused``.
        """
        v = step_command(velocities, dt)
        rate = self._rate = RateLimiter.keeping(self._rate, dt, f"GcsHexapod({self.url})")
        vc, clamped = clamp_velocities(self._q, v, dt, self.stroke, self.max_speed)
        target_q = np.clip(self._q + vc * dt, *self.stroke)
        before = self._q.copy()

        def period() -> tuple[float, float, float, float, float, bool]:
            t0 = time.perf_counter()
            target = self._coords_of(target_q)
            t1 = time.perf_counter()
            check = self.options.vmo == "always" or (
                self.options.vmo == "edge" and self._near_edge(target_q))
            ok = self._vmo(target) if check else True
            t2 = time.perf_counter()
            if ok:
                self._set(gp.command("MOV", to_wire(target)))
            else:
                self.vmo_refusals += 1
            t3 = time.perf_counter()
            slack = rate.sleep_after(t0)  # the first period starts with its MOV
            t4 = time.perf_counter()
            self._read_pose()
            # the legs went from where they were toward the target (held when refused):
            # a reading elsewhere is refused before a target is made of it
            check_reading(self.url, self._q, before, target_q if ok else before, None,
                          READING_TOLERANCE)
            vmo_rtt = t2 - t1 if check else 0.0
            return t1 - t0, vmo_rtt, t3 - t2, time.perf_counter() - t4, slack, ok

        fk_s, vmo_rtt, mov_rtt, pos_rtt, slack, ok = self._guarded(period)
        if not ok:
            vc, clamped = np.zeros(6), np.ones(6, dtype=bool)
        return BackendStep(
            lengths=self._q.copy(), applied_velocities=vc, clamped=clamped,
            round_trip_s=vmo_rtt + mov_rtt + pos_rtt, missed_period=slack < 0,
            extras={"mov_rtt_s": mov_rtt, "pos_rtt_s": pos_rtt, "vmo_rtt_s": vmo_rtt,
                    "fk_s": fk_s, "slack_s": slack, "vmo_refused": float(not ok)})

    # ------------------------------------------------------------------ stopping
    def _try_halt(self) -> bool | None:
        """Send ``HLT`` and read ``ERR?`` (error 10 confirms it and is cleared); never
        raises. True when confirmed, False when sent and not confirmed, None when it could
        not be written."""
        if self._closed:
            return None
        try:
            self._link.discard_input()
            self._link.write(gp.encode("HLT", "ERR?"), "HLT")
        except (GcsLinkError, GcsReplyError) as exc:
            logger.warning("%s: HLT could not be sent (%s)", self.url, exc)
            return None
        try:
            deadline = time.perf_counter() + self.timeout
            for _ in range(8):  # answers still on their way are skipped
                answer = self._link.read_answer("HLT", deadline)
                if answer.strip() == str(int(gp.GcsError.STOP)).encode():
                    return True
        except (GcsLinkError, GcsReplyError) as exc:
            logger.warning("%s: HLT sent, not confirmed within %.1f s (%s)", self.url,
                           self.timeout, exc)
        return False

    def halt_confirmed(self, timeout_s: float = 2.0) -> HaltReport:
        """Send ``HLT`` with ``ERR?`` and wait up to ``timeout_s`` [s] for error 10 (the
        controller's confirmation that a stop was commanded and done). Never raises.

        The answers still on their way (after a stall, those of the commands queued
        before the ``HLT``) are read and skipped, never discarded while waiting; the pair
        is sent again every ``timeout`` [s] until confirmed (``HLT`` is idempotent), so an
        ``HLT`` queued during a stall is confirmed as soon as the controller answers.

        Args:
            timeout_s: Longest wait [s].

        Returns:
            Confirmed when ``ERR?`` answered 10.
        """
        clock = HaltClock(timeout_s)
        t0, deadline, report = clock.t0, clock.deadline, clock.report
        if self._closed:
            return clock.closed(self.url)
        sent = 0
        stop = str(int(gp.GcsError.STOP)).encode()
        try:
            self._link.discard_input()
            resend = t0
            while True:
                now = time.perf_counter()
                if now >= deadline:
                    return report(False, f"{self.url}: HLT sent {sent} time(s), not confirmed "
                                         f"by ERR? (error 10) within {timeout_s:g} s")
                if now >= resend:
                    self._link.write(gp.encode("HLT", "ERR?"), "HLT")
                    sent += 1
                    resend = now + self.timeout
                try:
                    answer = self._link.read_answer("HLT", min(deadline, resend))
                except GcsTimeoutError:
                    continue
                if answer.strip() == stop:
                    self._halt_done = True
                    return report(True, f"{self.url}: HLT confirmed (ERR? answered 10, "
                                        "stopped by command)")
        except GcsLinkError as exc:
            return report(False, f"{self.url}: the link failed while halting: {exc}")
        except BackendError as exc:  # never raises: the caller is shutting down
            return report(False, f"{self.url}: halting failed: {exc}")

    def halt(self) -> None:
        """Stop the platform where it is (``HLT``); never raises if the link is dead."""
        if not self._try_halt() and not self._closed:
            logger.warning("%s: HLT not confirmed by ERR? (expected error 10)", self.url)

    def stop(self) -> None:
        """Stop abruptly (``STP``) and clear the resulting error 10; never raises."""
        if self._closed:
            return
        try:
            self._link.discard_input()
            self._exchange("STP\nERR?", 1)
        except (GcsLinkError, GcsReplyError) as exc:
            logger.warning("%s: could not stop the robot: %s", self.url, exc)

    def _shutdown(self, halt: bool) -> None:
        if halt and not self._halt_done:  # a confirmed halt is not sent again
            self._try_halt()
        if self._closed:
            return
        self._closed = True
        self._link.close()
        if self._on_close is not None:
            self._on_close()

    def close(self) -> None:
        """Halt the robot (if the link works) and close the link. Idempotent."""
        self._shutdown(halt=True)

    @property
    def is_open(self) -> bool:
        """The link is open."""
        return not self._closed

    def stats(self) -> dict[str, Any]:
        """Round-trip statistics of the exchanges so far: count, median and p99 [s]."""
        rtt = np.array(self.exchanges)
        if rtt.size == 0:
            return {"exchanges": 0}
        return {"exchanges": int(rtt.size), "median_s": float(np.median(rtt)),
                "p99_s": float(np.percentile(rtt, 99)), "max_s": float(rtt.max()),
                "vmo_checks": self.vmo_checks, "vmo_refusals": self.vmo_refusals}

    @classmethod
    def open(cls, args: str, geometry: HexapodGeometry, start: np.ndarray | None = None
             ) -> GcsHexapod:
        """Open ``gcs:tcp://HOST:PORT[?key=value&...]`` or ``gcs:serial:URL[?...]``."""
        if not args:
            raise BackendPluginError("gcs", "hexapod-vs", "needs an address: "
                                     "gcs:tcp://HOST:PORT or gcs:serial:URL")
        url, options = GcsOptions.parse(args)
        robot = cls(url, geometry, options)
        return started(robot, start)
