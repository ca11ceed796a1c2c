"""Tests of hexapod.fk: round trips on 1,000 random poses for both methods and the batch,
and the documented errors."""

from __future__ import annotations

import numpy as np
import pytest

from hexapod import (
    ForwardKinematicsError,
    HexapodGeometry,
    ShapeError,
    StrokeLimitError,
    build_model,
    forward_kinematics,
    forward_kinematics_batch,
    inverse_kinematics,
    legs_in_frame,
    sample_poses,
)
from hexapod.se3 import integrate_pose, pose_error

N_POSES = 1000


@pytest.fixture(scope="module")
def poses() -> tuple[np.ndarray, np.ndarray]:
    from hexapod import deltalab

    return sample_poses(deltalab(), N_POSES, rng=np.random.default_rng(99))


@pytest.mark.slow
@pytest.mark.parametrize("method", ["newton", "pinocchio"])
def test_round_trip_1000_poses(geometry: HexapodGeometry, poses: tuple[np.ndarray, np.ndarray],
                               method: str) -> None:
    R, t = poses
    q = inverse_kinematics(geometry, R, t)
    model = build_model(geometry) if method == "pinocchio" else None
    dp = np.empty(N_POSES)
    da = np.empty(N_POSES)
    for k in range(N_POSES):
        sol = forward_kinematics(geometry, q[k], method=method, model=model)  # type: ignore[arg-type]
        assert sol.method == method
        assert sol.residual < 1e-10
        dp[k], da[k] = pose_error(sol.rotation, sol.translation, R[k], t[k])
    assert dp.max() < 1e-9
    assert da.max() < 1e-9


def test_round_trip_warm_start_and_other_robot(other_geometry: HexapodGeometry,
                                               rng: np.random.Generator) -> None:
    """Warm start from a nearby pose (a few mm, a degree away), as in a control loop.

    This robot's box of random poses reaches near-singular poses, where another assembly
    mode lies within millimetres (both methods then agree on that other pose): keep the
    well-conditioned ones, where the nearest solution is the pose itself.
    """
    R, t = sample_poses(other_geometry, 60, rng=rng, max_angle=np.deg2rad(10))
    cond = np.linalg.cond(legs_in_frame(other_geometry, R, t).inverse_jacobian)
    R, t = R[cond < 3000][:30], t[cond < 3000][:30]
    assert len(R) == 30
    q = inverse_kinematics(other_geometry, R, t)
    model = build_model(other_geometry)
    for k in range(30):
        twist = rng.normal(size=6) * [0.003, 0.003, 0.003, 0.02, 0.02, 0.02]
        guess = integrate_pose(R[k], t[k], twist, 1.0)
        for method in ("newton", "pinocchio"):
            sol = forward_kinematics(other_geometry, q[k], guess=guess, method=method,  # type: ignore[arg-type]
                                     model=model)
            dp, da = pose_error(sol.rotation, sol.translation, R[k], t[k])
            assert dp < 1e-9 and da < 1e-9
            assert sol.iterations <= 6


def test_batch_round_trip(geometry: HexapodGeometry, poses: tuple[np.ndarray, np.ndarray]
                          ) -> None:
    R, t = poses
    q = inverse_kinematics(geometry, R, t)
    sol = forward_kinematics_batch(geometry, q)
    assert sol.converged.all()
    assert sol.residuals.max() < 1e-12
    dp, da = pose_error(sol.rotations, sol.translations, R, t)
    assert dp.max() < 1e-9 and da.max() < 1e-9
    np.testing.assert_allclose(inverse_kinematics(geometry, sol.rotations, sol.translations), q,
                               atol=1e-12)


def test_batch_flags_items_that_do_not_converge(geometry: HexapodGeometry,
                                                poses: tuple[np.ndarray, np.ndarray]) -> None:
    R, t = poses
    q = inverse_kinematics(geometry, R[:5], t[:5])
    q[2] = [0.1, 0.1, 0.1, 5.0, 5.0, 5.0]  # no pose has these lengths
    sol = forward_kinematics_batch(geometry, q)
    np.testing.assert_array_equal(sol.converged, [True, True, False, True, True])
    assert not sol.residuals[2] < 1e-12
    with pytest.raises(ShapeError):
        forward_kinematics_batch(geometry, q[:, :5])


def test_batch_per_item_geometry(geometry: HexapodGeometry, other_geometry: HexapodGeometry,
                                 rng: np.random.Generator) -> None:
    R, t = sample_poses(other_geometry, 4, rng=rng)
    q = inverse_kinematics(other_geometry, R, t)
    n = 4
    sol = forward_kinematics_batch(
        geometry, q, R + 0.0, t + 0.001,
        base_points=np.broadcast_to(other_geometry.base_points, (n, 6, 3)),
        platform_points=np.broadcast_to(other_geometry.platform_points, (n, 6, 3)))
    assert sol.converged.all()
    np.testing.assert_allclose(sol.translations, t, atol=1e-9)


@pytest.mark.parametrize("method", ["newton", "pinocchio"])
def test_lengths_outside_the_stroke(geometry: HexapodGeometry, method: str) -> None:
    q = np.full(6, geometry.q_mid)
    q[4] = geometry.q_max + 1e-3
    with pytest.raises(StrokeLimitError) as exc:
        forward_kinematics(geometry, q, method=method)  # type: ignore[arg-type]
    assert exc.value.leg == 4
    assert exc.value.value == pytest.approx(geometry.q_max + 1e-3)
    assert (exc.value.lower, exc.value.upper) == geometry.stroke
    q[4] = geometry.q_min - 1e-3
    with pytest.raises(StrokeLimitError, match="leg 4"):
        forward_kinematics(geometry, q, method=method)  # type: ignore[arg-type]
    # Allowed when the caller says so (the pose exists just outside the stroke).
    sol = forward_kinematics(geometry, q, method=method, check_stroke=False)  # type: ignore[arg-type]
    np.testing.assert_allclose(inverse_kinematics(geometry, sol.rotation, sol.translation), q,
                               atol=1e-10)


@pytest.mark.parametrize("method", ["newton", "pinocchio"])
def test_no_convergence_raises(geometry: HexapodGeometry, poses: tuple[np.ndarray, np.ndarray],
                               method: str) -> None:
    R, t = poses
    q = inverse_kinematics(geometry, R, t)
    far = int(np.argmax(np.abs(q - geometry.q_mid).max(axis=1)))
    with pytest.raises(ForwardKinematicsError) as exc:
        forward_kinematics(geometry, q[far], method=method,  # type: ignore[arg-type]
                           max_iterations=1)
    assert exc.value.method == method
    assert exc.value.residual > 1e-12
    assert 1 <= exc.value.iterations <= 3
    assert "iteration budget" in exc.value.reason


def test_lengths_without_pose_raise(geometry: HexapodGeometry) -> None:
    # Lengths that no pose has (the platform cannot be 5 m from three base joints and 0.1 m
    # from the others).
    for method in ("newton", "pinocchio"):
        with pytest.raises(ForwardKinematicsError):
            forward_kinematics(geometry, np.array([0.1, 0.1, 0.1, 5.0, 5.0, 5.0]),
                               method=method, check_stroke=False)  # type: ignore[arg-type]


def test_bad_arguments(geometry: HexapodGeometry) -> None:
    q = np.full(6, geometry.q_mid)
    with pytest.raises(ShapeError):
        forward_kinematics(geometry, q[:5])
    with pytest.raises(ShapeError):
        forward_kinematics(geometry, np.r_[q[:5], np.nan])
    with pytest.raises(ShapeError, match="guess"):
        forward_kinematics(geometry, q, guess=(np.eye(3), np.zeros(2)))
    with pytest.raises(ValueError, match="unknown forward-kinematics method"):
        forward_kinematics(geometry, q, method="magic")  # type: ignore[arg-type]


def test_a_guess_that_is_not_a_rotation_gives_the_pose_not_a_false_one() -> None:
    """A guess with a scale or a shear (a pose read back rounded) was carried by the
    Newton update into an answer millimetres off, reported converged (0.9 mm for a
    1 % shear, 69 mm for 2 I): it is replaced by the nearest rotation; a reflection is
    refused naming the guess; a rotation guess is used bit for bit."""
    from hexapod.fk import proper_rotations
    from hexapod.geometry import deltalab
    from hexapod.se3 import exp_so3
    from hexapod.workspace import home_pose

    g = deltalab()
    t0 = home_pose(g)[1]
    R, t = exp_so3(np.array([0.05, -0.03, 0.1])), t0 + np.array([0.01, 0.0, 0.01])
    q = inverse_kinematics(g, R, t)
    for guess in (np.eye(3) + 0.01 * np.triu(np.ones((3, 3)), 1), np.round(R, 2),
                  2 * np.eye(3)):
        s = forward_kinematics(g, q, guess=(guess, t0))
        np.testing.assert_allclose(s.translation, t, atol=1e-10)
        np.testing.assert_allclose(s.rotation, R, atol=1e-10)
        b = forward_kinematics_batch(g, q[None], guess[None], t0[None])
        assert b.converged[0]
        np.testing.assert_allclose(b.rotations[0], R, atol=1e-10)
    with pytest.raises(ValueError, match="guess: a rotation guess with determinant -1"):
        forward_kinematics(g, q, guess=(-np.eye(3), t0))
    assert np.array_equal(proper_rotations(R[None], "guess")[0], R)


def test_a_guess_given_half_a_budget_or_points_of_the_wrong_shape_are_refused() -> None:
    """A rotation guess without its translation was dropped for the home pose without a
    word; a tolerance of 0 or NaN reported a solve with residual 0 as failed; a budget of
    0 reported "failed after 0 iterations"; points of another shape gave numpy's
    broadcast error: each is named now."""
    from hexapod import deltalab, home_pose

    g = deltalab()
    R, t = home_pose(g)
    q = inverse_kinematics(g, R, t)[None]
    with pytest.raises(ValueError, match="translations: missing; give both guesses"):
        forward_kinematics_batch(g, q, rotations=R[None])
    with pytest.raises(ShapeError, match=r"base_points: expected shape \(6, 3\) or \(1, 6, "
                                         r"3\), got \(6, 2\)"):
        forward_kinematics_batch(g, q, base_points=np.zeros((6, 2)))
    with pytest.raises(ShapeError, match="rotations/translations"):
        forward_kinematics_batch(g, q, rotations=R[None], translations=t)
    for tol in (0.0, float("nan")):
        with pytest.raises(ValueError, match="tol: must be a positive finite length"):
            forward_kinematics(g, q[0], tol=tol)
    with pytest.raises(ValueError, match="max_iterations: must be an integer >= 1, got 0"):
        forward_kinematics_batch(g, q, max_iterations=0)
