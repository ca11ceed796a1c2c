"""Weighted least squares: exact on noise-free data, physical when asked, refusals."""

from __future__ import annotations

import numpy as np
import pytest

from hexapod.dynamics.identification.base import base_parameters, random_states
from hexapod.dynamics.identification.estimation import margins, weighted_least_squares
from hexapod.dynamics.identification.parameters import N_MECHANISM, standard_vector
from hexapod.dynamics.identification.regressor import regressor
from hexapod.exceptions import IdentificationError
from hexapod.geometry import preset
from tests.hexapod.dynamics.identification.test_regressor import lopsided


def _data(n: int = 300, seed: int = 1):
    nominal, truth = preset("deltalab"), lopsided()
    b = base_parameters(nominal)
    R, t, twist, acc = random_states(nominal, n, np.random.default_rng(seed))
    Y, _, _ = regressor(nominal, R, t, twist, acc)
    return nominal, truth, b, Y


@pytest.mark.slow
def test_noise_free_data_recovers_the_base_parameters() -> None:
    """Forces from the true parameters, no noise, a prior that is wrong: the weighted
    least squares gives the truth's base parameters to 1e-6 (relative to each one's
    scale); the prior's split being non-physical for them, the physical estimate (SLSQP,
    kept 1e-7 inside the constraints) is within 1e-3 of them and physical."""
    nominal, truth, b, Y = _data()
    theta = standard_vector(truth.inertia, truth.drives)
    forces = Y @ theta
    prior = standard_vector(nominal.inertia, nominal.drives)
    est = weighted_least_squares(b.columns(Y), forces, b, prior, nominal.inertia,
                                 nominal.drives)
    true_base = b.of(theta)
    scale = np.maximum(np.abs(true_base), 1e-3)
    assert est.unconstrained is not None
    error = np.abs(est.unconstrained - true_base) / scale
    assert error.max() < 1e-6, (b.names[int(np.argmax(error))], error.max())
    assert "not physical" in est.consistency[0]
    assert np.max(np.abs(est.theta - true_base) / scale) < 1e-3
    assert np.all(margins(est.standard) >= 0)


@pytest.mark.slow
def test_noise_free_data_with_a_physical_prior_needs_no_constraint() -> None:
    """The robot file is the truth: recovered to 1e-6, no constraint active."""
    nominal, _, b, Y = _data()
    theta = standard_vector(nominal.inertia, nominal.drives)
    est = weighted_least_squares(b.columns(Y), Y @ theta, b, theta, nominal.inertia,
                                 nominal.drives)
    assert est.consistency[0].startswith("physically consistent")
    true_base = b.of(theta)
    error = np.abs(est.theta - true_base) / np.maximum(np.abs(true_base), 1e-3)
    assert error.max() < 1e-6


@pytest.mark.slow
def test_standard_errors_match_the_scatter_of_noisy_estimates() -> None:
    """With Gaussian force noise of known sigma, the standard errors are those of the
    least squares (compared with the covariance computed from the known sigma)."""
    nominal, truth, b, Y = _data(n=400, seed=2)
    theta = standard_vector(truth.inertia, truth.drives)
    prior = standard_vector(nominal.inertia, nominal.drives)
    rng = np.random.default_rng(0)
    sigma = 0.05
    forces = Y @ theta + sigma * rng.standard_normal((400, 6))
    est = weighted_least_squares(b.columns(Y), forces, b, prior, nominal.inertia,
                                 nominal.drives)
    W = b.columns(Y).reshape(-1, b.size)
    se_known = sigma * np.sqrt(np.diag(np.linalg.inv(W.T @ W)))
    np.testing.assert_allclose(est.se, se_known, rtol=0.15)
    np.testing.assert_allclose(est.sigma_legs, sigma, rtol=0.15)


@pytest.mark.slow
def test_non_physical_estimate_is_solved_under_the_constraints() -> None:
    """Forces from a robot whose leg 0 has a negative viscous friction: the estimate is
    constrained to a non-negative one and the consistency note says so."""
    nominal, truth, b, Y = _data()
    theta = standard_vector(truth.inertia, truth.drives)
    theta[N_MECHANISM + 1] = -20.0  # viscous_0
    prior = standard_vector(nominal.inertia, nominal.drives)
    est = weighted_least_squares(b.columns(Y), Y @ theta, b, prior, nominal.inertia,
                                 nominal.drives)
    assert "not physical" in est.consistency[0]
    assert "viscous_0" in est.consistency[0]
    assert est.standard[N_MECHANISM + 1] >= 0
    assert np.all(margins(est.standard) >= 0)
    assert est.unconstrained is not None
    assert est.unconstrained[b.names.index("viscous_0")] == pytest.approx(-20.0, rel=1e-6)


@pytest.mark.slow
def test_a_centre_of_mass_off_the_leg_is_constrained_onto_it() -> None:
    """Forces from a rod whose centre of mass would be 0.6 m from its hinge, beyond the
    shortest leg (0.345 m): with the leg length given, the estimate is constrained until
    the robot file's own rule (``check_legs``) accepts its tables; without, it is not."""
    from hexapod.dynamics.identification.parameters import to_tables

    nominal, truth, b, Y = _data()
    q_min = nominal.stroke[0]
    theta = standard_vector(truth.inertia, truth.drives)
    theta[15] = 0.6 * theta[14]  # md_r = 0.6 m x m_r
    prior = standard_vector(nominal.inertia, nominal.drives)
    free = weighted_least_squares(b.columns(Y), Y @ theta, b, prior, nominal.inertia,
                                  nominal.drives)
    assert not 0.0 <= free.standard[15] / free.standard[14] <= q_min  # off the leg
    est = weighted_least_squares(b.columns(Y), Y @ theta, b, prior, nominal.inertia,
                                 nominal.drives, q_min=q_min)
    assert "outside the leg" in est.consistency[0], est.consistency
    assert np.all(margins(est.standard, q_min) >= 0)
    inertia, _ = to_tables(est.standard, nominal.inertia, nominal.drives)
    inertia.check_legs(q_min)  # what writing the robot file checks
    assert 0.0 <= inertia.rod_com <= q_min and 0.0 <= inertia.body_com <= q_min


def test_an_excitation_at_rest_is_refused_naming_the_weakest_parameter() -> None:
    """At rest only gravity acts: the inertias are undetermined, and the error says it."""
    nominal, _truth, b, _ = _data()
    R, t, _, _ = random_states(nominal, 100, np.random.default_rng(3))
    zero = np.zeros((100, 6))
    Y, _, _ = regressor(nominal, R, t, zero, zero)
    prior = standard_vector(nominal.inertia, nominal.drives)
    with pytest.raises(IdentificationError, match=r"undetermined.*weakest"):
        weighted_least_squares(b.columns(Y), Y @ prior, b, prior, nominal.inertia,
                               nominal.drives)


def test_a_record_of_heave_alone_is_refused_not_given_nan_errors() -> None:
    """Measured lengths of the platform moving up and down only (every leg the same 5 mm
    sine at 0.5 Hz, 6 s at 1 kHz) and the holding forces: most base parameters are
    confounded (scaled condition about 9e8). It was accepted with NaN standard errors
    and a -3792 kg platform under the constraints."""
    from hexapod.dynamics.identification.processing import samples
    from hexapod.workspace import home_pose

    g = preset("deltalab")
    b = base_parameters(g)
    R0, t0 = home_pose(g)
    time = np.arange(6000) * 1e-3
    home = np.linalg.norm(t0 + g.platform_points @ R0.T - g.base_points, axis=1)
    lengths = home + 0.005 * np.sin(2 * np.pi * 0.5 * time)[:, None]
    forces = 6.359 + 0.01 * np.random.default_rng(1).standard_normal((6000, 6))
    s = samples(g, 1e-3, lengths, forces)
    Y, _, _ = regressor(g, s.R, s.t, s.twist, s.acc)
    prior = standard_vector(g.inertia, g.drives)
    with pytest.raises(IdentificationError, match=r"undetermined \(condition [0-9.e+]+\); "
                                                  "weakest"):
        weighted_least_squares(b.columns(Y), s.forces, b, prior, g.inertia, g.drives,
                               s.mask(), q_min=g.stroke[0])


def test_too_few_or_bad_data_are_refused() -> None:
    nominal, _truth, b, Y = _data(n=10)
    prior = standard_vector(nominal.inertia, nominal.drives)
    with pytest.raises(IdentificationError, match=r"too few, at least 62 and 11 per leg "
                                                  r"\(the samples of a leg at rest or slower "
                                                  r".*a longer or a livelier record"):
        weighted_least_squares(b.columns(Y)[:3], np.zeros((3, 6)), b, prior,
                               nominal.inertia, nominal.drives)
    forces = np.zeros((10, 6))
    forces[4, 2] = np.nan
    with pytest.raises(IdentificationError, match="non-finite"):
        weighted_least_squares(b.columns(Y), forces, b, prior, nominal.inertia,
                               nominal.drives)
