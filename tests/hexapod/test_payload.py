"""Tests of hexapod.dynamics.payload: a payload fixed to the platform, combined with it by
the parallel-axis theorem, against the dynamics of the platform plus the payload written
as a separate rigid body (its own Newton-Euler terms), and its refusals."""

from __future__ import annotations

import numpy as np
import pytest

from hexapod import HexapodGeometry, sample_poses
from hexapod.dynamics import DynamicModel
from hexapod.dynamics.inertia import inertia_matrix
from hexapod.dynamics.payload import Payload, with_payload
from hexapod.exceptions import InertiaError
from hexapod.se3 import skew

#: A lopsided tool: off-centre, below the platform, with products of inertia.
TOOL = Payload(3.7, np.array([0.021, -0.013, -0.045]),
               np.array([0.011, 0.014, 0.008, 0.0012, -0.0007, 0.0009]))


def _body_terms(payload: Payload, R: np.ndarray, twist: np.ndarray, gravity: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """The payload alone as a rigid body moving with the platform: its mass matrix and
    bias forces in the platform's twist coordinates ``(v, w)`` (Newton-Euler: the centre
    of mass at ``r = R c``, ``v_c = v + w x r``, ``a_c = dv + dw x r + w x (w x r)``)."""
    m = payload.mass
    r = R @ payload.com
    inertia = R @ inertia_matrix(payload.inertia) @ R.T
    S = skew(r)
    M = np.block([[m * np.eye(3), -m * S], [m * S, inertia - m * S @ S]])
    w = twist[3:]  # (the linear velocity does not enter a rigid body's bias)
    f = m * (np.cross(w, np.cross(w, r)) - gravity)
    h = np.concatenate([f, np.cross(r, f) + np.cross(w, inertia @ w)])
    return M, h


def test_payload_equals_the_platform_plus_a_rigid_body(geometry: HexapodGeometry,
                                                       rng: np.random.Generator) -> None:
    loaded = geometry.replace(inertia=with_payload(geometry.inertia, TOOL))
    assert loaded.inertia.platform_mass == pytest.approx(2.0 + 3.7)
    n = 10
    R, t = sample_poses(geometry, n, rng=rng)
    twist = np.concatenate([rng.normal(scale=0.2, size=(n, 3)),
                            rng.normal(scale=1.0, size=(n, 3))], axis=1)
    M0, h0, K0, _, _ = DynamicModel(geometry).terms_batch(R, t, twist)
    M1, h1, K1, _, _ = DynamicModel(loaded).terms_batch(R, t, twist)
    np.testing.assert_array_equal(K0, K1)
    g = np.asarray(geometry.inertia.gravity)
    for k in range(n):
        Ml, hl = _body_terms(TOOL, R[k], twist[k], g)
        assert np.linalg.norm(Ml) > 0.5 * np.linalg.norm(M0[k])  # not a negligible load
        np.testing.assert_allclose(M1[k], M0[k] + Ml, rtol=0, atol=1e-12 * np.abs(M1[k]).max())
        np.testing.assert_allclose(h1[k], h0[k] + hl, rtol=0, atol=1e-11 * np.abs(h1[k]).max())


def test_combined_inertia_is_positive_and_the_centre_of_mass_weighted() -> None:
    from hexapod.dynamics.inertia import InertiaParameters

    base = InertiaParameters.default(0.1, 0.01, 0.3)
    out = with_payload(base, TOOL)
    np.testing.assert_allclose(out.platform_com, 3.7 * TOOL.com / 5.7, rtol=1e-14)
    # about the platform origin, the inertias simply add (both bodies moved there)
    origin = (out.platform_tensor + 5.7 * (out.platform_com @ out.platform_com * np.eye(3)
                                           - np.outer(out.platform_com, out.platform_com)))
    expected = (base.platform_tensor + inertia_matrix(TOOL.inertia)
                + 3.7 * (TOOL.com @ TOOL.com * np.eye(3) - np.outer(TOOL.com, TOOL.com)))
    np.testing.assert_allclose(origin, expected, rtol=1e-13, atol=1e-16)


def test_empty_payload_changes_nothing() -> None:
    from hexapod.dynamics.inertia import InertiaParameters

    base = InertiaParameters.default(0.1, 0.01, 0.3)
    assert with_payload(base, Payload(0.0, np.zeros(3), np.zeros(6))) is base
    point = with_payload(base, Payload(1.0, np.zeros(3), np.zeros(6)))
    assert point.platform_mass == 3.0
    np.testing.assert_array_equal(point.platform_inertia, base.platform_inertia)


@pytest.mark.parametrize(("mass", "com", "six", "key", "words"), [
    (-1.0, np.zeros(3), np.zeros(6), "payload.mass", "negative"),
    (1.0, np.zeros(2), np.zeros(6), "payload.com", "shape"),
    (1.0, np.array([0.0, np.nan, 0.0]), np.zeros(6), "payload.com", "not finite"),
    (0.0, np.zeros(3), np.array([0.1, 0.1, 0.1, 0, 0, 0]), "payload.inertia", "massless"),
    (1.0, np.zeros(3), np.array([-0.1, 0.1, 0.1, 0, 0, 0]), "payload.inertia",
     "semi-definite"),
    (1.0, np.zeros(3), np.array([0.01, 0.01, 0.05, 0, 0, 0]), "payload.inertia",
     "triangle"),
])
def test_impossible_payload_refused(mass: float, com: np.ndarray, six: np.ndarray, key: str,
                                    words: str) -> None:
    with pytest.raises(InertiaError) as info:
        Payload(mass, com, six, source="s.toml")
    assert info.value.field == key and words in str(info.value) and "s.toml" in str(info.value)


def test_with_mass_scales_the_inertia() -> None:
    heavier = TOOL.with_mass(7.4)
    assert heavier.mass == 7.4
    np.testing.assert_allclose(heavier.inertia, 2 * TOOL.inertia, rtol=1e-15)
    np.testing.assert_array_equal(heavier.com, TOOL.com)


def test_equivalent_heavier_platform_combined_by_pinocchio(geometry: HexapodGeometry,
                                                           rng: np.random.Generator) -> None:
    """The platform made heavier by Pinocchio's own sum of the two spatial inertias
    (``pin.Inertia`` addition): the same mass, centre of mass, inertia and dynamics."""
    import pinocchio as pin

    m = geometry.inertia
    total = (pin.Inertia(m.platform_mass, np.asarray(m.platform_com), m.platform_tensor)
             + pin.Inertia(TOOL.mass, np.asarray(TOOL.com), inertia_matrix(TOOL.inertia)))
    I = total.inertia
    heavier = geometry.replace(inertia=m.replace(
        platform_mass=total.mass, platform_com=np.array(total.lever),
        platform_inertia=np.array([I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2]])))
    loaded = geometry.replace(inertia=with_payload(m, TOOL))
    assert loaded.inertia.platform_mass == pytest.approx(heavier.inertia.platform_mass,
                                                         rel=1e-15)
    np.testing.assert_allclose(loaded.inertia.platform_com, heavier.inertia.platform_com,
                               rtol=0, atol=1e-15)
    np.testing.assert_allclose(loaded.inertia.platform_inertia,
                               heavier.inertia.platform_inertia, rtol=0, atol=1e-15)
    n = 8
    R, t = sample_poses(geometry, n, rng=rng)
    twist = rng.normal(scale=0.5, size=(n, 6))
    M1, h1, _, _, _ = DynamicModel(loaded).terms_batch(R, t, twist)
    M2, h2, _, _, _ = DynamicModel(heavier).terms_batch(R, t, twist)
    np.testing.assert_allclose(M1, M2, rtol=0, atol=1e-12 * np.abs(M2).max())
    np.testing.assert_allclose(h1, h2, rtol=0, atol=1e-12 * np.abs(h2).max())
