"""The image sensor of the closed-loop simulator."""

from __future__ import annotations

import numpy as np
import pytest

from hexapod.kinematics import Transform
from hexapod.se3 import exp_so3
from hexapod.workspace import sample_poses
from vision.cameras import PerspectiveCamera, front_camera, omni_camera
from vision.image_sensor import ImageMeasurement, ImageSensor
from vision.legs import observe_legs


@pytest.mark.parametrize("make_camera", [front_camera, omni_camera])
def test_measure_with_the_true_camera(geometry, rng, make_camera):
    cam = make_camera(geometry)
    sensor = ImageSensor(cam, cam, geometry, rng, blur_px=0.8, noise_std=2.0)
    Rs, ts = sample_poses(geometry, 5, rng)
    bound = 0.1 if cam.kind == "perspective" else 0.5  # [deg], 95th percentile bounds
    for k in range(5):
        m = sensor.measure(Rs[k], ts[k])
        assert isinstance(m, ImageMeasurement)
        obs = observe_legs(cam, geometry, Rs[k], ts[k])
        vis = m.edge_visible
        assert np.all(vis[obs.visible_fraction >= 0.9])
        err = np.degrees(np.arccos(np.clip(np.sum(m.normals * obs.normals, -1), -1, 1)))
        assert np.all(err[vis] < bound)
        assert np.all((m.quality >= 0) & (m.quality <= 1))
        assert m.render_time_s > 0 and m.detect_time_s > 0
        if isinstance(cam, PerspectiveCamera):
            assert m.lines is not None
            assert np.allclose(m.lines[vis], cam.normal_to_line(m.normals[vis]))
        else:
            assert m.lines is None
    assert sensor.last_image is not None and sensor.last_image.shape == (cam.height, cam.width)


@pytest.mark.parametrize("make_camera", [front_camera, omni_camera])
def test_calibration_error_of_the_camera_reaches_the_features(geometry, rng, make_camera):
    """The estimated camera interprets the pixels: its error shows in the normals,
    but every edge is still found (wide first search for the perspective tracker)."""
    cam = make_camera(geometry)
    K = cam.K.copy()
    K[0, 0] *= 1.02
    K[1, 1] *= 1.02
    K[0, 2] += 5.0
    T = cam.camera_from_base
    est = cam.replace(K=K, camera_from_base=Transform(
        exp_so3(np.array([0.01, -0.005, 0.003])) @ T.rotation, T.translation + 0.005))
    sensor = ImageSensor(cam, est, geometry, rng)
    exact = ImageSensor(cam, cam, geometry, rng)
    Rs, ts = sample_poses(geometry, 4, rng)
    for k in range(4):
        m = sensor.measure(Rs[k], ts[k])
        m0 = exact.measure(Rs[k], ts[k])
        both = m.edge_visible & m0.edge_visible
        assert both.sum() >= 10
        err = np.degrees(np.arccos(np.clip(np.sum(m.normals * m0.normals, -1), -1, 1)))
        assert np.median(err[both]) > 0.05  # the model error is visible in the features


def test_predicted_normals_are_used(geometry, rng):
    cam = front_camera(geometry)
    sensor = ImageSensor(cam, cam, geometry, rng)
    Rs, ts = sample_poses(geometry, 2, rng)
    m0 = sensor.measure(Rs[0], ts[0])
    # Tracking from the previous measurement to a nearby pose.
    t1 = ts[0] + np.array([0.002, -0.001, 0.001])
    m1 = sensor.measure(Rs[0], t1, predicted_normals=m0.normals)
    obs = observe_legs(cam, geometry, Rs[0], t1)
    vis = m1.edge_visible
    assert vis.sum() >= 10
    err = np.degrees(np.arccos(np.clip(np.sum(m1.normals * obs.normals, -1), -1, 1)))
    assert np.all(err[vis] < 0.1)


def test_mismatched_cameras_raise(geometry):
    with pytest.raises(ValueError, match="kind"):
        ImageSensor(front_camera(geometry), omni_camera(geometry), geometry)


@pytest.mark.slow
def test_averaged_teaching_reduces_the_spread_of_the_taught_normals(geometry, rng):
    """Teaching a goal from a burst of K rendered frames (normals averaged by
    ``average_normals``) instead of one: over repeated teachings at the same pose, the
    spread of the taught normals about the truth (``observe_legs``) drops as
    ``1/sqrt(K)`` for independent pixel noise (bound: 1.5 times that, for the sampling
    error of the spread estimated from a few teachings), and their error to the truth
    (detector bias plus noise) does not grow."""
    from vision.estimate import average_normals

    cam = front_camera(geometry)
    sensor = ImageSensor(cam, cam, geometry, rng, blur_px=0.8, noise_std=6.0)
    R, t = sample_poses(geometry, 1, rng)
    truth = observe_legs(cam, geometry, R[0], t[0])
    frames, teachings = 9, 10
    single, burst = [], []
    for _ in range(teachings):
        single.append(sensor.measure(R[0], t[0]).normals)
        ms = [sensor.measure(R[0], t[0]) for _ in range(frames)]
        n, vis = average_normals(np.array([m.normals for m in ms]),
                                 np.array([m.edge_visible for m in ms]))
        assert np.all(vis == np.all([m.edge_visible for m in ms], axis=0))
        burst.append(n)
    seen = truth.edge_visible & np.all(np.isfinite(np.array(single + burst)), axis=(0, -1))
    assert seen.sum() >= 10
    dev1 = (np.array(single) - truth.normals)[:, seen]  # (teachings, edges, 3) [rad]
    devk = (np.array(burst) - truth.normals)[:, seen]
    spread1 = np.sqrt(np.mean(np.sum(np.var(dev1, axis=0, ddof=1), axis=-1)))
    spreadk = np.sqrt(np.mean(np.sum(np.var(devk, axis=0, ddof=1), axis=-1)))
    assert spread1 > 0
    assert spreadk < 1.5 / np.sqrt(frames) * spread1, (spreadk, spread1)
    rms1 = np.sqrt(np.mean(np.sum(dev1**2, axis=-1)))
    rmsk = np.sqrt(np.mean(np.sum(devk**2, axis=-1)))
    assert rmsk <= rms1
