"""Tests of hexapod.model: the closed-chain Pinocchio model is the reference of the
closed-form kinematics (loop closure at the inverse-kinematics configuration, inverse
Jacobian from the constraint Jacobians)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from hexapod import HexapodGeometry, build_model, inverse_jacobian, legs_in_frame, sample_poses
from hexapod.model import HexapodModel, constraint_residual_and_jacobian


@pytest.fixture(params=["geometry", "other_geometry"])
def robot(request: pytest.FixtureRequest) -> tuple[HexapodGeometry, HexapodModel]:
    geo = request.getfixturevalue(request.param)
    return geo, build_model(geo)


def test_structure(robot: tuple[HexapodGeometry, HexapodModel]) -> None:
    geo, hm = robot
    assert hm.model.nq == 7 + 6 * 5
    assert hm.model.nv == 6 + 6 * 4
    assert len(hm.constraint_models) == 6
    lo = hm.model.lowerPositionLimit[hm.prismatic_q_indices()]
    hi = hm.model.upperPositionLimit[hm.prismatic_q_indices()]
    np.testing.assert_array_equal(lo, geo.q_min)
    np.testing.assert_array_equal(hi, geo.q_max)
    names = [g.name for g in hm.visual_model.geometryObjects]
    assert "base" in names and "platform" in names
    assert sum(n.startswith("leg") for n in names) == 12


def test_constraints_closed_at_inverse_kinematics(robot: tuple[HexapodGeometry, HexapodModel],
                                                  rng: np.random.Generator) -> None:
    geo, hm = robot
    R, t = sample_poses(geo, 30, rng=rng)
    for k in range(30):
        q = hm.configuration(R[k], t[k])
        assert np.abs(hm.constraint_residual(q)).max() < 1e-12
        legs = legs_in_frame(geo, R[k], t[k])
        np.testing.assert_allclose(hm.leg_lengths(q), legs.lengths, atol=1e-15)
        Rr, tr = hm.platform_pose(q)
        np.testing.assert_allclose(Rr, R[k], atol=1e-12)
        np.testing.assert_allclose(tr, t[k], atol=1e-15)
        # The tip frames sit at B_i (independent of the constraint code).
        pin.forwardKinematics(hm.model, hm.data, q)
        for i, jp in enumerate(hm.prismatic_joints):
            np.testing.assert_allclose(hm.data.oMi[jp].translation,
                                       R[k] @ geo.platform_points[i] + t[k], atol=1e-12)
    # The residual is not identically zero: a wrong leg length opens its loop.
    q = hm.configuration(R[0], t[0])
    q[hm.prismatic_q_indices()[2]] += 1e-3
    res = hm.constraint_residual(q).reshape(6, 3)
    assert np.linalg.norm(res[2]) == pytest.approx(1e-3, rel=1e-6)
    assert np.abs(np.delete(res, 2, axis=0)).max() < 1e-12


def _freeflyer_velocity(R: np.ndarray, t: np.ndarray, twist: np.ndarray) -> np.ndarray:
    """Pinocchio's free-flyer velocity (platform frame, at its origin) of our twist (base
    frame, at its origin)."""
    v, w = twist[:3], twist[3:]
    return np.concatenate([R.T @ (v + np.cross(w, t)), R.T @ w])


def test_inverse_jacobian_from_constraint_jacobians(
        robot: tuple[HexapodGeometry, HexapodModel], rng: np.random.Generator) -> None:
    geo, hm = robot
    R, t = sample_poses(geo, 20, rng=rng)
    pris = hm.prismatic_v_indices()
    passive = np.setdiff1d(np.arange(6, hm.model.nv), pris)
    for k in range(20):
        q = hm.configuration(R[k], t[k])
        _, J = constraint_residual_and_jacobian(hm, q)
        assert np.linalg.matrix_rank(J) == 18
        Jp, Ja, Jq = J[:, :6], J[:, passive], J[:, pris]
        # J_p v_ff + J_a v_a + J_q qdot = 0: eliminate v_a (the spins of the spherical
        # joints about the legs are in the null space, qdot is still unique).
        M = np.hstack([Ja, Jq])
        rhs = -Jp
        sol = np.linalg.lstsq(M, rhs, rcond=None)[0]
        assert np.abs(M @ sol - rhs).max() < 1e-10  # the loops can follow any twist
        qdot_of_vff = sol[-6:]  # (6, 6): qdot = this @ v_ff
        # Map our twist to the free-flyer velocity: v_ff = G tau.
        G = np.column_stack([_freeflyer_velocity(R[k], t[k], e) for e in np.eye(6)])
        J_from_model = qdot_of_vff @ G
        legs = legs_in_frame(geo, R[k], t[k])
        np.testing.assert_allclose(J_from_model, inverse_jacobian(legs.base_points,
                                                                  legs.directions),
                                   atol=1e-10)


def test_constraint_velocity_keeps_loops_closed(robot: tuple[HexapodGeometry, HexapodModel],
                                                rng: np.random.Generator) -> None:
    """Moving along the constraint null space closes the loops to second order, which
    checks the velocity convention used above (pin.integrate of the free-flyer)."""
    geo, hm = robot
    R, t = sample_poses(geo, 1, rng=rng)
    q = hm.configuration(R[0], t[0])
    _, J = constraint_residual_and_jacobian(hm, q)
    null = np.linalg.svd(J)[2][18:].T  # (30, 12)
    dv = null @ rng.normal(size=12)
    dv /= np.linalg.norm(dv)
    for h in (1e-3, 1e-4):
        res = np.abs(hm.constraint_residual(pin.integrate(hm.model, q, h * dv))).max()
        assert res < 10 * h * h
    # Against it, the residual grows linearly.
    bad = J.T @ rng.normal(size=18)
    bad /= np.linalg.norm(bad)
    assert np.abs(hm.constraint_residual(pin.integrate(hm.model, q, 1e-4 * bad))).max() > 1e-6
