"""The jerk-limited rest-to-rest move ("S-curve", seven phases), the fastest under speed,
acceleration and jerk limits.

A move of length ``D`` with ``|v| <= V``, ``|a| <= A``, ``|j| <= J`` takes, at the least
(bang-bang jerk, then acceleration, then speed, each at its limit as long as it helps):

- ``T = D / V + V / A + A / J`` when the speed limit is reached (``V >= A^2 / J`` and
  ``D >= V (V / A + A / J)``): jerk ``A / J``, acceleration, jerk back, cruise, the
  mirror image;
- when it is not, the peak speed ``v < V`` solves ``D = v T_a(v)`` with the acceleration
  phase ``T_a(v) = v / A + A / J`` (the acceleration limit reached, ``v >= A^2 / J``) or
  ``T_a(v) = 2 sqrt(v / J)`` (not reached: ``T = (32 D / J)^(1/3)``);

and ``T = 2 T_a + T_cruise``. The acceleration is continuous (trapezoids in time), the
jerk piecewise constant: ``+J, 0, -J`` over the acceleration phase, nothing while
cruising, ``-J, 0, +J`` while braking.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class SCurve:
    """A jerk-limited rest-to-rest move from 0 to ``distance``.

    Attributes:
        distance: Length of the move (``D``).
        jerk: Jerk of the jerk phases (``J``).
        jerk_time: Duration of a jerk phase (``T_j``) [s].
        ramp: Duration of the acceleration (and of the braking) phase (``T_a``) [s].
        peak: Speed reached (``v``).
        duration: Time of the whole move [s].
    """

    distance: float
    jerk: float
    jerk_time: float
    ramp: float
    peak: float
    duration: float

    @staticmethod
    def fit(distance: float, speed: float, acceleration: float, jerk: float) -> SCurve:
        """The fastest move of ``distance`` within the limits (module docstring); ``inf``
        for a limit that does not bind (the speed or the acceleration, not the jerk).

        Raises:
            ValueError: A non-positive limit or distance, or no finite limit on jerk.
        """
        for name, value in (("distance", distance), ("speed", speed),
                            ("acceleration", acceleration), ("jerk", jerk)):
            if not value > 0.0:
                raise ValueError(f"{name} must be positive, got {value!r}")
        if not math.isfinite(jerk):
            raise ValueError("jerk: a finite limit is required (without one, use the "
                             "trapezoidal profile)")
        D, A, J = distance, acceleration, jerk

        def ramp_of(v: float) -> tuple[float, float]:  # (T_j, T_a) reaching speed v
            if v * J >= A * A:
                return A / J, v / A + A / J
            tj = math.sqrt(v / J)
            return tj, 2.0 * tj

        v = speed
        if not (math.isfinite(v) and v * ramp_of(v)[1] <= D):  # the speed limit is not reached
            if math.isfinite(A):
                v_a = 0.5 * A * (-A / J + math.sqrt((A / J) ** 2 + 4.0 * D / A))
            else:
                v_a = 0.0
            v = v_a if v_a * J >= A * A else (0.5 * D * math.sqrt(J)) ** (2.0 / 3.0)
        tj, ta = ramp_of(v)
        cruise = max(D / v - ta, 0.0)
        return SCurve(D, J, tj, ta, v, 2.0 * ta + cruise)

    def _rise(self, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, speed and acceleration at ``tau`` in ``[0, T_a]`` of the
        acceleration phase."""
        J, tj, ta, v = self.jerk, self.jerk_time, self.ramp, self.peak
        a = J * tj  # the acceleration of the middle phase (if any)
        s1, v1 = J * tj**3 / 6.0, 0.5 * J * tj * tj
        first = tau <= tj
        last = tau >= ta - tj
        u = tau - tj
        sigma = ta - tau
        s = np.where(first, J * tau**3 / 6.0, np.where(
            last, 0.5 * v * ta - (v * sigma - J * sigma**3 / 6.0),
            s1 + v1 * u + 0.5 * a * u * u))
        sd = np.where(first, 0.5 * J * tau * tau, np.where(last, v - 0.5 * J * sigma * sigma,
                                                            v1 + a * u))
        sdd = np.where(first, J * tau, np.where(last, J * sigma, a))
        return s, sd, sdd

    def __call__(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, speed and acceleration at times ``t`` [s] (any shape): 0 before the
        start, ``distance`` after the end, at rest outside ``(0, duration)``."""
        t = np.asarray(t, dtype=float)
        T, ta, v = self.duration, self.ramp, self.peak
        tc = np.clip(t, 0.0, T)
        rising = tc <= ta
        falling = tc >= T - ta
        s_r, sd_r, sdd_r = self._rise(np.clip(tc, 0.0, ta))
        s_f, sd_f, sdd_f = self._rise(np.clip(T - tc, 0.0, ta))
        s = np.where(rising, s_r, np.where(falling, self.distance - s_f,
                                           0.5 * v * ta + v * (tc - ta)))
        sd = np.where(rising, sd_r, np.where(falling, sd_f, v))
        sdd = np.where(rising, sdd_r, np.where(falling, -sdd_f, 0.0))
        s = np.where(t >= T, self.distance, s)
        outside = (t <= 0.0) | (t >= T)
        return s, np.where(outside, 0.0, sd), np.where(outside, 0.0, sdd)
