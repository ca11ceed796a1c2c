"""The dynamic world's identification run against the identification model."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.identify.simulate import run
from hexapod.dynamics.identification.excitation import Excitation
from hexapod.dynamics.identification.parameters import standard_vector
from hexapod.dynamics.identification.regressor import regressor
from hexapod.geometry import preset


@pytest.mark.slow
def test_recorded_forces_are_the_model_at_the_true_states() -> None:
    """At the true states, the recorded drive forces are the identification model's with
    the true parameters, within 1 % of their RMS where the legs move (the rest: the
    integrator's implicit friction and the drives' reaction within a step)."""
    robot = preset("deltalab")
    rng = np.random.default_rng(0)
    a = 0.004 * rng.standard_normal((6, 3))
    a[3:] *= 3
    b = 0.004 * rng.standard_normal((6, 3))
    b[3:] *= 3
    excitation = Excitation(a, b, 0.5, np.nan, {})
    rec = run(robot, excitation, 3.0)
    assert rec.saturated == 0
    Y, qd, _ = regressor(robot, rec.R, rec.t, rec.twist, rec.acc)
    model = Y @ standard_vector(robot.inertia, robot.drives)
    moving = np.abs(qd) > 2e-3
    assert moving.mean() > 0.3
    residual = (rec.forces - model)[moving]
    rms = np.sqrt(np.mean(rec.forces[moving] ** 2))
    assert np.sqrt(np.mean(residual**2)) < 0.01 * rms
