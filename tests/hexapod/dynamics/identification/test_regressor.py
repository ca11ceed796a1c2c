"""The identification model against the dynamic model it is derived from."""

from __future__ import annotations

import numpy as np
import pytest

from hexapod.dynamics import DynamicModel
from hexapod.dynamics.drive_model import COULOMB_SMOOTHING
from hexapod.dynamics.identification.base import random_states
from hexapod.dynamics.identification.parameters import (
    N_MECHANISM,
    N_STANDARD,
    standard_vector,
    to_tables,
)
from hexapod.dynamics.identification.regressor import regressor
from hexapod.geometry import HexapodGeometry, preset


def lopsided() -> HexapodGeometry:
    """DeltaLab with an off-axis centre of mass, products of inertia, uneven drives."""
    g = preset("deltalab")
    inertia = g.inertia.replace(
        platform_mass=2.6, platform_com=np.array([0.015, -0.010, 0.008]),
        platform_inertia=np.array([0.016, 0.021, 0.030, 0.002, -0.0015, 0.001]),
        body_mass=0.6, rod_mass=0.25, rod_com=0.12)
    drives = g.drives.replace(rotor_inertia=np.array([2.2, 2.5, 2.8, 2.4, 2.6, 2.3]),
                              viscous=np.array([45.0, 50.0, 55.0, 60.0, 48.0, 52.0]),
                              coulomb=np.array([4.0, 5.0, 6.0, 4.5, 5.5, 5.0]))
    return g.replace(inertia=inertia, drives=drives)


@pytest.mark.parametrize("robot", [preset("deltalab"), lopsided()], ids=["deltalab", "lopsided"])
def test_regressor_times_true_parameters_is_the_inverse_dynamics(robot: HexapodGeometry) -> None:
    """``Y theta`` = ``DynamicModel.inverse_batch`` plus the drives' rotor inertia,
    viscous and Coulomb friction, to rounding, at random states."""
    R, t, twist, acc = random_states(robot, 200, np.random.default_rng(3))
    Y, qd, qdd = regressor(robot, R, t, twist, acc)
    assert Y.shape == (200, 6, N_STANDARD)
    d = robot.drives
    expected = (DynamicModel(robot).inverse_batch(R, t, twist, acc) + d.rotor_inertia * qdd
                + d.viscous * qd + d.coulomb * np.tanh(qd / COULOMB_SMOOTHING))
    got = Y @ standard_vector(robot.inertia, robot.drives)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-10 * np.abs(expected).max())


def test_mechanism_columns_match_the_pinocchio_closed_chain() -> None:
    """The mechanism's part against the independent Pinocchio implementation
    (``constraintDynamics`` on the closed chain) at a few states."""
    robot = lopsided()
    R, t, twist, acc = random_states(robot, 4, np.random.default_rng(5))
    Y, _, _ = regressor(robot, R, t, twist, acc)
    theta = standard_vector(robot.inertia, robot.drives)
    pin = DynamicModel(robot, method="pinocchio")
    for k in range(4):
        f = pin.inverse(R[k], t[k], twist[k], acc[k])
        np.testing.assert_allclose(Y[k, :, :N_MECHANISM] @ theta[:N_MECHANISM], f,
                                   rtol=0, atol=1e-7 * np.abs(f).max())


def test_standard_parameters_round_trip_through_the_tables() -> None:
    """``to_tables(standard_vector(...))`` gives the same tables back."""
    robot = lopsided()
    theta = standard_vector(robot.inertia, robot.drives)
    inertia, drives = to_tables(theta, robot.inertia, robot.drives)
    np.testing.assert_allclose(standard_vector(inertia, drives), theta, rtol=1e-12, atol=1e-15)
    assert inertia.platform_mass == pytest.approx(2.6)
    np.testing.assert_allclose(inertia.platform_com, [0.015, -0.010, 0.008], atol=1e-15)
    np.testing.assert_allclose(drives.coulomb, robot.drives.coulomb)
