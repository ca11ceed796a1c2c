"""The robot backend interface (in the style of upkie's backends).

A backend is where leg-velocity commands go: a simulated robot, or a real one
through a serial link. Every backend clamps commands to the stroke and speed
limits and reports the leg lengths a real robot's encoders would measure.
"""

from __future__ import annotations

import inspect
import logging
import time
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from types import TracebackType
from typing import Any, TypeVar

import numpy as np

from hexapod.actuation import Actuation, check_actuation
from hexapod.exceptions import BackendError, ShapeError
from hexapod.geometry import HexapodGeometry
from hexapod.link_errors import ImplausibleReadingError

log = logging.getLogger(__name__)


@dataclass
class BackendStep:
    """What a backend returns after applying one command.

    Attributes:
        lengths: (6,) measured leg lengths after the step [m].
        applied_velocities: (6,) the velocities actually applied after clamping [m/s].
        clamped: (6,) bool, legs whose command was clamped (stroke or speed).
        round_trip_s: Communication time spent in this step [s] (0 for a simulation).
        missed_period: True when the step took longer than its period.
        extras: Backend-specific diagnostics.
    """

    lengths: np.ndarray
    applied_velocities: np.ndarray
    clamped: np.ndarray
    round_trip_s: float = 0.0
    missed_period: bool = False
    extras: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class HaltReport:
    """What a backend knows after commanding its stop (:meth:`Backend.halt_confirmed`).

    Attributes:
        confirmed: The robot reported itself stopped (a simulated robot always is).
        detail: What was sent and read back, in words (for the user and the log).
        seconds: Time spent halting and confirming [s].
    """

    confirmed: bool
    detail: str
    seconds: float = 0.0


class HaltClock:
    """The clock of one confirmed halt (:meth:`Backend.halt_confirmed`), started when made.

    Args:
        timeout_s: Longest wait [s].

    Attributes:
        t0: When the halt started [s] (``time.perf_counter()``).
        deadline: When it gives up [s] (``t0 + timeout_s``).
    """

    def __init__(self, timeout_s: float) -> None:
        self.t0 = time.perf_counter()
        self.deadline = self.t0 + timeout_s

    def report(self, confirmed: bool, detail: str) -> HaltReport:
        """The halt's report, its ``seconds`` [s] the time since :attr:`t0`."""
        return HaltReport(confirmed, detail, time.perf_counter() - self.t0)

    def closed(self, url: str) -> HaltReport:
        """The (unconfirmed) report of a halt on a closed link to ``url``."""
        return self.report(False, f"{url}: the link is closed, HLT could not be sent")


BackendT = TypeVar("BackendT", bound="Backend")


class Backend(ABC):
    """A robot that accepts leg-velocity commands at a fixed period.

    A backend of your own (another robot controller) subclasses this class,
    implements :meth:`reset`, :meth:`step` and :meth:`measured_lengths` (and
    :meth:`halt` / :meth:`close` where they mean something), and is named on the
    command line as ``--backend my_package.module:MyRobot[:ARGS]`` or registered
    under the entry-point group ``hexapod.backends`` (``docs/backends.md``).
    """

    #: Stroke limits (q_min, q_max) [m].
    stroke: tuple[float, float]
    #: Leg speed limit [m/s].
    max_speed: float
    #: What the robot says it is (shown by the servo loop).
    identity: str = ""
    #: The command kinds it applies (leg velocities; a force-controlled robot adds
    #: :attr:`~hexapod.actuation.Actuation.FORCE` and overrides :meth:`step_forces`).
    actuations: tuple[Actuation, ...] = (Actuation.VELOCITY,)
    #: The robot is simulated (a model, an emulator), not hardware: ``hexapod-bench
    #: servo`` then allows ``--camera sim`` without asking (docs/servo.md).
    simulated: bool = False
    #: :meth:`step` returns at the end of its control period: the backend waits out the
    #: period itself (the serial and GCS backends, with a
    #: :class:`~hexapod.backends.rate.RateLimiter`). A servo session waits out each period
    #: for a backend that does not and is not :attr:`simulated` (docs/backends.md).
    paces_periods: bool = False

    @classmethod
    def open(cls, args: str, geometry: HexapodGeometry, start: np.ndarray | None = None
             ) -> Backend:
        """Open this backend for ``--backend NAME[:ARGS]``.

        The default builds ``cls(geometry)`` (``cls(geometry, args)`` when ARGS are
        given), then moves to ``start`` with :meth:`reset` when it is given, closing
        the backend if that fails. Override it when the backend needs more.

        Args:
            args: The text after the name in the spec ('' when none).
            geometry: The nominal robot (stroke, speed limit, kinematics).
            start: Leg lengths [m] to start from (None: where the robot is).
        """
        given = (geometry, args) if args else (geometry,)
        try:
            inspect.signature(cls).bind(*given)
        except TypeError as exc:  # (its own TypeError inside __init__ stays its own)
            raise BackendError(f"{cls.__name__}: cannot be opened with "
                               + (f"the ARGS {args!r} after its name" if args else "no ARGS")
                               + f" ({exc}); see its documentation") from None
        robot = cls(*given)
        return started(robot, start)

    @abstractmethod
    def reset(self, lengths: np.ndarray | None = None) -> np.ndarray:
        """Bring the robot to ``lengths`` (if given) and return the measured lengths [m]."""

    @abstractmethod
    def step(self, velocities: np.ndarray, dt: float) -> BackendStep:
        """Apply leg velocities [m/s] for ``dt`` [s] (after clamping) and measure."""

    def step_forces(self, forces: np.ndarray, dt: float) -> BackendStep:
        """Apply leg forces [N] for ``dt`` [s] (a backend listing
        :attr:`~hexapod.actuation.Actuation.FORCE` in :attr:`actuations` overrides it).

        Raises:
            ActuationError: This backend applies leg velocities only.
        """
        check_actuation(Actuation.FORCE, self.actuations, self._receiver(), "force command")
        raise NotImplementedError(f"{type(self).__name__} lists force actuation but does not "
                                  "implement step_forces")

    def apply(self, command: np.ndarray, actuation: Actuation, dt: float,
              controller: str = "controller") -> BackendStep:
        """Apply one period's command of its kind: :meth:`step` for leg velocities
        [m/s], :meth:`step_forces` for leg forces [N].

        Args:
            command: (6,) the command's values.
            actuation: What they are.
            dt: Period [s].
            controller: Who commands (named by the refusal).

        Raises:
            ActuationError: The backend does not apply this kind of command.
        """
        kind = check_actuation(actuation, self.actuations, self._receiver(), controller)
        if kind is Actuation.FORCE:
            return self.step_forces(command, dt)
        return self.step(command, dt)

    def _receiver(self) -> str:
        name = self.identity or type(self).__name__
        return f"the backend {name!r}"

    @abstractmethod
    def measured_lengths(self) -> np.ndarray:
        """The current measured leg lengths (6,) [m]."""

    def halt(self) -> None:  # noqa: B027 - optional hook
        """Stop every leg where it is (no-op for a simulation)."""

    def halt_confirmed(self, timeout_s: float = 2.0) -> HaltReport:
        """Stop every leg (:meth:`halt`) and wait up to ``timeout_s`` [s] for the robot to
        confirm it; never raises.

        The default knows only that :meth:`halt` returned: a backend that can read
        back the robot's state overrides it (the serial board and the GCS controller do).

        Args:
            timeout_s: Longest wait for the confirmation [s].

        Returns:
            Whether the robot confirmed it stopped, and what happened.
        """
        t0 = time.perf_counter()
        try:
            self.halt()
        except Exception as exc:  # a plugin's halt: report, never raise during a shutdown
            return HaltReport(False, f"halt() failed: {type(exc).__name__}: {exc}",
                              time.perf_counter() - t0)
        return HaltReport(False, "halt() returned; this backend does not report whether the "
                                 "robot stopped", time.perf_counter() - t0)

    def close(self) -> None:  # noqa: B027 - optional hook
        """Release the robot (halts it first where that means something)."""

    def __enter__(self) -> Backend:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        try:
            self.halt()
        finally:
            self.close()


def check_reading(url: str, q: np.ndarray, previous: np.ndarray | None,
                  setpoints: np.ndarray | None, stroke: tuple[float, float] | None,
                  tolerance: float) -> np.ndarray:
    """``q`` (6,) [m], leg lengths a controller reported, checked before anything is made
    of them: inside ``stroke`` and, streaming, on the way from the ``previous`` reading
    to the ``setpoints`` sent since, each within ``tolerance`` [m] (None: not checked).

    Raises:
        ImplausibleReadingError: Naming the leg, its reading and where it could be.
    """
    low, high = np.full(6, -np.inf), np.full(6, np.inf)
    why = []
    if stroke is not None:
        low[:], high[:] = stroke[0] - tolerance, stroke[1] + tolerance
        why.append("the stroke")
    if previous is not None and setpoints is not None:
        low = np.maximum(low, np.minimum(previous, setpoints) - tolerance)
        high = np.minimum(high, np.maximum(previous, setpoints) + tolerance)
        why.append("between its last reading and the setpoint sent")
    bad = np.flatnonzero((q < low) | (q > high))
    if bad.size:
        i = int(bad[0])
        raise ImplausibleReadingError(url, i, float(q[i]), float(low[i]), float(high[i]),
                                      " and ".join(why) + f", within {tolerance * 1e3:g} mm")
    return q


def write_failed(exc: BaseException) -> str:
    """``write failed: <reason>`` of a link's failed write (pyserial's own message already
    begins so: not said twice)."""
    text = str(exc)
    return text if text.startswith("write failed") else f"write failed: {text}"


def started(robot: BackendT, start: np.ndarray | None) -> BackendT:
    """``robot`` moved to ``start`` with ``reset`` (nothing when None); halted, then
    closed, if that fails (a move to a start is the longest a real robot makes: it was
    closed without a halt).

    Args:
        robot: A just-opened backend.
        start: Leg lengths [m] to start from, or None (where the robot is).

    Returns:
        The robot.
    """
    if start is not None:
        try:
            robot.reset(start)
        except BaseException:
            halt_and_close(robot)  # (its own failures said: the move's is raised)
            raise
    return robot


def halt_and_close(robot: Any) -> list[str]:
    """Halt ``robot``, then close it, whatever either does: a failure of one does not
    skip the other, and neither replaces an exception the caller is handling. Returns
    what failed (also logged as warnings)."""
    failed = []
    for what in ("halt", "close"):
        try:
            getattr(robot, what)()
        except Exception as exc:
            failed.append(f"{what}() raised {type(exc).__name__}: {exc}")
            log.warning("%s: %s", type(robot).__name__, failed[-1])
    return failed


def halt_on_open(url: str, acknowledged: bool | None) -> str:
    """What a backend whose link opened but whose controller failed to connect (no answer
    to its first question) did on the way out: the ``halt_detail`` its exception carries,
    which a servo session records (the robot was never connected, yet it was sent ``HLT``:
    a board that hears but cannot answer still stops). ``acknowledged`` None: the
    ``HLT`` could not be written (a broken pipe, a closed port)."""
    if acknowledged is None:
        return f"{url}: HLT could not be sent on the way out (the link failed)"
    return f"{url}: HLT sent on the way out, {'' if acknowledged else 'not '}acknowledged"


def step_command(velocities: np.ndarray, dt: float) -> np.ndarray:
    """A period's command checked: (6,) leg velocities [m/s] and a positive period [s].

    Raises:
        ShapeError: ``velocities`` is not of shape (6,).
        BackendError: ``dt`` is not a positive number.
    """
    v = np.asarray(velocities, dtype=float)
    if v.shape != (6,):
        raise ShapeError("velocities", "shape (6,)", v.shape)
    if not (np.isfinite(dt) and dt > 0):
        raise BackendError(f"dt must be positive, got {dt} s")
    return v


def clamp_velocities(
    lengths: np.ndarray,
    velocities: np.ndarray,
    dt: float,
    stroke: tuple[float, float],
    max_speed: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Clamp leg velocities to the speed limit and so that the stroke is never left.

    Works on batches (..., 6). Non-finite commands become zero (and count as clamped).

    Args:
        lengths: Current leg lengths [m].
        velocities: Commanded leg velocities [m/s].
        dt: Period [s].
        stroke: (q_min, q_max) [m].
        max_speed: Speed limit [m/s].

    Returns:
        The applied velocities and a boolean mask of clamped legs.
    """
    v = np.asarray(velocities, dtype=float)
    finite = np.isfinite(v)
    v = np.where(finite, v, 0.0)
    vc = np.clip(v, -max_speed, max_speed)
    lo = (stroke[0] - lengths) / dt
    hi = (stroke[1] - lengths) / dt
    vc = np.minimum(np.maximum(vc, np.minimum(lo, 0.0)), np.maximum(hi, 0.0))
    clamped = (~finite) | (np.abs(vc - v) > 1e-12)
    return vc, clamped
