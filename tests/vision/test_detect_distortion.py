"""Leg-edge detection on rendered frames through distorted lenses (known truth).

The cameras are the presets with the distortions of vision.cameras.presets
(FRONT_DISTORTION: k1 = -0.28, a 4.8 mm lens; OMNI_DISTORTION: a mild Mei distortion
with decentring terms) and a radial-only Mei distortion (the omnidirectional image
keeps its rotational symmetry: the detector's one-call compiled path).
"""

from __future__ import annotations

import numpy as np
import pytest

from hexapod.workspace import sample_poses
from tests.vision.detection_checks import (
    STYLE,
    angles_deg,
    check_curved_samples,
    detect_omni_sampled_poses,
    miscalibrated,
    same_detection,
    track_sampled_poses,
)
from vision.cameras import FRONT_DISTORTION, OMNI_DISTORTION, front_camera, omni_camera
from vision.detect import LegPrediction, OmniDetector, PerspectiveTracker
from vision.detect.curves import curved_samples, lift_near, pixels_per_radian
from vision.legs import edge_points, observe_legs
from vision.render import Renderer, RenderStyle

#: A radial-only Mei distortion (no decentring terms).
OMNI_RADIAL = (-0.08, 0.012, 0.0, 0.0)


def _front(geometry):
    return front_camera(geometry).replace(distortion=FRONT_DISTORTION)


def _omni(geometry, distortion=OMNI_DISTORTION):
    return omni_camera(geometry).replace(distortion=distortion)


# ----------------------------------------------------------------- curved samples
def test_curved_samples_lie_on_the_predicted_curves(geometry):
    """Every sample is the projection of its limb point, its search direction is
    normal to the curve (checked against a neighbouring projected point) and points
    out of the leg; the lift near a sample equals the camera's lift; the pixels per
    radian are those of a finite difference of ``n . lift(p)``."""
    cam = _front(geometry)
    pred, cs, P, pix = check_curved_samples(cam, geometry)
    outside, _ = cam.project(P + 0.001 * pred.normals[:, :, None, :])
    assert np.all(np.sum((outside - pix) * cs.out, -1) > 0)
    assert np.all(cs.margin >= 3.0) and np.all(cs.margin < 4.0)  # barrel: compressed


# ----------------------------------------------------------------- accuracy
def test_tracker_accuracy_on_distorted_frames(geometry, rng):
    """Front camera through the 4.8 mm lens's distortion (k1 = -0.28), blur 0.8 px,
    noise 3 grey levels, a prediction 3 mm off, the frames of
    tests/vision/test_detect.py's accuracy test (same seed): within 1.5 times the
    undistorted figures of those frames (median 0.0104 deg, 95th percentile 0.0223
    deg: bounds 0.0156 and 0.0334 deg); measured through the lens: 0.0108 and 0.0279
    deg, 1 visible edge missed (at most 2 allowed, as undistorted), none mostly hidden
    reported."""
    e, missed, _ = track_sampled_poses(_front(geometry), geometry, rng, 40)
    assert missed <= 2
    assert np.median(e) < 0.0156 and np.percentile(e, 95) < 0.0334, (np.median(e),
                                                                    np.percentile(e, 95))


@pytest.mark.slow
@pytest.mark.parametrize("distortion", [OMNI_DISTORTION, OMNI_RADIAL])
def test_omni_detector_accuracy_on_distorted_frames(geometry, rng, distortion):
    """Omnidirectional camera with a mild Mei distortion, no initialisation, the frames
    of tests/vision/test_detect.py's accuracy test (same seed): every visible edge
    found, none invented, within 1.5 times the undistorted figures of those frames
    (median 0.0631 deg, 95th percentile 0.1201 deg: bounds 0.095 and 0.180 deg);
    measured: 0.0645 / 0.1246 deg with the decentring terms (the image is not
    rotationally symmetric: association reference and rays from the camera model),
    0.0648 / 0.1238 deg radial-only (the one-call compiled path). The barrel
    distortion compresses the image (fewer pixels per radian), hence slightly larger
    angles for the same pixel accuracy."""
    cam = _omni(geometry, distortion)
    assert OmniDetector(cam)._isotropic == (distortion is OMNI_RADIAL)
    e, missed, invented = detect_omni_sampled_poses(cam, geometry, rng, 60)
    assert missed == 0 and invented == 0
    assert np.median(e) < 0.095 and np.percentile(e, 95) < 0.180, (np.median(e),
                                                                  np.percentile(e, 95))


def test_the_pipeline_without_the_distortion_model_is_wrong(geometry, rng):
    """The test above can fail: the same distorted frames read with the camera model
    that ignores the distortion are off by several tenths of a degree."""
    cam = _front(geometry)
    ideal = cam.replace(distortion=None)
    r = Renderer(cam, geometry, STYLE, rng=rng)
    Rs, ts = sample_poses(geometry, 5, rng)
    errs = []
    for k in range(5):
        obs = observe_legs(cam, geometry, Rs[k], ts[k])
        d = PerspectiveTracker(ideal).detect(
            r.render(Rs[k], ts[k]), LegPrediction.from_pose(ideal, geometry, Rs[k], ts[k]))
        errs.append(angles_deg(d.normals, obs.normals)[d.edge_visible])
    assert np.median(np.concatenate(errs)) > 0.2


def test_tracking_under_calibration_error_on_distorted_frames(geometry, rng):
    """tests/vision/test_detect.py's calibration-error test through the distorted lens
    (the same pose, intrinsics and principal point errors; the estimated distortion
    exact): ``track`` (alignment of the curved prediction, a 12 px search, a 4 px
    refinement) finds every edge the truth shows whole and clear of the other legs,
    each within 0.5 px of the true curved edge (measured: 0.25 px at worst)."""
    cam = _front(geometry)
    est = miscalibrated(cam)
    exact, tr = PerspectiveTracker(cam), PerspectiveTracker(est)
    r = Renderer(cam, geometry, STYLE, rng=rng)
    Rs, ts = sample_poses(geometry, 20, rng)
    worst, whole = 0.0, 0
    for k in range(20):
        img = r.render(Rs[k], ts[k])
        obs = observe_legs(cam, geometry, Rs[k], ts[k])
        cs = curved_samples(cam, LegPrediction.from_pose(cam, geometry, Rs[k], ts[k]),
                            exact._positions(), exact.occlusion_margin_px)
        clear = ~np.any(exact._contested(cs.gate, cs.seg, cs.lines, cs.margin), axis=-1)
        shown = (obs.visible_fraction > 0.99) & clear
        whole += int(shown.sum())
        det = tr.track(img, LegPrediction.from_pose(est, geometry, Rs[k], ts[k]))
        assert np.all(det.edge_visible[shown]), (k, det.edge_visible, shown)
        ep = edge_points(cam, obs.base_points, obs.directions, obs.radius, obs.lengths, 9,
                         normals=obs.normals, span=(0.2, 0.8))
        rays, m = est.lift(ep.pixels), est.pixels_to_normalised(ep.pixels)
        dist = (np.abs(np.einsum("ijkx,ijx->ijk", rays, det.normals))
                * pixels_per_radian(est, m, det.normals))
        worst = max(worst, float(np.max(dist[shown])))
    assert whole > 60
    assert worst < 0.5, worst


def test_occluded_edges_are_reported_missing_through_the_lens(geometry):
    """Edges hidden by another leg (visible fraction < 0.3) are never reported by the
    curved tracker, even with the exact prediction (the occlusion gate in the ideal
    image); what it reports is accurate (95th percentile < 0.1 deg)."""
    cam = _front(geometry)
    Rs, ts = sample_poses(geometry, 600, 11, max_translation=0.1, max_angle=np.deg2rad(20))
    obs = observe_legs(cam, geometry, Rs, ts)
    hidden = (obs.visible_fraction < 0.3) & obs.exists[..., None]
    idx = np.nonzero(hidden.any(axis=(1, 2)))[0][:20]
    assert idx.size >= 10
    r = Renderer(cam, geometry, STYLE, rng=3)
    tr = PerspectiveTracker(cam)
    errs = []
    for i in idx:
        d = tr.detect(r.render(Rs[i], ts[i]),
                      LegPrediction.from_pose(cam, geometry, Rs[i], ts[i]))
        assert not np.any(d.edge_visible & hidden[i])
        errs.append(angles_deg(d.normals, obs.normals[i])[d.edge_visible])
    assert np.percentile(np.concatenate(errs), 95) < 0.1


# ----------------------------------------------------------------- alignment
@pytest.mark.parametrize("background", ["plain", "cluttered"])
def test_curved_alignment_recovers_the_image_offset(geometry, rng, background):
    """A curved prediction displaced by (dx, dy) in the image (its samples moved, lifted,
    refitted) is brought back by one translation within 1 px, and both paths agree."""
    cam = _front(geometry)
    r = Renderer(cam, geometry, RenderStyle(background=background, blur_px=0.8,
                                            noise_std=3.0), rng=rng)
    tr = PerspectiveTracker(cam)
    Rs, ts = sample_poses(geometry, 6, rng)
    for k in range(6):
        img = r.render(Rs[k], ts[k])
        pred = LegPrediction.from_pose(cam, geometry, Rs[k], ts[k])
        offset = rng.uniform(-30.0, 30.0, 2)
        cs = curved_samples(cam, pred, tr._positions(), 3.0)
        rays, _ = lift_near(cam, cs.P + offset, cs.m)
        from vision.detect import fit_normals

        n, _ = fit_normals(rays, np.ones(rays.shape[:-1]))
        n = np.where(np.sum(n * pred.normals, -1, keepdims=True) < 0, -n, n)
        moved = pred.with_normals(n)
        shift, aligned = tr.align(img, moved, 40.0)
        assert np.all(np.abs(shift + offset) <= 1.0), (shift, offset)
        b, pb = tr.align(img, moved, 40.0, use_compiled=False)
        assert np.array_equal(shift, b)
        assert np.allclose(aligned.normals, pb.normals, atol=1e-12, equal_nan=True)
        # The aligned curves: the plane fits of the samples moved by offset + shift
        # (a translated curve is not exactly the image of a plane).
        rays, _ = lift_near(cam, cs.P + offset + shift, cs.m)
        gap = np.abs(np.einsum("ijkx,ijx->ijk", rays, aligned.normals)) * cam.fx
        assert gap.max() < 0.2, gap.max()


# ----------------------------------------------------------------- compiled == numpy
@pytest.mark.parametrize("distortion", [OMNI_DISTORTION, OMNI_RADIAL])
def test_compiled_omni_detection_on_distorted_frames_equals_numpy(geometry, rng, distortion):
    cam = _omni(geometry, distortion)
    r = Renderer(cam, geometry, RenderStyle(background="cluttered", blur_px=0.8,
                                            noise_std=4.0), rng=rng)
    det = OmniDetector(cam)
    Rs, ts = sample_poses(geometry, 10, rng)
    for k in range(10):
        img = r.render(Rs[k], ts[k])
        pred = LegPrediction.from_pose(cam, geometry, Rs[k], ts[k]) if k % 2 else None
        a = det.detect(img, pred, geometry=geometry, use_compiled=True)
        b = det.detect(img, pred, geometry=geometry, use_compiled=False)
        same_detection(a, b)


# ----------------------------------------------------------------- conventions
def test_predicted_segments_end_on_the_curves(geometry):
    """Through a distorted lens the predicted segments' ends lie on the predicted curves
    (the curves' samples at t = 0 and 1), not on the ideal image's lines (several
    pixels away from them)."""
    cam = _front(geometry)
    tr = PerspectiveTracker(cam)
    pred = LegPrediction.from_pose(cam, geometry)
    seg = tr.predicted_segments(pred)
    ends = curved_samples(cam, pred, np.array([0.0, 1.0]), 3.0).P
    assert np.abs(seg - ends).max() < 1e-9
    from vision.detect import _pixel_lines

    lines = _pixel_lines(cam, pred.normals)  # the ideal image's lines K^-T n
    d = np.sum(lines[:, :, None, :2] * seg, -1) + lines[:, :, None, 2]
    assert np.abs(d).max() > 1.0


@pytest.mark.parametrize("make_camera", [_front, _omni])
def test_image_sensor_through_a_distorted_lens(geometry, make_camera):
    """The simulator's image sensor (render through the lens, track, fit) on a sequence
    of poses, each frame tracked from the previous one: every edge the truth shows
    whole is measured, within 0.05 deg (front) or 0.3 deg (omni) at the 95th
    percentile (the accuracy tests' bounds with a margin: here the previous frame's
    normals, not the pose, give the prediction)."""
    from vision.image_sensor import ImageSensor

    cam = make_camera(geometry)
    sensor = ImageSensor(cam, cam, geometry, rng=1)
    Rs, ts = sample_poses(geometry, 8, 2, max_translation=0.01, max_angle=np.deg2rad(2))
    previous, errs = None, []
    for R, t in zip(Rs, ts, strict=True):
        m = sensor.measure(R, t, previous)
        previous = m.normals
        obs = observe_legs(cam, geometry, R, t)
        whole = obs.visible_fraction > 0.99
        assert np.all(m.edge_visible[whole])
        errs.append(angles_deg(m.normals, obs.normals)[m.edge_visible & obs.edge_visible])
    bound = 0.05 if cam.kind == "perspective" else 0.3
    assert np.percentile(np.concatenate(errs), 95) < bound
