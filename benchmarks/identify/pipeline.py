"""One identification: excitation, record, estimation (no printing, no files).

The record comes from the dynamic world (:mod:`.simulate`, the true robot given as
``truth``, by default the robot file itself) or from a backend that reports forces: a
:class:`~hexapod.backends.base.Backend` with a ``measured_forces()`` method returning the
six drive forces [N] of the last step. The project's own backends report leg lengths only
(:class:`~hexapod.backends.base.BackendStep`), so they are refused, naming that reason.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from benchmarks.identify.simulate import POSITION_GAIN, Record, reference_lengths, run
from hexapod.dynamics.drive_model import quantise
from hexapod.dynamics.identification.base import BaseParameters, base_parameters
from hexapod.dynamics.identification.estimation import Estimate, weighted_least_squares
from hexapod.dynamics.identification.excitation import Excitation, optimise
from hexapod.dynamics.identification.parameters import standard_vector
from hexapod.dynamics.identification.processing import (
    DEFAULT_CUTOFF_HZ,
    DEFAULT_MIN_SPEED,
    Samples,
    samples,
)
from hexapod.dynamics.identification.regressor import regressor
from hexapod.exceptions import BackendError, IdentificationError
from hexapod.geometry import HexapodGeometry

log = logging.getLogger(__name__)

#: ``--backend`` names of the dynamic world (the simulated truth).
WORLD_BACKENDS = ("world", "dynamic-world")


@dataclass
class Settings:
    """How to identify.

    Attributes:
        duration: Excitation length [s].
        seed: Seed of the excitation search and of the sensor noise.
        force_noise: Force noise, a fraction of each leg's RMS force (0.01: 1 %).
        resolution: Encoder resolution [m] (None: the robot file's).
        candidates: Excitation shapes tried by the search.
        cutoff_hz: Zero-phase filter cutoff [Hz].
        min_speed: Leg equations below this leg speed are not used [m/s].
        backend: ``--backend`` spec (:data:`WORLD_BACKENDS` or a backend with forces).
        sample_dt: Sampling period of the record [s].
    """

    duration: float = 20.0
    seed: int = 0
    force_noise: float = 0.01
    resolution: float | None = None
    candidates: int = 16
    cutoff_hz: float = DEFAULT_CUTOFF_HZ
    min_speed: float = DEFAULT_MIN_SPEED
    backend: str = "world"
    sample_dt: float = 1e-3


@dataclass
class Identification:
    """An identification's results."""

    robot: HexapodGeometry
    basis: BaseParameters
    excitation: Excitation
    samples: Samples
    mask: np.ndarray
    estimate: Estimate
    prior: np.ndarray
    truth: np.ndarray | None
    timings: dict[str, float] = field(default_factory=dict)
    record: dict[str, Any] = field(default_factory=dict)


def measured(record: Record, settings: Settings, rng: np.random.Generator
             ) -> tuple[np.ndarray, np.ndarray]:
    """What the sensors read: lengths through the encoders (an encoder zero anywhere
    within a count, then quantised), forces with Gaussian noise of ``force_noise`` times
    each leg's RMS force."""
    res = (np.full(6, settings.resolution) if settings.resolution is not None
           else record.resolution)
    offset = rng.uniform(-0.5, 0.5, 6) * res
    lengths = quantise(record.lengths + offset, res) - offset
    rms = np.sqrt(np.mean(record.forces**2, axis=0))
    forces = record.forces + settings.force_noise * rms * rng.standard_normal(
        record.forces.shape)
    return lengths, forces


#: When a backend's ``measured_forces()`` reading is taken (its ``force_timing``): the
#: mean over the last period, at its middle, or at its end (an instantaneous reading
#: with the lengths).
FORCE_TIMINGS = ("mean", "middle", "end")


def force_timing(backend: Any) -> tuple[str, bool]:
    """The backend's ``force_timing`` (:data:`FORCE_TIMINGS`) and whether it says one
    (``"end"`` when it does not).

    Raises:
        BackendError: A value not in :data:`FORCE_TIMINGS`.
    """
    timing = getattr(backend, "force_timing", None)
    if timing is None:
        return "end", False
    if timing not in FORCE_TIMINGS:
        raise BackendError(f"{type(backend).__name__}.force_timing: {timing!r}; expected one "
                           f"of {', '.join(repr(t) for t in FORCE_TIMINGS)} (when "
                           "measured_forces() is read: the last period's mean, its middle, "
                           "or its end with the lengths)")
    return str(timing), True


def aligned(lengths: np.ndarray, forces: np.ndarray, timing: str
            ) -> tuple[np.ndarray, np.ndarray]:
    """The readings of :func:`record_backend` at the same instants: a reading of a
    period's mean or middle (``timing``) belongs half a period before the lengths read at
    the period's end, so the force at those lengths is the mean of two consecutive
    readings (second-order accurate), the last sample dropped; an ``"end"`` reading is
    the lengths' instant already."""
    if timing == "end":
        return lengths, forces
    return lengths[:-1], 0.5 * (forces[:-1] + forces[1:])


def record_backend(backend: Any, robot: HexapodGeometry, excitation: Excitation,
                   duration: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Run the excitation on a backend that reports forces (a position loop on its
    encoders, leg velocities as commands); returns the lengths and forces (N, 6).

    Every reading is checked before a command is made of it (the study loop's
    :func:`benchmarks.sim.plant.reading_problem`: six finite lengths where the robot's legs
    can be; six finite forces): a bad one stops the run at once, the caller's ``with``
    halting the robot, never a command computed from it.

    Raises:
        BackendError: A reading that cannot be the robot's, naming the sample, the leg
            and the value.
    """
    from hexapod.plausible import reading_problem

    q_ref = reference_lengths(robot, excitation, duration, dt)
    qd_ref = np.gradient(q_ref, dt, axis=0)
    q = np.asarray(backend.measured_lengths(), float)
    lengths, forces = [], []
    for k in range(q_ref.shape[0] - 1):
        if (problem := reading_problem(q, robot.stroke)) is not None:
            raise BackendError(f"sample {k} ({k * dt:.3f} s): {problem}; stopped, nothing "
                               "commanded from it")
        step = backend.step(qd_ref[k] + POSITION_GAIN * (q_ref[k] - q), dt)
        q = np.asarray(step.lengths, float)
        f = np.asarray(backend.measured_forces(), float)
        if f.shape != (6,) or not np.isfinite(f).all():
            what = (f"forces of shape {f.shape}, not six" if f.shape != (6,) else
                    f"leg {int(np.argmin(np.isfinite(f)))}'s force as "
                    f"{f[np.argmin(np.isfinite(f))]} [N] (forces {f})")
            raise BackendError(f"sample {k} ({k * dt:.3f} s): the backend measured {what}; "
                               "stopped")
        lengths.append(q)
        forces.append(f)
    if (problem := reading_problem(q, robot.stroke)) is not None:
        raise BackendError(f"last sample: {problem}")
    return np.array(lengths), np.array(forces)


#: The largest fraction of the world's samples with a drive at its force limit that an
#: identification accepts (those forces are the limit's, not the dynamics').
SATURATED_FRACTION = 0.01


def check_backend(spec: str) -> None:
    """Refuse a backend that cannot report forces, before anything runs.

    Raises:
        BackendError: Naming the backend and why.
    """
    if spec in WORLD_BACKENDS:
        return
    from hexapod.backends.registry import backends

    name, _, _ = backends.resolve(spec)
    builtin = {"sim": "the kinematic simulator has no mass and no drives",
               "emulator": "the emulated boards' protocol reports positions only, even with "
                           "--dynamics (no force or current reading)",
               "serial": "the serial protocol (docs/serial-protocol.md) reports positions only",
               "gcs": "the GCS protocol reports positions only",
               "gcs-emulator": "the GCS protocol reports positions only"}
    reason = builtin.get(name)
    if reason is not None:
        raise BackendError(f"--backend {spec}: cannot identify the dynamics: {reason}; the "
                           "identification needs the drive forces (use --backend world, the "
                           "dynamic world, or a backend with measured_forces())")


def identify(robot: HexapodGeometry, settings: Settings,
             truth: HexapodGeometry | None = None) -> Identification:
    """Identify ``robot`` (the robot file: limits, prior) on the dynamic world whose true
    robot is ``truth`` (default ``robot``) or on ``settings.backend``.

    Raises:
        BackendError: A backend without forces.
        IdentificationError: The data cannot determine the parameters.
    """
    check_backend(settings.backend)
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    basis = base_parameters(robot, seed=settings.seed)
    timings["base_parameters_s"] = time.perf_counter() - t0
    t1 = time.perf_counter()
    excitation = optimise(robot, basis, seed=settings.seed,
                          candidates=settings.candidates)
    timings["excitation_s"] = time.perf_counter() - t1
    t1 = time.perf_counter()
    rng = np.random.default_rng([settings.seed, 38])
    info: dict[str, Any] = {"backend": settings.backend, "duration_s": settings.duration,
                            "sample_dt_s": settings.sample_dt,
                            "cutoff_hz": settings.cutoff_hz}
    true_theta = None
    if settings.backend in WORLD_BACKENDS:
        world = truth if truth is not None else robot
        rec = run(world, excitation, settings.duration, settings.sample_dt)
        n = len(rec.lengths)
        if rec.saturated > SATURATED_FRACTION * n:  # forces at a limit measure no dynamics
            raise IdentificationError(
                f"{world.source or world.name}: the drives were at their force limit in "
                f"{rec.saturated} of {n} samples ({100 * rec.saturated / n:.0f} %): the robot "
                "cannot follow the excitation, and a force at its limit says nothing of the "
                "masses (check [drives] force_limit and [inertia] of the robot file"
                + (" and --truth" if truth is not None else "") + ")")
        lengths, forces = measured(rec, settings, rng)
        true_theta = standard_vector(world.inertia, world.drives)
        info.update({"saturated_samples": rec.saturated,
                     "force_noise_fraction": settings.force_noise,
                     "encoder_resolution_m": (settings.resolution if settings.resolution
                                              is not None else rec.resolution.tolist()),
                     "true_robot": world.source or world.name})
    else:
        from hexapod.backends.registry import open_backend

        R0, t0_ = excitation.poses(robot, np.zeros(1))
        from hexapod.dynamics.identification.excitation import legs

        start = legs(R0, t0_, robot.base_points[None], robot.platform_points[None])[0][0]
        with open_backend(settings.backend, robot, start) as backend:
            if not callable(getattr(backend, "measured_forces", None)):
                raise BackendError(f"--backend {settings.backend}: {type(backend).__name__} "
                                   "has no measured_forces(): it cannot report the drive "
                                   "forces the identification needs")
            timing, declared = force_timing(backend)
            lengths, forces = aligned(*record_backend(backend, robot, excitation,
                                                      settings.duration, settings.sample_dt),
                                      timing)
        info.update({"force_timing": timing, "force_timing_declared": declared})
    timings["record_s"] = time.perf_counter() - t1
    t1 = time.perf_counter()
    s = samples(robot, settings.sample_dt, lengths, forces, settings.cutoff_hz)
    Y, _, _ = regressor(robot, s.R, s.t, s.twist, s.acc)
    mask = s.mask(settings.min_speed)
    prior = standard_vector(robot.inertia, robot.drives)
    est = weighted_least_squares(basis.columns(Y), s.forces, basis, prior, robot.inertia,
                                 robot.drives, mask, q_min=robot.stroke[0])
    timings["estimation_s"] = time.perf_counter() - t1
    timings["total_s"] = time.perf_counter() - t0
    return Identification(robot, basis, excitation, s, mask, est, prior, true_theta,
                          timings, info)
