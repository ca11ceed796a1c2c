"""Normals from noisy pixels: exact without noise, degrading with it, both cameras."""

from __future__ import annotations

import numpy as np
import pytest

from hexapod import sample_poses
from hexapod.geometry import HexapodGeometry
from vision.calibration import calibrate_base_points, collect_pixel_observations, point_errors
from vision.cameras import front_camera, omni_camera
from vision.legs import observe_legs
from vision.pixel_measure import normals_from_noisy_pixels


def _angles(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.degrees(np.arccos(np.clip(np.sum(a * b, axis=-1), -1.0, 1.0)))


@pytest.mark.parametrize("make_camera", [front_camera, omni_camera])
def test_noiseless_pixels_give_the_true_normals(make_camera: object,
                                                geometry: HexapodGeometry,
                                                rng: np.random.Generator) -> None:
    cam = make_camera(geometry)  # type: ignore[operator]
    R, t = sample_poses(geometry, 30, rng=rng)
    obs = observe_legs(cam, geometry, R, t)
    n, vis = normals_from_noisy_pixels(cam, cam, obs, 0.0, 10, rng)
    np.testing.assert_array_equal(vis, obs.edge_visible)
    np.testing.assert_allclose(n[vis], obs.normals[vis], atol=1e-9)
    assert np.all(np.isnan(n[~vis]))
    noisy, vis2 = normals_from_noisy_pixels(cam, cam, obs, 1.0, 10, rng)
    err = _angles(noisy[vis2], obs.normals[vis2])
    assert 1e-4 < np.median(err) < 1.0, "1 px noise gives a small but non-zero angle"
    many, _ = normals_from_noisy_pixels(cam, cam, obs, 1.0, 80, rng)
    assert np.median(_angles(many[vis2], obs.normals[vis2])) < np.median(err)


def test_intrinsics_error_reaches_the_normals(geometry: HexapodGeometry,
                                              rng: np.random.Generator) -> None:
    cam = front_camera(geometry)
    K = cam.K.copy()
    K[0, 0] *= 1.02
    wrong = cam.replace(K=K)
    R, t = sample_poses(geometry, 10, rng=rng)
    obs = observe_legs(cam, geometry, R, t)
    n, vis = normals_from_noisy_pixels(cam, wrong, obs, 0.0, 10, rng)
    assert np.median(_angles(n[vis], obs.normals[vis])) > 1e-3


def test_calibration_from_pixel_noise(geometry: HexapodGeometry) -> None:
    cam = omni_camera(geometry)
    exact = collect_pixel_observations(geometry, cam, "extremal", 0.0, 10, 0)
    truth = cam.camera_from_base.apply(geometry.base_points)
    est = calibrate_base_points(exact, geometry.leg_radius, "lstsq").base_points
    assert np.max(point_errors(est, truth)) < 1e-9
    noisy = collect_pixel_observations(geometry, cam, "extremal", 0.5, 20, 0)
    est = calibrate_base_points(noisy, geometry.leg_radius, "irls").base_points
    err = point_errors(est, truth)
    assert 1e-6 < np.max(err) < 5e-3
