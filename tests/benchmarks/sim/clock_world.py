"""Shared set-up of the camera-clock tests (test_clock.py, test_clock_exposure.py): a
controller that records the times of its observations, and a two-trial kinematic world
(the true plant and the camera clock over the same pose arrays) with one constant leg
velocity command per trial."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from benchmarks.sim.clock import CameraClock
from benchmarks.sim.plant import KinematicPlant
from benchmarks.sim.sensors import camera_batch
from benchmarks.sim.world import load_camera, load_geometry, make_trials
from controllers.base import Command, Controller, ControllerContext, Observation, ObservationBatch
from hexapod import HexapodGeometry

#: The controller spec of :class:`Recorder` in a scenario table.
RECORDER = "tests.benchmarks.sim.clock_world:Recorder"

#: The commanded leg velocities of the two trials [m/s].
VELOCITIES = np.array([[0.01, -0.02, 0.015, 0.0, 0.005, -0.01],
                       [-0.01, 0.0, 0.02, 0.01, 0.0, 0.0]])


class Recorder(Controller):
    """Records the times of the observations it gets; commands a slow constant motion."""

    name = "recorder"
    features = frozenset({"lengths"})
    seen: ClassVar[list[tuple[float, float | None]]] = []

    def __init__(self, gain: float = 0.0) -> None:
        self.gain = gain

    def reset(self, context: ControllerContext) -> None:
        pass

    def step(self, observation: Observation) -> Command:
        Recorder.seen.append((observation.t, observation.image_t))
        return Command(np.full(6, 1e-3))


@dataclass
class ClockWorld:
    """Trials 0 and 1 of a scenario at their start poses: ``plant`` and ``clock`` share
    the live arrays ``q`` [m], ``R``, ``t`` [m] (the plant moves them in place);
    ``start`` is a copy of them at the start."""

    sc: Any
    geometry: HexapodGeometry
    q: np.ndarray
    R: np.ndarray
    t: np.ndarray
    start: tuple[np.ndarray, np.ndarray, np.ndarray]
    plant: KinematicPlant
    clock: CameraClock
    rows: np.ndarray

    def advance(self) -> None:
        """Move the plant one control period with :data:`VELOCITIES`."""
        self.plant.advance(self.rows, VELOCITIES, self.sc.dt)

    def moved_from_start(self, duration: float) -> KinematicPlant:
        """A fresh plant started at ``start`` and moved ``duration`` [s] with
        :data:`VELOCITIES` (where the robot is that long after the start)."""
        g = self.geometry
        part = KinematicPlant(*(a.copy() for a in self.start), g.base_points,
                              g.platform_points, g.stroke, g.max_speed)
        part.advance(self.rows, VELOCITIES, duration)
        return part


def frame(n: int) -> ObservationBatch:
    """A camera batch of ``n`` rows, every edge seen (the clock tests' sensor output)."""
    return camera_batch(np.zeros((n, 6, 2, 3)), None, np.zeros((n, 6, 3)),
                        np.ones((n, 6, 2), dtype=bool), np.ones((n, 6), dtype=bool))


def clock_world(sc: Any) -> ClockWorld:
    """The two-trial world of scenario ``sc`` (see :class:`ClockWorld`)."""
    g = load_geometry(sc)
    setups = make_trials(sc, [0, 1], g, load_camera(sc, g))
    q = np.array([s.start_lengths for s in setups])
    R = np.array([s.start_rotation for s in setups])
    t = np.array([s.start_translation for s in setups])
    start = (q.copy(), R.copy(), t.copy())
    plant = KinematicPlant(q, R, t, g.base_points, g.platform_points, g.stroke, g.max_speed)
    clock = CameraClock(sc, setups, q, R, t, g.base_points, g.platform_points)
    return ClockWorld(sc, g, q, R, t, start, plant, clock, np.arange(2))
