"""The limits a lab sets on a servo session (:class:`SessionLimits`), the robot behind
them (:class:`LimitedRobot`) and the missed-deadline policy (:class:`DeadlinePolicy`).

Reaching a limit raises :class:`~benchmarks.robot.exits.SessionStop` with
:attr:`~benchmarks.robot.exits.ServoExit.LIMIT` and says which limit; the session's one
shutdown then halts the robot. SI units inside (m, m/s, s).
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from benchmarks.robot.exits import ServoExit, SessionStop
from hexapod.actuation import Actuation
from hexapod.backends.rate import RateLimiter
from hexapod.exceptions import BackendError

#: Default ``--max-time-s`` [s]: a session never runs unattended for ever.
DEFAULT_MAX_TIME_S = 60.0
#: Default ``--max-missed-consecutive``: this many late periods in a row stop the session.
DEFAULT_MAX_MISSED_CONSECUTIVE = 10
#: Default ``--max-missed-fraction``: more than this fraction of the last
#: :data:`MISSED_WINDOW` periods late stops the session.
DEFAULT_MAX_MISSED_FRACTION = 0.25
#: The window of ``--max-missed-fraction`` [periods].
MISSED_WINDOW = 50
#: Missed-period warnings are printed at most once every this many seconds.
WARN_PERIOD_S = 1.0
#: A backend that says it keeps its periods (``paces_periods``) is taken at its word
#: unless its first this many steps all return less than half a period apart.
PACING_CHECK_PERIODS = 5


@dataclass(frozen=True)
class SessionLimits:
    """What a session may do before it is stopped (exit 3, :attr:`ServoExit.LIMIT`).

    Attributes:
        max_speed: Leg speed limit [m/s] (at most the robot file's ``max_speed_mm_s``).
        max_travel: Largest leg travel from the start lengths [m] (None: the stroke).
        max_time: Longest session [s] (from the first period).
        max_steps: Period budget (None: none).
        max_missed_consecutive: Late periods in a row that stop the session (0: never).
        max_missed_fraction: Fraction of the last :data:`MISSED_WINDOW` periods late
            that stops the session (1: never).
    """

    max_speed: float
    max_travel: float | None = None
    max_time: float = DEFAULT_MAX_TIME_S
    max_steps: int | None = None
    max_missed_consecutive: int = DEFAULT_MAX_MISSED_CONSECUTIVE
    max_missed_fraction: float = DEFAULT_MAX_MISSED_FRACTION

    def to_json(self) -> dict[str, Any]:
        """The limits in the user's units (mm, mm/s, s), for the session record."""
        return {"max_speed_mm_s": self.max_speed * 1e3,
                "max_travel_mm": None if self.max_travel is None else self.max_travel * 1e3,
                "max_time_s": self.max_time if math.isfinite(self.max_time) else None,
                "max_steps": self.max_steps,
                "max_missed_consecutive": self.max_missed_consecutive,
                "max_missed_fraction": self.max_missed_fraction,
                "missed_window": MISSED_WINDOW}


class LimitedRobot:
    """The connected backend ``robot`` behind the session's ``limits`` (what the loop's
    plant drives): every command is capped to :attr:`SessionLimits.max_speed` (the
    capped legs reported clamped) and refused before it is sent when a leg would leave
    the travel box around the ``start`` lengths (6,) [m]. With ``pace``, each period is
    waited out after the backend's step returns (a backend that sends and returns: the
    next command leaves one period after this one, not as soon as it is computed; a late
    period is reported missed), and the period's link time is the time the backend's
    step took (what a backend reports may leave out its own work). With
    ``check_pacing`` (a backend that says it keeps its periods), its word is checked:
    when its first :data:`PACING_CHECK_PERIODS` steps all return less than half a
    period apart, ``warn`` is told and the session paces from then on. Other
    attributes are the backend's."""

    def __init__(self, robot: Any, limits: SessionLimits, start: np.ndarray,
                 pace: bool = False, check_pacing: bool = False,
                 warn: Callable[[str], None] | None = None) -> None:
        self.robot = robot
        #: The session's pacing of the periods (None: the backend keeps them).
        self.rate: RateLimiter | None = None
        self.pace = pace
        self.warn = warn
        #: When the backend's steps returned [s] (perf_counter), while they are checked.
        self._returns: list[float] | None = [] if check_pacing and not pace else None
        self.limits = limits
        self.start = np.asarray(start, float).copy()
        self.q = self.start.copy()
        #: A command was sent (the robot may have moved).
        self.moved = False
        #: The last applied velocities [m/s] (zeros before the first period).
        self.last_applied = np.zeros(6)
        #: The last period's dt [s].
        self.last_dt = 0.0
        #: What the last command was (leg velocities or leg forces).
        self.last_actuation = Actuation.VELOCITY

    def __getattr__(self, name: str) -> Any:
        return getattr(self.robot, name)

    def apply(self, command: np.ndarray, actuation: Actuation, dt: float,
              controller: str = "controller") -> Any:
        """Cap, check the travel, then apply through the backend.

        Raises:
            SessionStop: The command would take a leg beyond ``--max-travel-mm``.
        """
        v = np.asarray(command, float)
        capped = np.zeros(6, dtype=bool)
        if actuation is Actuation.VELOCITY:
            cap = self.limits.max_speed
            capped = np.abs(v) > cap
            v = np.clip(v, -cap, cap)
            if self.limits.max_travel is not None:
                travel = np.abs(self.q + v * dt - self.start)
                leg = int(np.argmax(travel))
                if travel[leg] > self.limits.max_travel + 1e-9:
                    raise SessionStop(ServoExit.LIMIT, (
                        f"--max-travel-mm {self.limits.max_travel * 1e3:g} reached: leg "
                        f"{leg} at {self.q[leg] * 1e3:.3f} mm would move "
                        f"{travel[leg] * 1e3:.3f} mm from its start length "
                        f"{self.start[leg] * 1e3:.3f} mm (the command was not sent)"))
        self.moved = True
        # what was sent, an upper bound until the backend says what it applied
        self.last_dt = dt
        self.last_actuation = actuation
        self.last_applied = v.copy() if actuation is Actuation.VELOCITY else np.zeros(6)
        sent = time.perf_counter()
        try:
            bs = self.robot.apply(v, actuation, dt, controller)
        except BackendError:
            raise
        except Exception as exc:  # the plugin's own failure: the robot's, not ours (it
            # was an 'internal error' with a traceback; the session halts it either way)
            raise BackendError(f"{self._name()}: its step raised {type(exc).__name__}: "
                               f"{exc}") from exc
        if self._returns is not None:
            self._check_pacing(dt)
        if self.pace:  # the rest of the period, on the grid of the first command
            bs = replace(bs, round_trip_s=time.perf_counter() - sent)
            self.rate = RateLimiter.keeping(self.rate, dt, "servo session")
            if self.rate.sleep_after(sent) < 0 and not bs.missed_period:
                bs = replace(bs, missed_period=True)
        self.q = np.asarray(bs.lengths, float).copy()
        self.last_applied = np.asarray(bs.applied_velocities, float).copy()
        if capped.any():
            bs = replace(bs, clamped=np.asarray(bs.clamped, bool) | capped)
        return bs

    def _name(self) -> str:
        """The backend as messages name it: what it says it is, else its class."""
        return str(getattr(self.robot, "identity", "") or type(self.robot).__name__)

    def _check_pacing(self, dt: float) -> None:
        """Take the backend's ``paces_periods`` at its word, or pace for it (class
        docstring)."""
        assert self._returns is not None
        self._returns.append(time.perf_counter())
        if len(self._returns) <= PACING_CHECK_PERIODS:
            return
        gaps = np.diff(self._returns)
        self._returns = None  # checked once
        if (gaps < dt / 2).all():
            self.pace = True
            if self.warn is not None:
                self.warn(f"warning: {self._name()} says it waits out its periods "
                          "(paces_periods) "
                          f"but its first {PACING_CHECK_PERIODS} steps returned "
                          f"{float(np.median(gaps)) * 1e3:.2f} ms apart (median) for a "
                          f"{dt * 1e3:g} ms period: the session paces them from now on")


class DeadlinePolicy:
    """Missed periods of control period ``dt`` [s]: counted, warned (``warn``) at most
    once a second, and fatal after ``limits.max_missed_consecutive`` in a row or more
    than ``limits.max_missed_fraction`` of the last :data:`MISSED_WINDOW` periods."""

    def __init__(self, limits: SessionLimits, dt: float, warn: Callable[[str], None]) -> None:
        self.limits, self.dt, self.warn = limits, dt, warn
        self.consecutive = 0
        self.total = 0
        self.window: deque[bool] = deque(maxlen=MISSED_WINDOW)
        self._last_warn = -math.inf
        self._since_warn = 0

    def update(self, step: int, missed: bool, compute_s: float, link_s: float) -> None:
        """Account period ``step``: ``missed`` (late), with its camera and controller
        time ``compute_s`` and its link time ``link_s`` [s] (for the messages).

        Raises:
            SessionStop: Too many missed periods (exit 3).
        """
        self.window.append(missed)
        if not missed:
            self.consecutive = 0
            return
        self.total += 1
        self.consecutive += 1
        self._since_warn += 1
        now = time.perf_counter()
        why = (f"compute {compute_s * 1e3:.1f} ms + link {link_s * 1e3:.1f} ms for a "
               f"{self.dt * 1e3:g} ms period")
        if now - self._last_warn >= WARN_PERIOD_S:
            self.warn(f"warning: {self._since_warn} late period(s) since the last warning, "
                      f"{self.total} of {step + 1} so far (last: {why})")
            self._last_warn, self._since_warn = now, 0
        n = self.limits.max_missed_consecutive
        if n > 0 and self.consecutive >= n:
            raise SessionStop(ServoExit.LIMIT, (
                f"--max-missed-consecutive {n} reached: {self.consecutive} periods in a row "
                f"missed their {self.dt * 1e3:g} ms deadline (last: {why})"))
        f = self.limits.max_missed_fraction
        late = sum(self.window)
        if (f < 1 and len(self.window) == MISSED_WINDOW
                and late > f * MISSED_WINDOW):
            raise SessionStop(ServoExit.LIMIT, (
                f"--max-missed-fraction {f:g} reached: {late} of the last {MISSED_WINDOW} "
                f"periods missed their {self.dt * 1e3:g} ms deadline (last: {why})"))
