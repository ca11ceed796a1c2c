"""How the six drives behave in simulation, batched over trials (numpy).

The parameters are those of the robot file (:class:`~hexapod.dynamics.drives.DriveParameters`);
this module is their behaviour, the force each drive puts on its leg:

- **velocity mode** (a commercial drive's inner loop): a PI controller on the leg
  velocity, ``u = kp (v_set - v) + I``, ``dI/dt = ki (v_set - v)``, its output clipped at
  the force limit. Anti-windup by conditional integration: the integral does not grow
  while the output is saturated in the direction of the error, and is itself kept within
  the force limit. The gains are tuned on the inertia the drive moves (``tuned_mass``:
  the reflected rotor inertia plus the mechanism's inertia seen by the leg) and its
  viscous friction so that the closed loop ``(kp s + ki) / (m s^2 + (kp + c) s + ki)``
  has its -3 dB point at the stated bandwidth, with the integral's corner
  ``ki / kp`` a tenth of it (:func:`tune_velocity_loop`);
- **force mode** (torque mode): the commanded force, clipped at the force limit, with a
  servo amplifier's speed limit in torque mode: within the leg speed limit ``v_max`` the
  command passes unchanged; beyond it the velocity loop's proportional term of the
  excess is subtracted, ``F - kp (|v| - v_max) sign(v)`` (clipped at the force limit),
  so a leg pushed along its motion by ``F`` more than holds it (the drive's force and
  the load's share) settles ``F / kp`` past ``v_max`` (the proportional limiter's
  droop). The drive is at its force limit when the force it applies is;
- **friction**: viscous ``c v`` plus a *smooth* Coulomb force ``f_c tanh(v / v_s)``
  (:data:`COULOMB_SMOOTHING` ``v_s`` = 0.1 mm/s), not stick-slip. The plant integrates
  friction implicitly as the damping ``c + f_c tanh(v / v_s) / v`` (its secant, in
  :attr:`DriveForces.slope`): it can slow a leg to rest but never reverse it within a
  step, whatever the step; a leg whose drive force ``F`` is below ``f_c`` creeps at
  ``v_s atanh(F / f_c)`` instead of sticking (under ``v_s`` up to 76 % of ``f_c``);
- the **reflected rotor inertia** is a mass on the leg's translation (the plant adds
  ``m_r`` to the mechanism's inertia seen by the leg);
- **encoders**: the measured length is quantised to the encoder resolution, rounded to
  the nearest count (:func:`quantise`).

Every array is (n, 6): rows are trials, columns legs. Forces are positive when they push
the platform away from the base (lengthen the leg).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from hexapod.dynamics.drives import DriveParameters

log = logging.getLogger(__name__)

#: Velocity scale of the smooth Coulomb friction ``f_c tanh(v / v_s)`` [m/s].
COULOMB_SMOOTHING = 1e-4
#: Corner of the integral action as a fraction of the velocity bandwidth (``ki / kp``).
INTEGRAL_CORNER = 0.1


def closed_loop_gain(omega: np.ndarray, mass: np.ndarray, viscous: np.ndarray,
                     kp: np.ndarray, ki: np.ndarray) -> np.ndarray:
    """``|H(j omega)|`` of the PI velocity loop on a mass with viscous friction.

    Args:
        omega: Angular frequency [rad/s].
        mass: Moved mass [kg].
        viscous: Viscous friction [N s/m].
        kp: Proportional gain [N s/m].
        ki: Integral gain [N/m].
    """
    s = 1j * omega
    return np.abs((kp * s + ki) / (mass * s**2 + (kp + viscous) * s + ki))  # type: ignore[no-any-return]


def tune_velocity_loop(mass: np.ndarray, viscous: np.ndarray, bandwidth_hz: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray]:
    """The PI gains whose closed velocity loop has its -3 dB point at ``bandwidth_hz``.

    Args:
        mass: Moved mass per leg [kg], positive.
        viscous: Viscous friction per leg [N s/m].
        bandwidth_hz: Bandwidth per leg [Hz], positive.

    Returns:
        ``(kp [N s/m], ki [N/m])``, with ``ki = kp * INTEGRAL_CORNER * omega_b``.
    """
    m, c, wb = np.broadcast_arrays(np.asarray(mass, float), np.asarray(viscous, float),
                                   2 * np.pi * np.asarray(bandwidth_hz, float))
    wi = INTEGRAL_CORNER * wb
    target = 1 / np.sqrt(2)
    lo = np.zeros_like(m)  # the gain at omega_b rises with kp (0 at kp = 0, 1 at infinity)
    hi = np.maximum(10 * m * wb, 1.0)
    while np.any(closed_loop_gain(wb, m, c, hi, hi * wi) < target):
        hi = np.where(closed_loop_gain(wb, m, c, hi, hi * wi) < target, 10 * hi, hi)
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        low = closed_loop_gain(wb, m, c, mid, mid * wi) < target
        lo = np.where(low, mid, lo)
        hi = np.where(low, hi, mid)
    kp = 0.5 * (lo + hi)
    return kp, kp * wi


def quantise(lengths: np.ndarray, resolution: np.ndarray) -> np.ndarray:
    """Encoder readings: ``lengths`` [m] rounded to the nearest multiple of ``resolution``
    [m] per leg (a zero resolution reads exactly)."""
    res = np.asarray(resolution, float)
    counted = res > 0
    # np.rint: np.round's halves to even (its own call for no decimals), without its
    # wrappers (two calls every period of the dynamic world)
    if counted.all():  # every leg counted (the common case): no selection
        return np.rint(lengths / res) * res  # type: ignore[no-any-return]
    safe = np.where(counted, res, 1.0)
    return np.where(counted, np.rint(lengths / safe) * safe, lengths)  # type: ignore[no-any-return]


@dataclass
class DriveForces:
    """The drives' output over one physics step.

    Attributes:
        motor: (n, 6) force of the drive on its leg [N] (within the force limit).
        friction: (n, 6) friction force opposing the leg's motion [N].
        slope: (n, 6) how ``motor - friction`` changes with the leg velocity [N s/m]
            (non-positive): the proportional gain while not saturated (velocity mode) or
            while holding the speed limit (force mode), and the friction's secant
            damping; the plant takes this part implicitly.
        saturated: (n, 6) whether the drive is at its force limit (the force it applies,
            not its command).
    """

    motor: np.ndarray
    friction: np.ndarray
    slope: np.ndarray
    saturated: np.ndarray


class DriveModel:
    """The six drives of ``n`` trials (rows), each row with its own parameters and gains.

    Args:
        params: One :class:`DriveParameters` for every row, or one per row.
        tuned_mass: (6,) or (n, 6) inertia each velocity loop is tuned on [kg] (the
            rotor's plus the mechanism's seen by the leg).
        n: Number of rows.
        speed_limit: (n,) or (n, 6) each leg's speed limit in force mode [m/s], finite
            and positive (the robot's ``max_speed``; None: the command is not held to
            a speed).
    """

    def __init__(self, params: DriveParameters | list[DriveParameters], tuned_mass: np.ndarray,
                 n: int, speed_limit: np.ndarray | None = None) -> None:
        plist = params if isinstance(params, list) else [params] * n
        if len(plist) != n:
            raise ValueError(f"params: expected {n} drive parameter sets, got {len(plist)}")
        modes = {p.mode for p in plist}
        if len(modes) != 1:
            raise ValueError(f"params: one drive mode for every row, got {sorted(modes)}")
        self.mode = modes.pop()

        def stack(key: str) -> np.ndarray:
            return np.array([getattr(p, key) for p in plist], dtype=float).reshape(n, 6)

        self.force_limit = stack("force_limit")
        self.rotor_inertia = stack("rotor_inertia")
        self.viscous = stack("viscous")
        self.coulomb = stack("coulomb")
        self.encoder_resolution = stack("encoder_resolution")
        bandwidth = stack("velocity_bandwidth")
        mass = np.broadcast_to(np.asarray(tuned_mass, float), (n, 6))
        self.kp, self.ki = tune_velocity_loop(mass, self.viscous, bandwidth)
        #: (n, 6) the legs' speed limit in force mode [m/s] (infinite: none).
        self.speed_limit = np.full((n, 6), np.inf)
        if speed_limit is not None:
            limit = np.asarray(speed_limit, float)
            limit = np.broadcast_to(limit[:, None] if limit.ndim == 1 else limit, (n, 6))
            if not (np.all(np.isfinite(limit)) and np.all(limit > 0)):
                raise ValueError("speed_limit: expected finite positive leg speeds [m/s], "
                                 f"got {limit.min()} to {limit.max()}")
            self.speed_limit[:] = limit
        #: (n, 6) state of the integral action [N].
        self.integral = np.zeros((n, 6))

    def hold(self, rows: np.ndarray, forces: np.ndarray) -> None:
        """Start rows ``rows`` holding ``forces`` [N] (the integral preloaded, as a drive
        that has been holding the robot still: gravity is carried from the start)."""
        self.integral[rows] = np.clip(forces, -self.force_limit[rows], self.force_limit[rows])

    def forces(self, rows: np.ndarray, setpoints: np.ndarray, velocities: np.ndarray,
               h: float) -> DriveForces:
        """The drives' forces over one physics step, and the integral advanced by ``h``.

        Args:
            rows: (n,) row indices.
            setpoints: (n, 6) leg velocity setpoints [m/s] (velocity mode) or leg forces
                [N] (force mode).
            velocities: (n, 6) leg velocities now [m/s].
            h: Physics step [s].
        """
        limit = self.force_limit[rows]
        v = velocities
        x = v / COULOMB_SMOOTHING
        small = np.abs(x) < 1e-8
        secant = np.where(small, 1.0, np.tanh(x) / np.where(small, 1.0, x))  # tanh(x) / x
        # friction = d_friction * v: a velocity-dependent damping, taken implicitly
        d_friction = self.viscous[rows] + self.coulomb[rows] / COULOMB_SMOOTHING * secant
        friction = self.viscous[rows] * v + self.coulomb[rows] * np.tanh(x)
        kp = self.kp[rows]
        if self.mode == "force":  # the command, held to the speed limit (module docstring)
            vmax = self.speed_limit[rows]
            beyond = np.maximum(v - vmax, 0.0) + np.minimum(v + vmax, 0.0)
            held = np.clip(setpoints, -limit, limit) - kp * beyond
            saturated = np.abs(held) >= limit  # the force applied at the limit
            governed = ((v > vmax) | (v < -vmax)) & ~saturated
            return DriveForces(np.clip(held, -limit, limit), friction,
                               -np.where(governed, kp, 0.0) - d_friction, saturated)
        err = setpoints - v
        integral = self.integral[rows]
        u = kp * err + integral
        motor = np.clip(u, -limit, limit)
        saturated = np.abs(u) >= limit
        winding = saturated & (np.sign(err) == np.sign(u))
        integral = np.where(winding, integral, integral + self.ki[rows] * err * h)
        self.integral[rows] = np.clip(integral, -limit, limit)
        slope = -np.where(saturated, 0.0, kp) - d_friction
        return DriveForces(motor, friction, slope, saturated)
