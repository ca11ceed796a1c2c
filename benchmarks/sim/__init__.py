"""The simulated closed loop: the truth of each trial (:mod:`benchmarks.sim.world`), what
the camera gives (:mod:`benchmarks.sim.sensors`), the plants (:mod:`benchmarks.sim.plant`),
the one closed loop (:mod:`benchmarks.sim.loop`, also run by the servo session) and
:func:`run_trials`, which runs a work unit through it (:mod:`benchmarks.sim.stepper`).
The simulator reads a scenario through :mod:`benchmarks.sim.inputs` and imports nothing of
:mod:`benchmarks.study`."""

from benchmarks.sim.book import MAX_REFUSED_STEPS, TrialResult
from benchmarks.sim.sensors import GeometricSensor, make_sensor, trial_goal
from benchmarks.sim.stepper import run_trials
from benchmarks.sim.world import (
    TrialSetup,
    World,
    load_camera,
    load_geometry,
    make_trial,
    make_trials,
    trial_rng,
)

__all__ = [
    "MAX_REFUSED_STEPS", "GeometricSensor", "TrialResult", "TrialSetup", "World",
    "load_camera", "load_geometry", "make_sensor", "make_trial", "make_trials", "run_trials",
    "trial_goal", "trial_rng",
]
