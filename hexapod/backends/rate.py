"""A loop at a fixed period: the pacing of the real-robot backends' control periods."""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

import numpy as np

from hexapod.exceptions import BackendError

logger = logging.getLogger(__name__)

__all__ = ["RateLimiter"]


def _sleep(duration: float) -> None:
    """``time.sleep``, looked up when called (a test that patches it is obeyed)."""
    time.sleep(duration)


class RateLimiter:
    """Regulate a loop at a fixed period (the idiom of upkie's ``loop_rate_limiters``).

    Call :meth:`sleep` once per iteration: it sleeps until the next tick. A late
    iteration does not sleep, counts as missed and restarts the schedule from now
    (no burst of catch-up iterations).

    Args:
        period: Loop period [s].
        name: Name for the log messages.
        warn: Log a warning when an iteration is late by more than 10 % of the period.
        clock: The clock [s] (monotonic).
        sleep: Sleeps a duration [s] (``time.sleep``; with ``clock``, a simulated time).

    Attributes:
        period: Loop period [s].
        slack: Time left before the tick at the last :meth:`sleep` [s] (negative: late).
        missed: Number of late iterations.
        iterations: Number of calls to :meth:`sleep`.
    """

    def __init__(self, period: float, name: str = "rate limiter", warn: bool = False,
                 clock: Callable[[], float] = time.perf_counter,
                 sleep: Callable[[float], None] = _sleep) -> None:
        if not (np.isfinite(period) and period > 0):
            raise BackendError(f"{name}: period must be positive, got {period} s")
        self.period = float(period)
        self.name = name
        self.warn = warn
        self._clock = clock
        self._sleep = sleep
        self.next_tick = clock() + self.period
        self.slack = 0.0
        self.missed = 0
        self.iterations = 0

    @property
    def frequency(self) -> float:
        """Loop frequency [Hz]."""
        return 1.0 / self.period

    def remaining(self) -> float:
        """Time left until the next tick [s] (negative when late)."""
        return self.next_tick - self._clock()

    @classmethod
    def keeping(cls, limiter: RateLimiter | None, period: float, name: str) -> RateLimiter:
        """``limiter`` if it keeps ``period`` [s], else a new limiter of that period (the
        period of a robot's loop may change from one run to the next)."""
        if limiter is not None and limiter.period == period:
            return limiter
        return cls(period, name=name)

    def sleep_after(self, start: float) -> float:
        """:meth:`sleep`; the first iteration's tick is one period after ``start`` (the
        clock time at which the period's command was sent)."""
        if self.iterations == 0:
            self.next_tick = start + self.period
        return self.sleep()

    def sleep(self) -> float:
        """Sleep until the next tick; returns the slack [s] (negative: the tick was missed)."""
        self.iterations += 1
        self.slack = self.next_tick - self._clock()
        if self.slack > 0:
            self._sleep(self.slack)
            self.next_tick += self.period
        else:
            self.missed += 1
            if self.warn and self.slack < -0.1 * self.period:
                logger.warning("%s is late by %.1f ms", self.name, -self.slack * 1e3)
            self.next_tick = self._clock() + self.period
        return self.slack
