"""The excitation run in the dynamic world (the simulated truth).

The true robot (:class:`hexapod.dynamics.robots.DynamicRobots`: the closed-chain
mechanism, velocity-mode drives with their PI loops, friction and reflected rotor
inertia, integrated at ``physics_dt``) follows the excitation's leg lengths with a
position loop (proportional, :data:`POSITION_GAIN`, plus the reference leg rates as
feed-forward) whose output is the drives' velocity setpoint, as a lab's motion controller
drives it. Recorded at every physics step: the encoders' lengths (quantised to the
resolution) and the force each drive applied over the step. The plant integrates the
drives' velocity-dependent forces implicitly (:mod:`hexapod.dynamics.robots`), so the
force that acted over step ``k`` is the motor's plus its velocity slope times the
step's change of leg rate; that is what a force sensor in series with the leg reads.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from hexapod.dynamics.drive_model import quantise
from hexapod.dynamics.identification.excitation import Excitation, legs
from hexapod.dynamics.robots import DynamicRobots
from hexapod.exceptions import BackendError
from hexapod.geometry import HexapodGeometry

log = logging.getLogger(__name__)

#: Position loop gain [1/s] (10 Hz).
POSITION_GAIN = 2 * np.pi * 10.0


@dataclass
class Record:
    """A recorded excitation.

    Attributes:
        time_step: Sampling period [s].
        lengths: (N, 6) true leg lengths [m] (before the encoders).
        forces: (N, 6) true drive forces [N] (before any noise).
        resolution: (6,) encoder resolution [m].
        saturated: Samples where a drive was at its force limit.
        R, t, twist: (N, ...) the true platform states at the samples (for tests).
        acc: (N, 6) the true platform acceleration over every step.
    """

    time_step: float
    lengths: np.ndarray
    forces: np.ndarray
    resolution: np.ndarray
    saturated: int
    R: np.ndarray
    t: np.ndarray
    twist: np.ndarray
    acc: np.ndarray


def reference_lengths(geometry: HexapodGeometry, excitation: Excitation, duration: float,
                      h: float) -> np.ndarray:
    """The excitation's leg lengths (N + 1, 6) [m] at ``k h``, ``k = 0..N``."""
    n = round(duration / h)
    time_s = np.arange(n + 1) * h
    R, t = excitation.poses(geometry, time_s)
    q, _, _ = legs(R, t, np.broadcast_to(geometry.base_points, (n + 1, 6, 3)),
                   np.broadcast_to(geometry.platform_points, (n + 1, 6, 3)))
    return q


def run(truth: HexapodGeometry, excitation: Excitation, duration: float,
        sample_dt: float = 1e-3, physics_dt: float = 2e-5) -> Record:
    """Run the excitation on the true robot ``truth`` (module docstring), sampled every
    ``sample_dt`` [s] (the position loop's period too), integrated at ``physics_dt``.

    The sample of period ``k`` is the state at the start of the period's middle physics
    step and the force over that step (an instantaneous reading: the implicit integration
    of the friction's steep Coulomb curve differs from the continuous law by
    ``O(physics_dt)``, hence the fine physics step).

    Raises:
        BackendError: The drives are in force mode, or the robot diverged.
    """
    if truth.drives.mode != "velocity":
        raise BackendError(f"{truth.source or truth.name}: key 'drives.mode': "
                           f"{truth.drives.mode!r}; the dynamic world's identification run "
                           "drives velocity-mode drives (mode = \"velocity\", the default)")
    sub = max(1, round(sample_dt / physics_dt))
    h = sample_dt / sub
    q_ref = reference_lengths(truth, excitation, duration, sample_dt)
    qd_ref = np.gradient(q_ref, sample_dt, axis=0)
    n = q_ref.shape[0] - 1
    R0, t0 = excitation.poses(truth, np.zeros(1))
    robots = DynamicRobots([truth], R0.copy(), t0.copy())
    rows = np.array([0])
    res = np.asarray(truth.drives.encoder_resolution, float)
    A = truth.base_points[None]
    E = truth.platform_points[None]
    lengths = np.empty((n, 6))
    forces = np.empty((n, 6))
    kp = robots.drives.kp[0]
    limit = robots.drives.force_limit[0]
    saturated = 0
    Rs, ts, tws, accs = np.empty((n, 3, 3)), np.empty((n, 3)), np.empty((n, 6)), np.empty((n, 6))
    mid = sub // 2
    for k in range(n):
        # the position loop runs once per sample period, on the encoders (read at the
        # period's start); the sample is taken mid-period, where the drives' force is
        # its period average to first order (their PI loop reacts to each new setpoint)
        q = legs(robots.R, robots.t, A, E)[0][0]
        v = (qd_ref[k] + POSITION_GAIN * (q_ref[k] - quantise(q, res)))[None]
        if mid and robots.advance(rows, v, h, mid).any():
            raise BackendError(f"the dynamic robot diverged at {k * sample_dt:.3f} s")
        q, u, r = legs(robots.R, robots.t, A, E)
        K = np.concatenate([u[0], np.cross(r[0], u[0])], axis=1)
        tw0 = robots.twist[0].copy()
        Rs[k], ts[k], lengths[k] = robots.R[0], robots.t[0], q[0]
        if robots.advance(rows, v, h, 1).any():
            raise BackendError(f"the dynamic robot diverged at {k * sample_dt:.3f} s")
        tws[k], accs[k] = tw0, (robots.twist[0] - tw0) / h
        motor = robots.forces[0]
        at_limit = np.abs(motor) >= limit
        saturated += int(at_limit.any())
        # the force over the step: the motor's, with its implicit velocity slope
        forces[k] = motor - np.where(at_limit, 0.0, kp) * (K @ (robots.twist[0] - tw0))
        rest = sub - mid - 1
        if rest and robots.advance(rows, v, h, rest).any():
            raise BackendError(f"the dynamic robot diverged at {k * sample_dt:.3f} s")
    return Record(sample_dt, lengths, forces, res, saturated, Rs, ts, tws, accs)
