"""Rendering through a distorted lens: the limbs are curves, drawn within 0.02 px."""

from __future__ import annotations

import numpy as np
import pytest

from hexapod.workspace import sample_poses
from tests.vision.coverage_checks import limb_column
from vision.cameras import FRONT_DISTORTION, OMNI_DISTORTION, front_camera, omni_camera
from vision.legs import limb_points, observe_legs
from vision.render import Renderer, RenderError, RenderStyle
from vision.render_curves import projected_polylines


def _front(geometry):
    return front_camera(geometry).replace(distortion=FRONT_DISTORTION)


def _omni(geometry):
    return omni_camera(geometry).replace(distortion=OMNI_DISTORTION)


def _distance_to_polyline(points: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """(N,) distance [px] of points (N, 2) to the polyline (V, 2)."""
    a, d = poly[:-1], np.diff(poly, axis=0)
    ap = points[:, None, :] - a[None]
    t = np.clip(np.sum(ap * d, -1) / np.maximum(np.sum(d * d, -1), 1e-300), 0.0, 1.0)
    return np.min(np.linalg.norm(ap - t[..., None] * d[None], axis=-1), axis=1)


def _true_limbs(cam, geometry, R, t, n: int = 4001) -> tuple[np.ndarray, object]:
    """(6, 2, n, 2) pixels of the true limbs sampled densely, and the observation."""
    obs = observe_legs(cam, geometry, R, t)
    s = np.linspace(0.0, 1.0, n)
    P = limb_points(obs.base_points, obs.directions, obs.radius, obs.lengths, obs.normals, s)
    pix, _ = cam.project(P)
    return pix, obs


@pytest.mark.slow
@pytest.mark.parametrize("make_camera", [_front, _omni])
def test_drawn_limbs_are_within_0_02_px_of_the_true_curves(geometry, rng, make_camera):
    """The silhouette's sides (the polygons the exact renderer fills) against the true
    limbs, projected with the camera at 4001 points each: every point within 0.02 px
    of the drawn polyline, and every vertex on the true curve (it is a projection of a
    point of the limb). The limbs are really curved: the chord between the two ends of
    a limb is more than 1 px away from it somewhere (a straight polygon would fail)."""
    cam = make_camera(geometry)
    r = Renderer(cam, geometry)
    Rs, ts = sample_poses(geometry, 6, rng)
    worst, sag = 0.0, 0.0
    for R, t in zip(Rs, ts, strict=True):
        true, obs = _true_limbs(cam, geometry, R, t)
        limbs = r.limb_polylines(R, t)
        for i in range(6):
            for j in range(2):
                poly = limbs[i][j]
                assert poly is not None and obs.exists[i]
                assert np.allclose(poly[0], true[i, j, 0], atol=1e-9)
                assert np.allclose(poly[-1], true[i, j, -1], atol=1e-9)
                worst = max(worst, float(_distance_to_polyline(true[i, j], poly).max()))
                assert _distance_to_polyline(poly, true[i, j]).max() < 1e-3
                sag = max(sag, float(_distance_to_polyline(true[i, j], poly[[0, -1]]).max()))
    assert worst < 0.02, worst
    assert sag > 1.0, sag


@pytest.mark.slow
def test_row_coverage_across_a_curved_limb_is_the_true_limb_position(geometry, rng):
    """tests/vision/test_render.py's row-coverage test through the front camera's
    distorted lens: along an image row, the coverage summed across a limb gives the
    limb's position at that row; the true position is interpolated on the limb's image
    sampled at 4001 points. Every row within 0.02 px, median below 0.005 px."""
    cam = _front(geometry)
    style = RenderStyle(shading_bands=1, platform=False)
    bg, lv = float(style.background_level), float(style.leg_edge_level)
    r = Renderer(cam, geometry, style)
    assert r.exact
    Rs, ts = sample_poses(geometry, 4, rng)
    errors = []
    for R, t in zip(Rs, ts, strict=True):
        img = r.render(R, t).astype(float)
        true, obs = _true_limbs(cam, geometry, R, t)
        # each limb's samples in increasing image row, sorted once per pose
        order = np.argsort(true[..., 1], axis=-1)
        by_row = np.take_along_axis(true, order[..., None], axis=2)

        def x_at(i: int, j: int, y: float, by_row: np.ndarray = by_row) -> float:
            c = by_row[i, j]
            return float(np.interp(y, c[:, 1], c[:, 0]))

        def other_leg_near(i: int, y: int, xa: float, xb: float,
                           true: np.ndarray = true) -> bool:
            for k in range(6):
                ys = true[k, :, :, 1]
                if k == i or not ys.min() - 15 <= y <= ys.max() + 15:
                    continue
                xk = [x_at(k, e, y) for e in range(2)]
                if max(xk) >= xa - 15 and min(xk) <= xb + 15:
                    return True
            return False

        for i in range(6):
            for j in range(2):
                if not obs.edge_visible[i, j]:
                    continue
                c = true[i, j]
                dy = np.diff(c[:, 1])
                if not (np.all(dy > 0) or np.all(dy < 0)):
                    continue
                d = np.diff(c, axis=0)
                if np.any(np.abs(d[:, 1]) < 0.5 * np.hypot(d[:, 0], d[:, 1])):
                    continue  # shallow edge: rows cross it obliquely
                n = c.shape[0]
                for y in np.unique(np.rint(c[int(0.3 * n):int(0.7 * n), 1]).astype(int)):
                    x_true = x_at(i, j, y)
                    x0 = int(np.floor(x_true)) - 4
                    if other_leg_near(i, y, x0, x0 + 9):
                        continue
                    x_est = limb_column(img[y], x0, bg, lv)
                    if x_est is None:
                        continue  # another leg in the window (not one monotonic step)
                    errors.append(x_est - x_true)
    e = np.abs(np.array(errors))
    assert e.size > 300
    assert e.max() < 0.02 and np.median(e) < 0.005, (e.max(), np.median(e))


def test_an_ideal_lens_is_drawn_as_before(geometry, rng):
    """Zero coefficients are an ideal lens: the same straight two-point limbs and the
    same pixels as a camera given no distortion at all."""
    cam = front_camera(geometry)
    zero = cam.replace(distortion=(0.0, 0.0, 0.0, 0.0, 0.0))
    assert not zero.is_distorted
    Rs, ts = sample_poses(geometry, 3, rng)
    a, b = Renderer(cam, geometry, rng=1), Renderer(zero, geometry, rng=1)
    for R, t in zip(Rs, ts, strict=True):
        assert np.array_equal(a.render(R, t), b.render(R, t))
        assert all(len(limb) == 2 for leg in a.limb_polylines(R, t) for limb in leg
                   if limb is not None)


def test_polyline_tolerance_and_settings(geometry):
    """A coarser tolerance gives fewer vertices, each chord's midpoint within it; a
    segment behind the camera is not refined (NaN vertices); the setting is checked."""
    cam = _front(geometry)
    a = np.array([[-0.3, -0.2, 0.8], [0.0, 0.0, -1.0]])
    b = np.array([[0.3, 0.25, 0.9], [0.1, 0.0, 1.0]])
    s0 = np.linspace(0.0, 1.0, 3)
    fine = projected_polylines(cam, a, b, s0, 0.005)
    coarse = projected_polylines(cam, a, b, s0, 0.2)
    assert 2 < len(coarse[0]) < len(fine[0])
    dense, _ = cam.project(a[0] + np.linspace(0, 1, 5001)[:, None] * (b[0] - a[0]))
    assert _distance_to_polyline(dense, coarse[0]).max() < 0.25
    assert _distance_to_polyline(dense, fine[0]).max() < 0.01
    assert len(fine[1]) == 3 and np.isnan(fine[1]).any()
    # a segment running beyond the lens's fold (wide off axis): its pixels there are
    # OpenCV's, of no image, and were split at every level (24 levels: a picture of a
    # camera at the base origin took 28 s); the imaged part is refined as before
    wide = np.array([[0.0, 0.0, 1.0]]), np.array([[1.0, 0.5, 0.001]])
    assert cam.imaged(wide[0])[0] and not cam.imaged(wide[1])[0]
    (poly,) = projected_polylines(cam, *wide, s0, 0.005)
    assert len(poly) < 100, len(poly)  # (90063 vertices before)
    assert np.isnan(poly[-1]).all()  # the end beyond the fold: no pixel (it was -2.4e22)
    assert np.isfinite(poly[0]).all()
    inside = np.linspace(0.0, 1.0, 3001)[:, None] * wide[1]
    inside = inside[cam.imaged(inside + wide[0])] + wide[0]
    near, _ = cam.project(inside[: len(inside) // 2])  # the half away from the fold
    assert _distance_to_polyline(near, poly[np.isfinite(poly).all(axis=1)]).max() < 0.01
    with pytest.raises(RenderError, match="curve_tolerance_px"):
        RenderStyle(curve_tolerance_px=0.0)
