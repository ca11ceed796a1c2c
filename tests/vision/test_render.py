"""Rendering of the legs: image content, edges at the true limbs, noise, clutter, speed."""

from __future__ import annotations

import numpy as np
import pytest

from hexapod.workspace import home_pose, sample_poses
from tests.vision.coverage_checks import limb_column
from vision.cameras import FRONT_DISTORTION, OMNI_DISTORTION, front_camera, omni_camera
from vision.legs import edge_points, observe_legs
from vision.render import Renderer, RenderError, RenderStyle, render_legs


@pytest.mark.parametrize("make_camera", [front_camera, omni_camera])
def test_legs_are_dark_on_the_plain_background(geometry, make_camera):
    cam = make_camera(geometry)
    R, t = home_pose(geometry)
    img = render_legs(cam, geometry, R, t, RenderStyle(platform=False))
    assert img.shape == (cam.height, cam.width) and img.dtype == np.uint8
    obs = observe_legs(cam, geometry, R, t)
    # Points on the leg axes (middle third) are dark, the image corners are background.
    s = np.linspace(0.35, 0.65, 9)
    P = obs.base_points[:, None, :] + (s[None, :, None] * obs.lengths[:, None, None]) \
        * obs.directions[:, None, :]
    pix, vis = cam.project(P)
    px = np.round(pix[vis]).astype(int)
    assert px.shape[0] > 20
    assert np.all(img[px[:, 1], px[:, 0]] < 110)
    assert img[0, 0] == 230 and img[-1, -1] == 230


def test_row_coverage_across_a_limb_is_the_true_limb_position(geometry, rng):
    """Exact coverage (box filter of the pixel): along an image row, the coverage summed
    across a straight limb is the distance from the window's border to the limb, so it
    gives the limb's position at that row exactly (up to the grey-level rounding, about
    0.003 px per pixel). Checked against the true limb lines ``l ~ K^-T n`` of
    ``observe_legs`` on random poses: every row within 0.02 px, median below 0.005 px.
    (OpenCV's anti-aliased polygons, the fallback, are off by up to about 0.1 px.)"""
    cam = front_camera(geometry)
    style = RenderStyle(shading_bands=1, platform=False)
    bg, lv = float(style.background_level), float(style.leg_edge_level)
    r = Renderer(cam, geometry, style)
    assert r.exact
    Rs, ts = sample_poses(geometry, 4, rng)
    errors = []
    for R, t in zip(Rs, ts, strict=True):
        img = r.render(R, t).astype(float)
        obs = observe_legs(cam, geometry, R, t)
        lines = cam.normal_to_pixel_line(obs.normals)  # (6, 2, 3) in raw pixels
        ep = edge_points(cam, obs.base_points, obs.directions, obs.radius, obs.lengths, 40,
                         normals=obs.normals, span=(0.3, 0.7))
        ends, _ = cam.project(obs.base_points[:, None] + obs.lengths[:, None, None]
                              * np.array([0.0, 1.0])[None, :, None] * obs.directions[:, None])

        def other_leg_near(i: int, y: int, xa: float, xb: float, ends: np.ndarray = ends,
                           lines: np.ndarray = lines) -> bool:
            for k in range(6):
                ys = ends[k, :, 1]
                if k == i or not ys.min() - 15 <= y <= ys.max() + 15:
                    continue
                xk = [-(lb * y + lc) / la for la, lb, lc in lines[k]]
                if max(xk) >= xa - 15 and min(xk) <= xb + 15:
                    return True
            return False

        for i in range(6):
            for j in range(2):
                if not obs.edge_visible[i, j]:
                    continue
                a, b, c = lines[i, j]
                if abs(a) < 0.5 * np.hypot(a, b):  # shallow edge: rows cross it obliquely
                    continue
                for y in np.unique(np.rint(ep.pixels[i, j][ep.visible[i, j], 1]).astype(int)):
                    x_true = -(b * y + c) / a
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


def _front_lens(geometry):
    return front_camera(geometry).replace(distortion=FRONT_DISTORTION)


def _omni_lens(geometry):
    return omni_camera(geometry).replace(distortion=OMNI_DISTORTION)


@pytest.mark.slow
@pytest.mark.parametrize("exact", [True, False])
@pytest.mark.parametrize("make_camera", [front_camera, omni_camera, _front_lens, _omni_lens])
def test_rendered_edges_lie_on_the_true_limbs(geometry, make_camera, exact):
    """The 50 % grey level across each limb (read by bilinear interpolation, itself off
    by a few hundredths of a pixel on oblique edges, along the image normal of the
    curve: the gradient of ``n . lift(p)``, the lift removing any distortion) is near
    the true limb: median 0.15 px and 95th percentile 0.4 px for both renderers,
    0.07 / 0.12 px for the exact one, with an ideal lens and through a distorting one."""
    cam = make_camera(geometry)
    R, t = home_pose(geometry)
    img = Renderer(cam, geometry, RenderStyle(shading_bands=1, platform=False),
                   use_compiled=exact).render(R, t)
    obs = observe_legs(cam, geometry, R, t)
    ep = edge_points(cam, obs.base_points, obs.directions, obs.radius, obs.lengths, 12,
                     normals=obs.normals, span=(0.3, 0.7))
    import cv2

    errors = []
    for i in range(6):
        for j in range(2):
            n = obs.normals[i, j]
            for p, v in zip(ep.pixels[i, j], ep.visible[i, j], strict=True):
                if not v:
                    continue
                # Image direction of the normal of the edge: gradient of n.lift(p).
                e = 1e-3
                dx, dy = np.array([e, 0.0]), np.array([0.0, e])
                g = np.array([n @ cam.lift(p + dx) - n @ cam.lift(p - dx),
                              n @ cam.lift(p + dy) - n @ cam.lift(p - dy)])
                g /= np.linalg.norm(g)  # points outwards (n.X > 0 outside the leg)
                s = np.linspace(-3, 3, 601)
                q = (p[None] + s[:, None] * g[None]).astype(np.float32)
                prof = cv2.remap(img.astype(np.float32), q[:, :1].T.copy(), q[:, 1:].T.copy(),
                                 cv2.INTER_LINEAR)[0]
                level = 0.5 * (35.0 + 230.0)
                k = np.argmax(prof > level)
                errors.append(s[k])
    errors = np.abs(np.array(errors))
    assert errors.size > 60
    p95 = np.percentile(errors, 95)
    assert np.median(errors) < 0.15 and p95 < 0.4, (np.median(errors), p95)
    if exact:
        assert np.median(errors) < 0.07 and p95 < 0.12, (np.median(errors), p95)


def test_noise_and_determinism(geometry):
    cam = omni_camera(geometry)
    R, t = home_pose(geometry)
    a = Renderer(cam, geometry, RenderStyle(noise_std=4.0), rng=5).render(R, t)
    b = Renderer(cam, geometry, RenderStyle(noise_std=4.0), rng=5).render(R, t)
    c = Renderer(cam, geometry, RenderStyle(noise_std=4.0), rng=6).render(R, t)
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    patch = a[:40, :40].astype(float)  # plain background
    assert 3.0 < patch.std() < 5.0 and abs(patch.mean() - 230) < 1.0


def test_cluttered_background_is_textured_and_brighter_than_legs(geometry):
    cam = front_camera(geometry)
    r = Renderer(cam, geometry, RenderStyle(background="cluttered", platform=False))
    bg = r.background
    assert bg.std() > 10 and bg.min() >= r.style.clutter_min
    img = r.render(*home_pose(geometry))
    assert not np.array_equal(img, bg) and img.min() < 60


def test_default_renderer_fills_by_compiled_coverage_on_both_cameras(geometry, rng):
    """The default renderer of either camera, blurred and noisy, takes the compiled
    filler (the fast path), and keeps it through ``with_style``. (Its speed is measured
    by ``python -m benchmarks.perf.detect``, not asserted here.)"""
    from vision import kernels

    assert kernels.available()  # the test machines compile C kernels
    Rs, ts = sample_poses(geometry, 2, rng)
    for cam in (front_camera(geometry), omni_camera(geometry)):
        r = Renderer(cam, geometry, RenderStyle(blur_px=0.8, noise_std=2.0), rng=1)
        assert r.exact, cam.name
        assert r.with_style(noise_std=0.0).exact, cam.name
        img = r.render(Rs[1], ts[1])
        assert img.shape == (cam.height, cam.width) and img.dtype == np.uint8


def test_invalid_settings_raise(geometry):
    with pytest.raises(RenderError, match="background"):
        RenderStyle(background="stripes")
    with pytest.raises(RenderError, match="blur_px"):
        RenderStyle(blur_px=-1)
    r = Renderer(front_camera(geometry), geometry)
    with pytest.raises(RenderError, match="pose"):
        r.render(np.eye(3), np.array([0.0, np.nan, 0.3]))


def _ray_hits(rays: np.ndarray, geometry, cam, R: np.ndarray, t: np.ndarray,
              disc_radius: float) -> np.ndarray:
    """(N, 7) distance along each unit ray to the six finite leg cylinders and the
    platform disc (inf where missed), by direct ray casting."""
    from hexapod.kinematics import legs_in_frame

    T = cam.camera_from_base
    legs = legs_in_frame(geometry, R, t, T)
    r = geometry.leg_radius
    hits = np.full((rays.shape[0], 7), np.inf)
    for i in range(6):
        A, u = legs.base_points[i], legs.directions[i]
        dp = rays - np.outer(rays @ u, u)  # ray direction across the axis
        ap = -A - (-A @ u) * u  # camera centre across the axis
        a, b, c = np.sum(dp * dp, -1), 2.0 * dp @ ap, ap @ ap - r * r
        disc = b * b - 4 * a * c
        with np.errstate(invalid="ignore"):
            s = (-b - np.sqrt(disc)) / (2 * a)  # first intersection
        along = (s[:, None] * rays - A) @ u
        hit = (disc >= 0) & (s > 0) & (along >= 0) & (along <= legs.lengths[i])
        hits[hit, i] = s[hit]
    centre, normal = T.apply(t), (T.rotation @ R)[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (centre @ normal) / (rays @ normal)
    hit = (s > 0) & (np.linalg.norm(s[:, None] * rays - centre, axis=-1) <= disc_radius)
    hits[hit, 6] = s[hit]
    return hits


@pytest.mark.slow
@pytest.mark.parametrize("make_camera", [front_camera, omni_camera])
def test_draw_order_is_the_order_of_the_true_depths(geometry, rng, make_camera):
    """Wherever two objects (legs, platform disc) overlap in the image, the one the
    painter's algorithm draws last is the nearest along the pixel's ray (ray casting
    on a 3-pixel grid, random poses). Exception, left out: within two leg radii of a
    leg's top end the cylinder crosses the plane of the disc around its joint (the
    objects interpenetrate; no drawing order is right there; the detectors do not use
    the ends of the legs)."""
    from hexapod.kinematics import legs_in_frame

    cam = make_camera(geometry)
    r = Renderer(cam, geometry)
    ys, xs = np.mgrid[0:cam.height:3, 0:cam.width:3]
    rays = cam.lift(np.stack([xs.ravel(), ys.ravel()], -1).astype(float))
    rays = rays[np.all(np.isfinite(rays), -1)]
    Rs, ts = sample_poses(geometry, 40, rng)
    overlaps = 0
    for R, t in zip(Rs, ts, strict=True):
        hits = _ray_hits(rays, geometry, cam, R, t, r._platform_radius)
        multi = np.isfinite(hits).sum(-1) >= 2
        if not multi.any():
            continue
        rank = np.empty(7)
        for k, obj in enumerate(r.draw_order(R, t)):  # later = in front
            rank[6 if obj < 0 else obj] = k
        legs = legs_in_frame(geometry, R, t, cam.camera_from_base)
        h, hr = hits[multi], rays[multi]
        leg_hits = h[:, :6, None] * hr[:, None, :]  # (N, 6, 3) points on the legs
        along = np.einsum("nkx,kx->nk", leg_hits - legs.base_points, legs.directions)
        joint = np.isfinite(h[:, :6]) & (legs.lengths - along < 2 * geometry.leg_radius)
        keep = ~(joint.any(-1) & np.isfinite(h[:, 6]))
        painted = np.argmax(np.where(np.isfinite(h), rank[None], -1), -1)
        assert np.array_equal(painted[keep], np.argmin(h, -1)[keep])
        overlaps += int(keep.sum())
    assert overlaps > (1000 if cam.kind == "perspective" else 50)
