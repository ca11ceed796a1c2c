"""Leg-edge detection on rendered images with known truth."""

from __future__ import annotations

import numpy as np
import pytest

from hexapod.workspace import home_pose, sample_poses
from tests.vision.detection_checks import (
    STYLE,
    angles_deg,
    detect_omni_sampled_poses,
    miscalibrated,
    track_sampled_poses,
)
from vision.cameras import FRONT_DISTORTION, OMNI_DISTORTION, front_camera, omni_camera
from vision.detect import (
    DetectionError,
    LegPrediction,
    OmniDetector,
    PerspectiveTracker,
    draw_detection,
    fit_normals,
)
from vision.legs import observe_legs
from vision.render import Renderer, RenderStyle


def test_omni_detector_accuracy_without_initialisation(geometry, rng):
    """Stated accuracy (omni, 640x480, blur 0.8 px, noise 3 grey levels): median
    < 0.1 deg, 95th percentile < 0.2 deg (1 px is about 0.43 deg here); every edge
    the truth marks visible is found, none is invented."""
    e, missed, invented = detect_omni_sampled_poses(omni_camera(geometry), geometry, rng, 60)
    assert missed == 0 and invented == 0
    assert np.median(e) < 0.1 and np.percentile(e, 95) < 0.2, (np.median(e),
                                                              np.percentile(e, 95))


def test_omni_detector_on_cluttered_background(geometry, rng):
    """Clutter (static textured background, lines, discs, rectangles): stated median
    < 0.15 deg and 95th percentile < 0.5 deg over the edges reported, at least 90 % of
    the visible edges reported, none where the truth sees no edge."""
    cam = omni_camera(geometry)
    r = Renderer(cam, geometry, RenderStyle(background="cluttered", blur_px=0.8,
                                            noise_std=3.0), rng=rng)
    det = OmniDetector(cam)
    Rs, ts = sample_poses(geometry, 40, rng)
    errs, found, visible, invented = [], 0, 0, 0
    for k in range(40):
        obs = observe_legs(cam, geometry, Rs[k], ts[k])
        d = det.detect(r.render(Rs[k], ts[k]), geometry=geometry)
        errs.append(angles_deg(d.normals, obs.normals)[d.edge_visible])
        found += int((d.edge_visible & obs.edge_visible).sum())
        visible += int(obs.edge_visible.sum())
        invented += int((d.edge_visible & ~obs.edge_visible).sum())
    e = np.concatenate(errs)
    assert found >= 0.9 * visible and invented == 0
    assert np.median(e) < 0.15 and np.percentile(e, 95) < 0.5, (np.median(e),
                                                               np.percentile(e, 95))


def test_perspective_tracker_accuracy(geometry, rng):
    """Stated accuracy (front camera, 1024x780, blur 0.8 px, noise 3 grey levels, a
    prediction 3 mm off in each axis): median < 0.02 deg, 95th percentile < 0.05 deg."""
    # Partly hidden edges may be measured from their visible part (and are then
    # accurate, see below); mostly hidden ones are never reported (checked inside).
    e, missed, _ = track_sampled_poses(front_camera(geometry), geometry, rng, 40)
    assert missed <= 2
    assert np.median(e) < 0.02 and np.percentile(e, 95) < 0.05, (np.median(e),
                                                                np.percentile(e, 95))


def test_perspective_tracker_on_cluttered_background(geometry, rng):
    cam = front_camera(geometry)
    r = Renderer(cam, geometry, RenderStyle(background="cluttered", blur_px=0.8,
                                            noise_std=3.0), rng=rng)
    tr = PerspectiveTracker(cam)
    Rs, ts = sample_poses(geometry, 15, rng)
    errs, found, visible = [], 0, 0
    for k in range(15):
        obs = observe_legs(cam, geometry, Rs[k], ts[k])
        d = tr.detect(r.render(Rs[k], ts[k]), LegPrediction.from_pose(cam, geometry, Rs[k],
                                                                       ts[k]))
        errs.append(angles_deg(d.normals, obs.normals)[d.edge_visible])
        found += int((d.edge_visible & obs.edge_visible).sum())
        visible += int(obs.edge_visible.sum())
    e = np.concatenate(errs)
    assert found >= 0.9 * visible
    assert np.percentile(e, 95) < 0.15


def test_occluded_edges_are_reported_missing(geometry):
    """Front camera, poses where an edge is hidden by another leg (visible fraction
    < 0.3 in vision.legs.observe_legs): the tracker never reports it, even with the
    exact prediction, and what it reports is accurate."""
    cam = front_camera(geometry)
    Rs, ts = sample_poses(geometry, 600, 11, max_translation=0.1, max_angle=np.deg2rad(20))
    obs = observe_legs(cam, geometry, Rs, ts)
    hidden = (obs.visible_fraction < 0.3) & obs.exists[..., None]
    idx = np.nonzero(hidden.any(axis=(1, 2)))[0][:25]
    assert idx.size >= 10
    r = Renderer(cam, geometry, STYLE, rng=3)
    tr = PerspectiveTracker(cam)
    n_hidden, errs = 0, []
    for i in idx:
        d = tr.detect(r.render(Rs[i], ts[i]), LegPrediction.from_pose(cam, geometry, Rs[i],
                                                                       ts[i]))
        assert not np.any(d.edge_visible & hidden[i])
        assert np.all(np.isnan(d.normals[hidden[i]]))
        n_hidden += int(hidden[i].sum())
        errs.append(angles_deg(d.normals, obs.normals[i])[d.edge_visible])
    assert n_hidden >= 10
    assert np.percentile(np.concatenate(errs), 95) < 0.1


@pytest.mark.parametrize("make_camera", [front_camera, omni_camera])
def test_nothing_is_invented_in_an_empty_image(geometry, make_camera):
    cam = make_camera(geometry)
    r = Renderer(cam, geometry, RenderStyle(noise_std=3.0, platform=False), rng=1)
    blank = r.background.copy()
    pred = LegPrediction.from_pose(cam, geometry)
    if cam.kind == "unified":
        d = OmniDetector(cam).detect(blank, pred)
    else:
        d = PerspectiveTracker(cam).detect(blank, pred)
    assert not d.edge_visible.any() and np.all(np.isnan(d.normals))
    assert np.all(d.quality == 0)


def _front_lens(geometry):
    return front_camera(geometry).replace(distortion=FRONT_DISTORTION)


def _omni_lens(geometry):
    return omni_camera(geometry).replace(distortion=OMNI_DISTORTION)


@pytest.mark.parametrize("make_camera", [front_camera, omni_camera, _front_lens, _omni_lens])
def test_edge_order_and_orientation_follow_legs_convention(geometry, make_camera):
    """n1 and n2 come in the order and with the signs of vision.legs.leg_edges (the
    leg direction u = n2 x n1 / |.| points from the base to the platform), with an
    ideal lens and through a distorting one."""
    cam = make_camera(geometry)
    R, t = home_pose(geometry)
    img = Renderer(cam, geometry, STYLE, rng=2).render(R, t)
    pred = LegPrediction.from_pose(cam, geometry, R, t)
    det = OmniDetector(cam) if cam.kind == "unified" else PerspectiveTracker(cam)
    d = det.detect(img, pred)
    obs = observe_legs(cam, geometry, R, t)
    assert d.edge_visible.all()
    assert np.all(np.sum(d.normals * obs.normals, -1) > 0.999)
    u = np.cross(d.normals[:, 1], d.normals[:, 0])
    u /= np.linalg.norm(u, axis=-1, keepdims=True)
    assert np.all(np.sum(u * obs.directions, -1) > 0.99)
    # Drawing works on the result.
    out = draw_detection(img, cam, d)
    assert out.shape == (cam.height, cam.width, 3)


def test_detector_input_errors(geometry):
    cam = omni_camera(geometry)
    det = OmniDetector(cam)
    with pytest.raises(DetectionError, match="size"):
        det.detect(np.zeros((100, 100), np.uint8), geometry=geometry)
    with pytest.raises(DetectionError, match="uint8"):
        det.detect(np.zeros((480, 640), np.float32), geometry=geometry)
    with pytest.raises(DetectionError, match="prediction"):
        det.detect(np.zeros((480, 640), np.uint8))
    with pytest.raises(DetectionError, match="d_max"):
        OmniDetector(cam, d_min=100, d_max=600)


def test_fit_normals_recovers_a_plane(rng):
    n = np.array([0.3, -0.2, 0.9])
    n /= np.linalg.norm(n)
    a = np.cross(n, [1.0, 0, 0])
    a /= np.linalg.norm(a)
    b = np.cross(n, a)
    th = rng.uniform(0, 1, 20)
    X = np.cos(th)[:, None] * a + np.sin(th)[:, None] * b
    w = np.ones(20)
    X[3] = [1.0, 0, 0]
    w[3] = 0  # a zero-weight outlier is ignored
    m, res = fit_normals(X, w)
    assert abs(abs(m @ n) - 1) < 1e-12
    assert np.all(res[w > 0] < 1e-12)
    # the zero-weight point keeps its true residual (a robust loop must not re-admit it)
    assert res[3] == pytest.approx(abs(n[0]), abs=1e-12)


@pytest.mark.parametrize("iterations", [1, 2])
def test_robust_fit_rejects_outliers_for_good(rng, iterations):
    """17 points of a plane (0.1 px noise) and 3 points 5 px off: the fit, the inlier
    count and the RMS are those of the 17, whatever the number of refits (a rejected
    point used to come back with a zero residual at the next refit)."""
    from vision.detect import _robust_fit

    normal = np.array([0.0, 0.0, 1.0])
    a = rng.uniform(0.0, 1.0, 20)
    px_per_rad = 1000.0
    rays = np.stack([np.cos(a), np.sin(a), rng.normal(0.0, 0.1 / px_per_rad, 20)], -1)
    rays[:3, 2] = 5.0 / px_per_rad
    rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
    batch = np.broadcast_to(rays, (6, 2, 20, 3)).copy()
    valid = np.ones((6, 2, 20), bool)
    predicted = np.broadcast_to(normal, (6, 2, 3))
    n, vis, cnt, rms, inl = _robust_fit(batch, valid, px_per_rad, predicted, 1.0, 5, 1.0,
                                        iterations=iterations)
    assert vis.all() and np.all(cnt == 17)
    assert not inl[..., :3].any() and inl[..., 3:].all()
    clean, _ = fit_normals(rays[3:], np.ones(17))
    assert np.allclose(np.abs(n @ clean), 1.0, atol=1e-12)
    assert np.all(rms < 0.3)  # the 0.1 px noise, not the 5 px outliers


def _pixel_distance(cam_found, normals, cam_true, obs) -> np.ndarray:
    """(6, 2) largest distance [px] of the true edge points (middle 60 %) from the
    pixel line each detected normal stands for (nan where not detected)."""
    from vision.legs import edge_points

    lines = cam_found.normal_to_pixel_line(normals)
    lines = lines / np.linalg.norm(lines[..., :2], axis=-1, keepdims=True)
    ep = edge_points(cam_true, obs.base_points, obs.directions, obs.radius, obs.lengths, 9,
                     normals=obs.normals, span=(0.2, 0.8))
    d = np.einsum("ijkx,ijx->ijk", ep.pixels, lines[..., :2]) + lines[..., None, 2]
    return np.max(np.abs(d), axis=-1)


@pytest.mark.parametrize("background", ["plain", "cluttered"])
def test_alignment_recovers_the_image_offset(geometry, rng, background):
    """A prediction displaced by (dx, dy) in the image is brought back by one
    translation within 1 px, on random poses, with clutter too."""
    cam = front_camera(geometry)
    r = Renderer(cam, geometry, RenderStyle(background=background, blur_px=0.8,
                                            noise_std=3.0), rng=rng)
    tr = PerspectiveTracker(cam)
    Rs, ts = sample_poses(geometry, 8, rng)
    for k in range(8):
        img = r.render(Rs[k], ts[k])
        pred = LegPrediction.from_pose(cam, geometry, Rs[k], ts[k])
        offset = rng.uniform(-30.0, 30.0, 2)
        lines = cam.normal_to_pixel_line(pred.normals)
        lines = lines / np.linalg.norm(lines[..., :2], axis=-1, keepdims=True)
        lines[..., 2] -= lines[..., 0] * offset[0] + lines[..., 1] * offset[1]
        moved = pred.with_normals(cam.pixel_line_to_normal(lines))
        shift, aligned = tr.align(img, moved, 40.0)
        assert np.all(np.abs(shift + offset) <= 1.0), (shift, offset)
        # the aligned prediction is the displaced one moved by the shift
        back = cam.normal_to_pixel_line(aligned.normals)
        back = back / np.linalg.norm(back[..., :2], axis=-1, keepdims=True)
        expected = lines[..., 2] - lines[..., 0] * shift[0] - lines[..., 1] * shift[1]
        assert np.allclose(back[..., :2], lines[..., :2], atol=1e-9)
        assert np.allclose(back[..., 2], expected, atol=1e-6)


def test_tracking_under_calibration_error_finds_every_edge(geometry, rng):
    """A miscalibrated camera (the prediction is 10-30 px off): ``track`` (alignment,
    then a 12 px search and a 4 px refinement) finds every edge the truth shows whole
    and clear of the other legs (an edge running against another leg in the image is
    dropped by the occlusion gate on purpose), each within 0.5 px of the true edge.
    Then, tracked with one edge lost in the previous frame, it finds them all again.
    (Where searching each edge over 40 px without alignment fails: the seed-002 goal,
    tests/benchmarks/test_simulate.py.)"""
    from vision.detect import _pixel_lines

    exact = PerspectiveTracker(cam := front_camera(geometry))
    est = miscalibrated(cam)
    r = Renderer(cam, geometry, RenderStyle(blur_px=0.8, noise_std=3.0), rng=rng)
    tr = PerspectiveTracker(est)
    Rs, ts = sample_poses(geometry, 30, rng)
    worst, whole = 0.0, 0
    for k in range(30):
        img = r.render(Rs[k], ts[k])
        obs = observe_legs(cam, geometry, Rs[k], ts[k])
        pred = LegPrediction.from_pose(est, geometry, Rs[k], ts[k])
        true_pred = LegPrediction.from_pose(cam, geometry, Rs[k], ts[k])
        seg = exact.predicted_segments(true_pred)
        lines = _pixel_lines(cam, true_pred.normals)
        clear = ~np.any(exact._contested(exact._samples(seg, lines)[1], seg, lines), axis=-1)
        shown = (obs.visible_fraction > 0.99) & clear
        whole += int(shown.sum())
        det = tr.track(img, pred)
        assert np.all(det.edge_visible[shown]), (k, det.edge_visible, shown)
        d = _pixel_distance(est, det.normals, cam, obs)
        worst = max(worst, float(np.max(d[shown])))
        if k == 0:
            prev = det.normals.copy()
            prev[1, 0] = np.nan  # lost in the previous frame
            again = tr.track(img, pred, prev)
            assert np.all(again.edge_visible[shown])
            assert np.max(_pixel_distance(est, again.normals, cam, obs)[shown]) < 0.5
    assert whole > 100
    assert worst < 0.5, worst
