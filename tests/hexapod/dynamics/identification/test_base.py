"""Base parameters by QR: what the leg forces can and cannot determine."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hexapod.dynamics.identification.base import base_parameters, random_states
from hexapod.dynamics.identification.parameters import N_STANDARD
from hexapod.dynamics.identification.regressor import regressor
from hexapod.geometry import preset


def test_base_parameters_of_the_deltalab() -> None:
    """31 base parameters; the body's mass and the axial inertias never enter; the rods'
    mass regroups with the platform's (a point mass at each platform joint)."""
    b = base_parameters(preset("deltalab"))
    assert b.size == 31
    assert set(b.unidentifiable) == {"m_b", "Ia_b", "Ia_r"}
    assert b.names[0] == "m_p + 6 m_r"
    assert "It_r + It_b" in b.names  # (no coefficient 1 written)
    assert all(f"rotor_{i}" in b.names and f"coulomb_{i}" in b.names for i in range(6))


def test_base_regressor_reproduces_the_standard_model_for_any_parameters() -> None:
    """At new random states and for random (even non-physical) standard parameters,
    ``Y theta == Y_base theta_base``: the regrouping is exact."""
    g = preset("deltalab")
    b = base_parameters(g)
    R, t, twist, acc = random_states(g, 50, np.random.default_rng(11))
    Y, _, _ = regressor(g, R, t, twist, acc)
    rng = np.random.default_rng(2)
    for _ in range(3):
        theta = rng.standard_normal(N_STANDARD)
        full = Y @ theta
        np.testing.assert_allclose(b.columns(Y) @ b.of(theta), full, rtol=0,
                                   atol=1e-9 * np.abs(full).max())


def test_standard_split_keeps_the_prior_where_the_forces_cannot_see() -> None:
    """``standard(of(theta), prior)`` has the base parameters of ``theta`` and the
    prior's inseparable ones."""
    b = base_parameters(preset("deltalab"))
    rng = np.random.default_rng(4)
    theta, prior = rng.standard_normal(N_STANDARD), rng.standard_normal(N_STANDARD)
    split = b.standard(b.of(theta), prior)
    np.testing.assert_allclose(b.of(split), b.of(theta), atol=1e-12)
    np.testing.assert_array_equal(split[b.dependent], prior[b.dependent])


def test_the_base_parameters_do_not_depend_on_rounding_or_the_states_seed(
        tmp_path: Path) -> None:
    """The same robot, from its preset or from its robot file (points rounded at 1e-13 m),
    with the random states of any seed: the same base parameters, named the same. (A
    pivoted QR chose among columns of equal norm by rounding: 'm_p + 6 m_r' or 'm_r +
    0.167 m_p', and the robot file written from the estimate split the masses
    differently.)"""
    from hexapod.geometry import HexapodGeometry

    robot = preset("deltalab")
    robot.to_toml(tmp_path / "robot.toml")
    from_file = HexapodGeometry.from_toml(tmp_path / "robot.toml")
    ref = base_parameters(robot, seed=0)
    assert ref.names[0] == "m_p + 6 m_r"
    for geometry in (robot, from_file):
        for seed in range(4):
            b = base_parameters(geometry, seed=seed)
            assert b.names == ref.names and np.array_equal(b.independent, ref.independent)
            np.testing.assert_allclose(b.beta, ref.beta, atol=1e-9)
