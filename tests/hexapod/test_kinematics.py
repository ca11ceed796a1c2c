"""Tests of hexapod.kinematics: inverse kinematics, directions, inverse Jacobian (finite
differences of the leg lengths under a small twist), other frames, batching."""

from __future__ import annotations

import numpy as np
import pytest

from hexapod import (
    HexapodGeometry,
    ShapeError,
    Transform,
    inverse_jacobian,
    inverse_kinematics,
    leg_directions,
    legs_in_frame,
    platform_points_in_base,
    sample_poses,
)
from hexapod.kinematics import twist_to_frame
from hexapod.se3 import exp_so3, integrate_pose, look_at


def _camera_from_base() -> Transform:
    """A camera 0.7 m in front of the base centre looking at the legs."""
    eye = np.array([0.7, 0.05, 0.25])
    base_R_cam = look_at(eye, np.array([0.0, 0.0, 0.2]), np.array([0.0, 0.0, 1.0]))
    return Transform(base_R_cam, eye).inverse()


def test_inverse_kinematics_by_loops(geometry: HexapodGeometry, rng: np.random.Generator
                                     ) -> None:
    R, t = sample_poses(geometry, 20, rng=rng)
    q = inverse_kinematics(geometry, R, t)
    u = leg_directions(geometry, R, t)
    for k in range(20):
        for i in range(6):
            B = R[k] @ geometry.platform_points[i] + t[k]
            d = B - geometry.base_points[i]
            assert q[k, i] == pytest.approx(np.sqrt(d @ d), abs=1e-15)
            np.testing.assert_allclose(q[k, i] * u[k, i], d, atol=1e-15)
    np.testing.assert_allclose(
        platform_points_in_base(geometry, R[3], t[3]),
        geometry.platform_points @ R[3].T + t[3], atol=1e-15)


def test_batch_shapes(geometry: HexapodGeometry, rng: np.random.Generator) -> None:
    R, t = sample_poses(geometry, 12, rng=rng)
    R4, t4 = R.reshape(3, 4, 3, 3), t.reshape(3, 4, 3)
    q = inverse_kinematics(geometry, R4, t4)
    assert q.shape == (3, 4, 6)
    np.testing.assert_array_equal(q.reshape(12, 6), inverse_kinematics(geometry, R, t))
    legs = legs_in_frame(geometry, R4, t4, _camera_from_base())
    assert legs.base_points.shape == (3, 4, 6, 3)
    assert legs.inverse_jacobian.shape == (3, 4, 6, 6)
    np.testing.assert_allclose(legs.inverse_jacobian[1, 2],
                               legs_in_frame(geometry, R[6], t[6],
                                             _camera_from_base()).inverse_jacobian,
                               atol=1e-15)


def test_bad_pose_shapes(geometry: HexapodGeometry) -> None:
    with pytest.raises(ShapeError, match="rotation"):
        inverse_kinematics(geometry, np.eye(2), np.zeros(3))
    with pytest.raises(ShapeError, match="translation"):
        inverse_kinematics(geometry, np.eye(3), np.zeros(2))
    with pytest.raises(ShapeError, match="matching batch shapes"):
        inverse_kinematics(geometry, np.stack([np.eye(3)] * 2), np.zeros((3, 3)))
    with pytest.raises(ShapeError, match="finite"):
        inverse_kinematics(geometry, np.eye(3), np.array([0.0, np.nan, 0.4]))


def _length_rates_fd(geometry: HexapodGeometry, R: np.ndarray, t: np.ndarray,
                     twist_base: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """Central finite difference of the leg lengths under a base-frame twist."""
    Rp, tp = integrate_pose(R, t, twist_base, h)
    Rm, tm = integrate_pose(R, t, twist_base, -h)
    return (inverse_kinematics(geometry, Rp, tp) - inverse_kinematics(geometry, Rm, tm)) / (2 * h)


@pytest.mark.parametrize("which", ["geometry", "other_geometry"])
def test_inverse_jacobian_finite_differences(which: str, request: pytest.FixtureRequest,
                                             rng: np.random.Generator) -> None:
    geo = request.getfixturevalue(which)
    R, t = sample_poses(geo, 50, rng=rng)
    twists = rng.normal(size=(50, 6)) * [0.1, 0.1, 0.1, 1.0, 1.0, 1.0]
    legs = legs_in_frame(geo, R, t)
    J = inverse_jacobian(legs.base_points, legs.directions)
    predicted = np.einsum("kij,kj->ki", J, twists)
    fd = _length_rates_fd(geo, R, t, twists)
    np.testing.assert_allclose(predicted, fd, atol=1e-8)
    # Not a trivial agreement: the twists do move the legs.
    assert np.abs(fd).max() > 0.05
    # A_i x u_i = B_i x u_i (MATH section 3).
    B = platform_points_in_base(geo, R, t)
    np.testing.assert_allclose(np.cross(B, legs.directions),
                               np.cross(legs.base_points, legs.directions), atol=1e-15)


def test_inverse_jacobian_in_camera_frame(geometry: HexapodGeometry,
                                          rng: np.random.Generator) -> None:
    cam_from_base = _camera_from_base()
    R, t = sample_poses(geometry, 50, rng=rng)
    twists_base = rng.normal(size=(50, 6)) * [0.1, 0.1, 0.1, 1.0, 1.0, 1.0]
    twists_cam = twist_to_frame(twists_base, cam_from_base)
    legs_c = legs_in_frame(geometry, R, t, cam_from_base)
    np.testing.assert_allclose(legs_c.base_points, cam_from_base.apply(geometry.base_points)
                               * np.ones((50, 1, 1)), atol=1e-15)
    predicted = np.einsum("kij,kj->ki", legs_c.inverse_jacobian, twists_cam)
    fd = _length_rates_fd(geometry, R, t, twists_base)
    np.testing.assert_allclose(predicted, fd, atol=1e-8)
    # The camera-frame Jacobian applied to the base-frame twist is wrong (the test can fail).
    wrong = np.einsum("kij,kj->ki", legs_c.inverse_jacobian, twists_base)
    assert np.abs(wrong - fd).max() > 1e-2
    # The lengths do not depend on the frame.
    np.testing.assert_allclose(legs_c.lengths, inverse_kinematics(geometry, R, t), atol=1e-15)


def test_twist_to_frame_moves_the_same_body(rng: np.random.Generator) -> None:
    """Integrating the converted twist in the camera frame gives the same motion."""
    cam_from_base = _camera_from_base()
    for _ in range(20):
        R = exp_so3(rng.normal(size=3))
        t = rng.normal(size=3)
        tw = rng.normal(size=6)
        R1, t1 = integrate_pose(R, t, tw, 0.3)
        pose_c = cam_from_base.compose(Transform(R, t))
        Rc1, tc1 = integrate_pose(pose_c.rotation, pose_c.translation,
                                  twist_to_frame(tw, cam_from_base), 0.3)
        expected = cam_from_base.compose(Transform(R1, t1))
        np.testing.assert_allclose(Rc1, expected.rotation, atol=1e-12)
        np.testing.assert_allclose(tc1, expected.translation, atol=1e-12)
    # a list is a twist too (it raised "list indices must be integers"); five numbers not
    np.testing.assert_array_equal(twist_to_frame(list(tw), cam_from_base),
                                  twist_to_frame(tw, cam_from_base))
    with pytest.raises(ShapeError, match=r"twist: expected shape \(\.\.\., 6\)"):
        twist_to_frame(tw[:5], cam_from_base)


def test_transform_algebra(rng: np.random.Generator) -> None:
    T = Transform(exp_so3(rng.normal(size=3)), rng.normal(size=3))
    S = Transform(exp_so3(rng.normal(size=3)), rng.normal(size=3))
    p = rng.normal(size=(5, 3))
    np.testing.assert_allclose(T.inverse().apply(T.apply(p)), p, atol=1e-13)
    np.testing.assert_allclose(T.compose(S).apply(p), T.apply(S.apply(p)), atol=1e-13)
    np.testing.assert_allclose(T.compose(S).as_matrix(), T.as_matrix() @ S.as_matrix(),
                               atol=1e-13)
    np.testing.assert_allclose(T.rotate(p), (T.as_matrix()[:3, :3] @ p.T).T, atol=1e-13)
    np.testing.assert_array_equal(Transform.identity().apply(p), p)


def test_a_matrix_that_is_not_a_rotation_is_refused_naming_it() -> None:
    """1.01 R gave lengths 0.31 mm off, a 5 % shear 4.5 mm off, a reflection lengths:
    all taken without a word (the camera's pose already refused them)."""
    from hexapod.geometry import deltalab
    from hexapod.workspace import home_pose

    g = deltalab()
    R, t = home_pose(g)[:2]
    inverse_kinematics(g, R, t)  # a rotation: taken
    for M, what in ((1.01 * R, "det from 1.03"), (R + 0.05 * np.triu(np.ones((3, 3)), 1),
                                                   "|R^T R - I| = 5.25e-02"),
                    (np.diag([1.0, 1.0, -1.0]), "det from -1")):
        with pytest.raises(ShapeError, match="rotation: expected rotation matrices") as info:
            inverse_kinematics(g, M, t)
        assert what in str(info.value), str(info.value)
