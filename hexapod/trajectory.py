"""Reference pose trajectories with their first and second time derivatives.

A trajectory starts at rest at a start pose and ends at rest:

- ``line``: to a goal pose, the position along the segment and the orientation about
  the fixed axis of ``log(R0^T R1)``, both driven by one timing law ``s(t)`` from 0 to
  1, so that neither the translation speed and acceleration nor the angular ones
  exceed their limits;
- ``circle``: ``laps`` turns of a circle of radius ``r`` through the start position, in
  a plane of the base frame, the orientation held;
- ``lemniscate``: ``laps`` figure-eights of Gerono's lemniscate
  ``r (sin phi, sin phi cos phi)`` centred on the start position, the orientation held.

The timing law is a quintic polynomial (smooth acceleration), a trapezoidal speed
profile (bang-coast-bang acceleration) or a jerk-limited "S-curve" (:mod:`hexapod.scurve`:
the fastest move under speed, acceleration and jerk limits). The speed limit bounds
``|dp/dt|`` everywhere; the acceleration limit bounds the tangential acceleration
(exactly ``|d2p/dt2|`` on a line; on the curves the centripetal part, up to
``speed^2 / r``, comes on top); the jerk limit the tangential jerk.

Given a ``peak_acceleration``, the motion so timed is then slowed down or sped up as a
whole (``s(t) -> s(t / k)``: speeds scale by ``1 / k``, accelerations by ``1 / k^2``) until
its largest ``|d2p/dt2|`` (tangential and centripetal together) is that value: a circle
or a lemniscate "at 50 m/s^2".

Conventions (``docs/math.md``): the twist ``(v, w)`` is the velocity of the platform
frame's origin and the angular velocity, both in the base frame; the acceleration is
their time derivative. Units are SI (m, rad, s).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from hexapod.exceptions import ShapeError, TrajectoryError
from hexapod.kinematics import check_rotations
from hexapod.scurve import SCurve
from hexapod.se3 import exp_so3, log_so3

#: Timing laws.
PROFILES = ("quintic", "trapezoidal", "s-curve")
#: Samples per motion where the peak acceleration is searched (``peak_acceleration``).
PEAK_SAMPLES = 20_001
#: Path shapes.
SHAPES = ("line", "circle", "lemniscate")
#: Planes of the closed curves: the base-frame axes ``(e1, e2)`` spanning them.
PLANES = {"xy": (0, 1), "xz": (0, 2), "yz": (1, 2)}

#: Peak speed and acceleration of the quintic ``10 u^3 - 15 u^4 + 6 u^5`` over unit time.
_QUINTIC_PEAK_SPEED = 15.0 / 8.0
_QUINTIC_PEAK_ACCELERATION = 10.0 / math.sqrt(3.0)


@dataclass(frozen=True)
class TimingLaw:
    """A path parameter ``s(t)`` from 0 (at ``t <= 0``) to 1 (at ``t >= duration``), at
    rest at both ends.

    Attributes:
        kind: ``"quintic"``, ``"trapezoidal"`` or ``"s-curve"``.
        duration: Time from start to end [s].
        ramp: Duration of the acceleration (and deceleration) phase of the trapezoid [s].
        peak: Peak ``ds/dt`` of the trapezoid [1/s].
        curve: The S-curve of ``s`` (kind ``"s-curve"``).
        stretch: The law is ``s(t / stretch)`` of the one fitted (1: as fitted).
    """

    kind: str
    duration: float
    ramp: float = 0.0
    peak: float = 0.0
    curve: SCurve | None = None
    stretch: float = 1.0

    @staticmethod
    def fit(kind: str, speed: float, acceleration: float, jerk: float = math.inf
            ) -> TimingLaw:
        """The fastest law of ``kind`` with ``|ds/dt| <= speed``, ``|d2s/dt2| <=
        acceleration`` and (S-curve) ``|d3s/dt3| <= jerk`` (normalised limits [1/s],
        [1/s^2], [1/s^3]; ``inf`` for no motion)."""
        if kind not in PROFILES:
            raise TrajectoryError("profile", f"expected one of {', '.join(PROFILES)}, "
                                  f"got {kind!r}")
        if math.isinf(speed) and math.isinf(acceleration):
            return TimingLaw(kind, 0.0)
        if kind == "s-curve":
            curve = SCurve.fit(1.0, speed, acceleration, jerk)
            return TimingLaw(kind, curve.duration, curve=curve)
        if kind == "quintic":
            duration = max(_QUINTIC_PEAK_SPEED / speed,
                           math.sqrt(_QUINTIC_PEAK_ACCELERATION / acceleration))
            return TimingLaw(kind, duration)
        if speed * speed / acceleration <= 1.0:  # the peak speed is reached: a cruise phase
            ramp = speed / acceleration
            return TimingLaw(kind, 1.0 / speed + ramp, ramp, speed)
        peak = math.sqrt(acceleration)  # a triangle: accelerate, then brake at once
        return TimingLaw(kind, 2.0 / peak, 1.0 / peak, peak)

    def corners(self) -> np.ndarray:
        """The times where ``d2s/dt2`` (trapezoid) or ``d3s/dt3`` (S-curve) jumps [s]."""
        T = self.duration / self.stretch
        if self.curve is not None:
            tj, ta = self.curve.jerk_time, self.curve.ramp
            at = np.array([tj, ta - tj, ta, T - ta, T - ta + tj, T - tj])
        elif self.kind == "trapezoidal":
            at = np.array([self.ramp, T - self.ramp])
        else:
            at = np.zeros(0)
        return at * self.stretch  # type: ignore[no-any-return]

    def stretched(self, factor: float) -> TimingLaw:
        """The same law ``factor`` times slower (``s(t / factor)``; ``factor > 0``)."""
        return TimingLaw(self.kind, self.duration * factor, self.ramp, self.peak, self.curve,
                         self.stretch * factor)

    def __call__(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``s``, ``ds/dt`` [1/s] and ``d2s/dt2`` [1/s^2] at times ``t`` [s] (any shape)."""
        t = np.asarray(t, dtype=float)
        if self.stretch != 1.0:
            k = self.stretch
            s, sd, sdd = replace(self, duration=self.duration / k, stretch=1.0)(t / k)
            outside = (t <= 0.0) | (t >= self.duration)
            return (np.where(t >= self.duration, 1.0, s), np.where(outside, 0.0, sd / k),
                    np.where(outside, 0.0, sdd / (k * k)))
        T = self.duration
        if T <= 0.0:
            return (np.where(t >= 0.0, 1.0, 0.0), np.zeros_like(t), np.zeros_like(t))
        if self.curve is not None:
            return self.curve(t)
        if self.kind == "quintic":
            u = np.clip(t / T, 0.0, 1.0)
            inside = (t > 0.0) & (t < T)
            s = u**3 * (10.0 - 15.0 * u + 6.0 * u * u)
            sd = np.where(inside, 30.0 * u * u * (1.0 - u) ** 2 / T, 0.0)
            sdd = np.where(inside, 60.0 * u * (1.0 - u) * (1.0 - 2.0 * u) / (T * T), 0.0)
            return s, sd, sdd
        ta, v = self.ramp, self.peak
        a = v / ta
        tc = np.clip(t, 0.0, T)
        rise = tc < ta
        fall = tc > T - ta
        s = np.where(rise, 0.5 * a * tc * tc,
                     np.where(fall, 1.0 - 0.5 * a * (T - tc) ** 2, 0.5 * a * ta * ta
                              + v * (tc - ta)))
        sd = np.where(rise, a * tc, np.where(fall, a * (T - tc), v))
        sdd = np.where(rise, a, np.where(fall, -a, 0.0))
        outside = (t <= 0.0) | (t >= T)
        return s, np.where(outside, 0.0, sd), np.where(outside, 0.0, sdd)


@dataclass(frozen=True)
class ReferenceSample:
    """A trajectory at ``m`` times (leading axis).

    Attributes:
        rotation: (m, 3, 3) platform orientation in the base frame.
        translation: (m, 3) platform position in the base frame [m].
        velocity: (m, 3) linear velocity of the platform origin, base frame [m/s].
        angular_velocity: (m, 3) angular velocity, base frame [rad/s].
        acceleration: (m, 3) time derivative of ``velocity`` [m/s^2].
        angular_acceleration: (m, 3) time derivative of ``angular_velocity`` [rad/s^2].
    """

    rotation: np.ndarray
    translation: np.ndarray
    velocity: np.ndarray
    angular_velocity: np.ndarray
    acceleration: np.ndarray
    angular_acceleration: np.ndarray

    @property
    def twist(self) -> np.ndarray:
        """(m, 6) ``(v, w)``."""
        return np.concatenate([self.velocity, self.angular_velocity], axis=-1)

    @property
    def twist_rate(self) -> np.ndarray:
        """(m, 6) ``(dv/dt, dw/dt)``."""
        return np.concatenate([self.acceleration, self.angular_acceleration], axis=-1)


def _positive(value: float | None, field: str) -> float:
    if value is None or isinstance(value, bool):
        raise TrajectoryError(field, f"a positive number is required, got {value!r}")
    v = float(value)
    if not (math.isfinite(v) and v > 0.0):
        raise TrajectoryError(field, f"must be positive and finite, got {value!r}")
    return v


def _pose(rotation: np.ndarray, translation: np.ndarray, which: str
          ) -> tuple[np.ndarray, np.ndarray]:
    """A pose argument as floats: a finite (3,) translation and a (3, 3) rotation.

    Raises:
        TrajectoryError: Naming ``{which}_rotation`` or ``{which}_translation``.
    """
    R = np.asarray(rotation, dtype=float)
    p = np.asarray(translation, dtype=float)
    if R.shape != (3, 3) or not np.all(np.isfinite(R)):
        raise TrajectoryError(f"{which}_rotation", f"expected a finite (3, 3) rotation, got "
                              f"shape {R.shape}" + ("" if R.shape != (3, 3) else " with NaN"))
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise TrajectoryError(f"{which}_translation", f"expected a finite (3,) position [m], "
                              f"got {p.tolist()}")
    try:
        check_rotations(R)
    except ShapeError as exc:
        raise TrajectoryError(f"{which}_rotation", f"not a rotation ({exc.got})") from None
    return R, p


class PoseTrajectory:
    """A reference pose trajectory from a start pose at rest (see the module docstring).

    Args:
        shape: ``"line"``, ``"circle"`` or ``"lemniscate"``.
        profile: ``"quintic"``, ``"trapezoidal"`` or ``"s-curve"``.
        start_rotation: (3, 3) start orientation (base frame).
        start_translation: (3,) start position (base frame) [m].
        speed: Largest platform speed ``|dp/dt|`` [m/s].
        acceleration: Largest tangential acceleration [m/s^2].
        goal_rotation: (3, 3) end orientation of a line.
        goal_translation: (3,) end position of a line [m].
        angular_speed: Largest angular speed of a line [rad/s].
        angular_acceleration: Largest angular acceleration of a line [rad/s^2].
        radius: Radius of the circle, half-width of the lemniscate [m].
        laps: Turns of a closed curve (a positive integer: it ends where it started).
        plane: ``"xy"``, ``"xz"`` or ``"yz"``: the plane of a closed curve.
        jerk: Largest tangential jerk [m/s^3] (the ``"s-curve"`` profile).
        angular_jerk: Largest angular jerk of a line [rad/s^3] (``"s-curve"``).
        peak_acceleration: The largest ``|d2p/dt2|`` of the motion [m/s^2]: the timed
            motion scaled in time to reach it exactly (module docstring); None: as timed.

    Raises:
        TrajectoryError: Naming the parameter at fault.
    """

    def __init__(self, shape: str, profile: str, start_rotation: np.ndarray,
                 start_translation: np.ndarray, speed: float, acceleration: float, *,
                 goal_rotation: np.ndarray | None = None,
                 goal_translation: np.ndarray | None = None,
                 angular_speed: float | None = None, angular_acceleration: float | None = None,
                 radius: float | None = None, laps: int = 1, plane: str = "xy",
                 jerk: float | None = None, angular_jerk: float | None = None,
                 peak_acceleration: float | None = None) -> None:
        if shape not in SHAPES:
            raise TrajectoryError("shape", f"expected one of {', '.join(SHAPES)}, got {shape!r}")
        if profile not in PROFILES:
            raise TrajectoryError("profile", f"expected one of {', '.join(PROFILES)}, "
                                  f"got {profile!r}")
        R0, p0 = _pose(start_rotation, start_translation, "start")
        self.shape = shape
        self.profile = profile
        self.speed = _positive(speed, "speed")
        self.acceleration = _positive(acceleration, "acceleration")
        self.jerk = _positive(jerk, "jerk") if profile == "s-curve" else math.inf
        self._R0 = R0
        self._p0 = p0
        inf = math.inf
        if shape == "line":
            if goal_rotation is None or goal_translation is None:
                raise TrajectoryError("goal", "a line needs a goal pose")
            R1, p1 = _pose(goal_rotation, goal_translation, "goal")
            self._delta = p1 - p0
            self._axis_angle = log_so3(R0.T @ R1)  # body-frame rotation vector
            length = float(np.linalg.norm(self._delta))
            angle = float(np.linalg.norm(self._axis_angle))
            speeds, accels, jerks = [inf], [inf], [inf]
            if length > 0.0:
                speeds.append(self.speed / length)
                accels.append(self.acceleration / length)
                jerks.append(self.jerk / length)
            if angle > 0.0:
                speeds.append(_positive(angular_speed, "angular_speed") / angle)
                accels.append(_positive(angular_acceleration, "angular_acceleration") / angle)
                if profile == "s-curve":
                    jerks.append(_positive(angular_jerk, "angular_jerk") / angle)
            self.timing = TimingLaw.fit(profile, min(speeds), min(accels), min(jerks))
            self.end_rotation = R0 @ exp_so3(self._axis_angle)
            self.end_translation = p0 + self._delta
            self._scale_to(peak_acceleration)
            return
        self.radius = _positive(radius, "radius")
        if isinstance(laps, bool) or not isinstance(laps, int | np.integer) or laps < 1:
            raise TrajectoryError("laps", f"a positive integer is required, got {laps!r}")
        if plane not in PLANES:
            raise TrajectoryError("plane", f"expected one of {', '.join(PLANES)}, got {plane!r}")
        i, j = PLANES[plane]
        self._e1 = np.eye(3)[i]
        self._e2 = np.eye(3)[j]
        self._phi_total = 2.0 * math.pi * int(laps)
        # the largest |dp/dphi|: r on the circle, r sqrt(2) on the lemniscate (at phi = 0)
        peak = self.radius * (1.0 if shape == "circle" else math.sqrt(2.0)) * self._phi_total
        self.timing = TimingLaw.fit(profile, self.speed / peak, self.acceleration / peak,
                                    self.jerk / peak)
        self.end_rotation = R0.copy()
        self.end_translation = p0.copy()
        self._scale_to(peak_acceleration)

    def _scale_to(self, peak_acceleration: float | None) -> None:
        """Scale the timing in time so that the largest ``|d2p/dt2|`` is
        ``peak_acceleration`` (None: leave it)."""
        if peak_acceleration is None:
            return
        target = _positive(peak_acceleration, "peak_acceleration")
        if self.duration <= 0.0:
            return  # no motion: nothing to scale
        reached = self.peak_acceleration()
        if reached <= 0.0:
            raise TrajectoryError("peak_acceleration", "the path has no translation to "
                                  "accelerate (a pure rotation)")
        self.timing = self.timing.stretched(math.sqrt(reached / target))

    def peak_acceleration(self) -> float:
        """The largest ``|d2p/dt2|`` of the platform origin [m/s^2] (sampled at
        :data:`PEAK_SAMPLES` instants over the motion and on both sides of the timing
        law's corners)."""
        corners = self.timing.corners()
        grid = np.linspace(0.0, self.duration, PEAK_SAMPLES)
        times = np.concatenate([grid, corners * (1 - 1e-12), corners * (1 + 1e-12)])
        norms = np.linalg.norm(self.at(times).acceleration, axis=1)
        k = int(np.argmax(norms))
        if k < PEAK_SAMPLES:  # a smooth maximum: refined around its sample
            step = grid[1] - grid[0]
            fine = np.linspace(max(grid[k] - step, 0.0), min(grid[k] + step, self.duration),
                               PEAK_SAMPLES)
            return max(float(norms[k]), float(np.max(np.linalg.norm(
                self.at(fine).acceleration, axis=1))))
        return float(norms[k])

    @property
    def duration(self) -> float:
        """Time from the start to the end of the motion [s]."""
        return self.timing.duration

    def at(self, t: float | np.ndarray) -> ReferenceSample:
        """The reference at times ``t`` [s] (a scalar or an (m,) array): before 0 the start
        pose, after :attr:`duration` the end pose, at rest."""
        times = np.atleast_1d(np.asarray(t, dtype=float))
        s, sd, sdd = self.timing(times)
        m = len(times)
        zeros = np.zeros((m, 3))
        if self.shape == "line":
            rv = self._axis_angle
            rotation = self._R0 @ exp_so3(s[:, None] * rv)
            w_dir = self._R0 @ rv  # the fixed axis times the angle, base frame
            return ReferenceSample(
                rotation, self._p0 + s[:, None] * self._delta, sd[:, None] * self._delta,
                sd[:, None] * w_dir, sdd[:, None] * self._delta, sdd[:, None] * w_dir)
        phi = self._phi_total * s
        dphi = self._phi_total * sd
        ddphi = self._phi_total * sdd
        g, g1, g2 = self._curve(phi)
        velocity = g1 * dphi[:, None]
        acceleration = g2 * (dphi * dphi)[:, None] + g1 * ddphi[:, None]
        rotation = np.broadcast_to(self._R0, (m, 3, 3)).copy()
        return ReferenceSample(rotation, self._p0 + g, velocity, zeros, acceleration,
                               zeros.copy())

    def _curve(self, phi: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The curve's offset from the start position and its first two derivatives with
        respect to ``phi``, each (m, 3)."""
        r, e1, e2 = self.radius, self._e1, self._e2
        c, s = np.cos(phi)[:, None], np.sin(phi)[:, None]
        if self.shape == "circle":
            return (r * ((c - 1.0) * e1 + s * e2), r * (-s * e1 + c * e2),
                    -r * (c * e1 + s * e2))
        c2, s2 = np.cos(2.0 * phi)[:, None], np.sin(2.0 * phi)[:, None]
        return (r * (s * e1 + 0.5 * s2 * e2), r * (c * e1 + c2 * e2),
                -r * (s * e1 + 2.0 * s2 * e2))
