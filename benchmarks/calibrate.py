"""Calibrate-then-control: the scenario option ``[calibration] method = "linear"``."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from benchmarks.scenario import Scenario

CalibrationHook = Callable[..., tuple[np.ndarray, dict[str, float]]]


def calibration_hook(sc: Scenario) -> CalibrationHook | None:
    """The per-trial calibration function of a scenario, or None when it does not calibrate."""
    if sc.calibration.method == "none":
        return None
    from benchmarks.simulate import World

    def calibrate(world: World, rng: np.random.Generator) -> tuple[np.ndarray,
                                                                  dict[str, float]]:
        from vision.calibration import calibrate_in_world

        return calibrate_in_world(world.geometry, world.camera, sc.calibration, sc.noise, rng)

    return calibrate
