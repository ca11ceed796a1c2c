"""Checks and set-ups shared by the vision tests (detection on rendered frames)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np

from hexapod import HexapodGeometry, Transform
from hexapod.se3 import exp_so3
from hexapod.workspace import sample_poses
from vision.cameras import Camera
from vision.detect import LegPrediction, OmniDetector, PerspectiveTracker
from vision.detect.curves import CurvedSamples, curved_samples, lift_near, pixels_per_radian
from vision.legs import limb_points, observe_legs
from vision.render import Renderer, RenderStyle

#: The accuracy tests' frames: blur 0.8 px, noise 3 grey levels.
STYLE = RenderStyle(blur_px=0.8, noise_std=3.0)


def same_detection(a: Any, b: Any) -> None:
    """Assert that two detections (compiled and numpy paths) agree: the same edges and
    point counts, normals to 1e-12, residuals and points to 1e-9, NaN where NaN."""
    assert np.array_equal(a.edge_visible, b.edge_visible)
    assert np.array_equal(a.n_points, b.n_points)
    m = a.edge_visible
    assert np.allclose(a.normals[m], b.normals[m], rtol=0, atol=1e-12)
    assert np.all(np.isnan(a.normals[~m])) and np.all(np.isnan(b.normals[~m]))
    assert np.allclose(a.residual[m], b.residual[m], rtol=0, atol=1e-9)
    assert np.array_equal(np.isnan(a.points), np.isnan(b.points))
    assert np.allclose(a.points, b.points, rtol=0, atol=1e-9, equal_nan=True)


def angles_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angles [deg] between unit vectors (..., 3) (NaN where either is NaN)."""
    return np.degrees(np.arccos(np.clip(np.sum(a * b, -1), -1.0, 1.0)))


class Tracked(NamedTuple):
    """Errors of the detections of sampled poses against the truth."""

    errors: np.ndarray  #: Angles [deg] of the reported edges' normals to the true ones.
    missed: int  #: Edges the truth sees and the detector did not report.
    invented: int  #: Edges reported where the truth sees none.


def _sampled_errors(cam: Camera, geometry: HexapodGeometry, rng: np.random.Generator,
                    n: int, detect: Callable[[np.ndarray, np.ndarray, np.ndarray, Any], Any]
                    ) -> Tracked:
    """Render ``n`` sampled poses (:data:`STYLE`), detect each with ``detect(image, R,
    t, truth)`` and tally the errors against the truth."""
    r = Renderer(cam, geometry, STYLE, rng=rng)
    Rs, ts = sample_poses(geometry, n, rng)
    errs, missed, invented = [], 0, 0
    for R, t in zip(Rs, ts, strict=True):
        obs = observe_legs(cam, geometry, R, t)
        d = detect(r.render(R, t), R, t, obs)
        errs.append(angles_deg(d.normals, obs.normals)[d.edge_visible])
        missed += int((obs.edge_visible & ~d.edge_visible).sum())
        invented += int((d.edge_visible & ~obs.edge_visible).sum())
    return Tracked(np.concatenate(errs), missed, invented)


def track_sampled_poses(cam: Camera, geometry: HexapodGeometry, rng: np.random.Generator,
                        n: int, offset: float = 0.003) -> Tracked:
    """Render ``n`` sampled poses (:data:`STYLE`) and track each with the prediction of
    the pose moved by ``offset`` [m] in each axis; assert that no mostly hidden edge
    (visible fraction < 0.25) is reported (partly hidden ones may be measured from their
    visible part)."""
    tr = PerspectiveTracker(cam)

    def detect(image: np.ndarray, R: np.ndarray, t: np.ndarray, obs: Any) -> Any:
        d = tr.detect(image, LegPrediction.from_pose(cam, geometry, R, t + offset))
        assert not np.any(d.edge_visible & (obs.visible_fraction < 0.25))
        return d

    return _sampled_errors(cam, geometry, rng, n, detect)


def detect_omni_sampled_poses(cam: Camera, geometry: HexapodGeometry,
                              rng: np.random.Generator, n: int) -> Tracked:
    """Render ``n`` sampled poses (:data:`STYLE`) and detect them without initialisation
    (the home-pose reference); assert that every reported edge has at least the
    detector's point count and at most its RMS residual."""
    det = OmniDetector(cam)

    def detect(image: np.ndarray, R: np.ndarray, t: np.ndarray, obs: Any) -> Any:
        d = det.detect(image, geometry=geometry)
        assert np.all(d.n_points[d.edge_visible] >= det.min_points)
        assert np.all(d.residual[d.edge_visible] <= det.max_rms_px)
        return d

    return _sampled_errors(cam, geometry, rng, n, detect)


def check_curved_samples(cam: Camera, geometry: HexapodGeometry
                         ) -> tuple[LegPrediction, CurvedSamples, np.ndarray, np.ndarray]:
    """Assert the curved samples of the home pose (24 along each edge, 3 px margin):
    each is the projection of its limb point, its search direction is normal to the
    curve (against a neighbouring projected point), the lift near a sample (12 px
    around) is the camera's lift, and the pixels per radian are those of a finite
    difference of ``n . lift(p)``.

    Returns:
        The prediction, the samples, the limb points (6, 2, 24, 3) [m] and their pixels.
    """
    pred = LegPrediction.from_pose(cam, geometry)
    t = np.linspace(0.06, 0.94, 24)
    cs = curved_samples(cam, pred, t, 3.0)
    P = limb_points(pred.base_points, pred.directions, pred.radius, pred.lengths,
                    pred.normals, t)
    pix, _ = cam.project(P)
    assert np.abs(pix - cs.P).max() < 1e-9
    ahead, _ = cam.project(limb_points(pred.base_points, pred.directions, pred.radius,
                                       pred.lengths, pred.normals, t + 1e-6))
    tangent = ahead - pix
    cos = np.sum(tangent * cs.out, -1) / np.linalg.norm(tangent, axis=-1)
    assert np.abs(cos).max() < 1e-6
    q = cs.P + np.random.default_rng(0).uniform(-12.0, 12.0, cs.P.shape)
    rays, m = lift_near(cam, q, cs.m)
    assert np.abs(rays - cam.lift(q)).max() < 1e-12
    n = pred.normals
    e = 1e-4

    def f(p: np.ndarray) -> np.ndarray:
        return np.einsum("ijkx,ijx->ijk", cam.lift(p), n)

    ex, ey = np.array([e, 0.0]), np.array([0.0, e])
    grad = np.hypot(f(q + ex) - f(q - ex), f(q + ey) - f(q - ey))
    assert np.abs(pixels_per_radian(cam, m, n) * grad / (2 * e) - 1.0).max() < 1e-6
    return pred, cs, P, pix


def miscalibrated(cam: Camera) -> Camera:
    """The camera as a user would estimate it: 0.8 deg and 8 mm off, principal point
    6 px and 5 px off, focal length 1 % off (typical of a hand calibration)."""
    T = cam.camera_from_base
    dR = exp_so3(np.deg2rad(0.8) * np.array([0.6, -0.48, 0.64]))
    K = cam.K.copy()
    K[0, 0] *= 1.01
    K[0, 2] += 6.0
    K[1, 2] -= 5.0
    return cam.replace(K=K, camera_from_base=Transform(dR @ T.rotation,
                                                       dR @ T.translation + [0.008, 0, 0]))
