"""Legs as image features: edge normals, limbs, image lines/conics, visibility and
occlusions (checked against an independent brute-force ray test)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from hexapod import Transform, legs_in_frame, sample_poses
from hexapod.se3 import look_at
from vision.cameras import PerspectiveCamera, UnifiedCamera, front_camera, omni_camera
from vision.legs import (
    LegObservation,
    directions_from_edges,
    edge_points,
    leg_edges,
    limb_points,
    observation_edge_points,
    observe_edges,
    observe_legs,
    occluded_by_disc,
    occluded_by_legs,
)


def _camera_at(eye, target, kind: str = "perspective"):
    base_R_cam = look_at(np.asarray(eye, float), np.asarray(target, float), np.array([0, 0, 1.0]))
    pose = Transform(base_R_cam, np.asarray(eye, float)).inverse()
    if kind == "perspective":
        K = np.array([[600.0, 0, 399.5], [0, 600.0, 299.5], [0, 0, 1]])
        return PerspectiveCamera(K, 800, 600, pose)
    K = np.array([[200.0, 0, 319.5], [0, 200.0, 239.5], [0, 0, 1]])
    return UnifiedCamera(K, 1.0, 640, 480, pose)


# ---------------------------------------------------------------- edges
def test_edge_normals_constraints(geometry, rng: np.random.Generator) -> None:
    R, t = sample_poses(geometry, 200, rng)
    for cam in (front_camera(geometry), omni_camera(geometry)):
        legs = legs_in_frame(geometry, R, t, cam.camera_from_base)
        n, exists = leg_edges(legs.base_points, legs.directions, geometry.leg_radius)
        assert exists.all()
        A = legs.base_points[..., None, :]
        u = legs.directions[..., None, :]
        assert np.allclose(np.sum(n * A, -1), -geometry.leg_radius, atol=1e-12)
        assert np.allclose(np.sum(n * u, -1), 0.0, atol=1e-12)
        assert np.allclose(np.linalg.norm(n, axis=-1), 1.0, atol=1e-12)
        assert np.allclose(directions_from_edges(n), legs.directions, atol=1e-10)
        # The two edges are different planes.
        assert np.all(np.abs(np.sum(n[..., 0, :] * n[..., 1, :], -1)) < 1 - 1e-6)


def test_limbs_are_tangent_silhouettes(geometry, rng: np.random.Generator) -> None:
    """Limb points are on the cylinder, and the viewing ray is tangent there; brute
    force: on the circle of the cylinder through the point, the limb is where the
    radial direction is orthogonal to the viewing ray (the extreme of the silhouette)."""
    cam = front_camera(geometry)
    R, t = sample_poses(geometry, 20, rng)
    obs = observe_legs(cam, geometry, R, t)
    s = np.linspace(0, 1, 7)
    P = limb_points(obs.base_points, obs.directions, geometry.leg_radius, obs.lengths,
                    obs.normals, s)
    A = obs.base_points[..., :, None, None, :]
    u = obs.directions[..., :, None, None, :]
    ax = np.sum((P - A) * u, -1, keepdims=True)
    radial = P - A - ax * u
    assert np.allclose(np.linalg.norm(radial, axis=-1), geometry.leg_radius, atol=1e-12)
    assert np.abs(np.sum(radial * P, -1)).max() < 1e-12
    assert np.allclose(ax[..., 0] / obs.lengths[..., None, None], s, atol=1e-12)
    # Dense circle around one limb point: the silhouette of the circle seen from the
    # camera is at the limb point.
    a0, u0, p0 = obs.base_points[3, 2], obs.directions[3, 2], P[3, 2, 0, 4]
    foot = a0 + np.dot(p0 - a0, u0) * u0
    e1 = (p0 - foot) / geometry.leg_radius
    e2 = np.cross(u0, e1)
    phi = np.linspace(-0.3, 0.3, 200001)
    Q = foot + geometry.leg_radius * (np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2)
    m = np.cross(a0, u0)
    m /= np.linalg.norm(m)
    # Angle of the plane through the centre, parallel to the axis and through Q, with the
    # plane through the axis: the edge plane is the extreme one.
    Qp = Q - (Q @ u0)[:, None] * u0
    ang = np.abs(np.arcsin(np.clip(Q @ m / np.linalg.norm(Qp, axis=1), -1, 1)))
    assert abs(phi[np.argmax(ang)]) < 1e-4


def test_projected_edges_lie_on_lines_and_conics(geometry, rng: np.random.Generator) -> None:
    R, t = sample_poses(geometry, 30, rng)
    cam = front_camera(geometry)
    obs = observe_legs(cam, geometry, R, t)
    assert obs.lines is not None
    pix, vis = observation_edge_points(cam, obs, 25)
    c = cam.pixels_to_line_coordinates(pix)
    val = np.einsum("...nk,...k->...n", np.concatenate([c, np.ones_like(c[..., :1])], -1),
                    obs.lines)
    # Distance in pixels to the line (normalised coordinates are pixels / width).
    d_px = np.abs(val) / np.linalg.norm(obs.lines[..., None, :2], axis=-1) * cam.width
    assert d_px[vis].max() < 1e-8
    # segments are the projected ends of the limbs.
    ends = limb_points(obs.base_points, obs.directions, geometry.leg_radius, obs.lengths,
                       obs.normals, np.array([0.0, 1.0]))
    assert np.allclose(obs.segments, cam.project(ends)[0])

    omni = omni_camera(geometry)
    obs = observe_legs(omni, geometry, R, t)
    assert obs.lines is None
    pix, vis = observation_edge_points(omni, obs, 25)
    C = omni.normal_to_conic(obs.normals)
    ph = np.concatenate([pix, np.ones_like(pix[..., :1])], -1)
    val = np.einsum("...ni,...ij,...nj->...n", ph, C, ph)
    grad = np.linalg.norm(2 * np.einsum("...ni,...ij->...nj", ph, C)[..., :2], axis=-1)
    assert (np.abs(val) / grad)[vis].max() < 1e-8


# ---------------------------------------------------------------- observe_legs
def test_observation_shapes_and_batching(geometry, rng: np.random.Generator) -> None:
    R, t = sample_poses(geometry, 6, rng)
    cam = front_camera(geometry)
    batch = observe_legs(cam, geometry, R.reshape(2, 3, 3, 3), t.reshape(2, 3, 3))
    assert isinstance(batch, LegObservation)
    assert batch.batch_shape == (2, 3)
    assert batch.normals.shape == (2, 3, 6, 2, 3)
    assert batch.edge_visible.shape == (2, 3, 6, 2)
    assert batch.visible_fraction.shape == (2, 3, 6, 2)
    assert batch.lines is not None and batch.lines.shape == (2, 3, 6, 2, 3)
    assert batch.segments.shape == (2, 3, 6, 2, 2, 2)
    assert batch.visible_interval.shape == (2, 3, 6, 2, 2)
    assert batch.direction_visible.shape == (2, 3, 6)
    for k in range(6):
        single = observe_legs(cam, geometry, R[k], t[k])
        assert single.batch_shape == ()
        i, j = divmod(k, 3)
        assert np.allclose(single.normals, batch.normals[i, j])
        assert np.array_equal(single.edge_visible, batch.edge_visible[i, j])
        assert np.allclose(single.visible_fraction, batch.visible_fraction[i, j])
        assert np.allclose(single.segments, batch.segments[i, j])
    assert np.allclose(batch.lines, cam.normal_to_line(batch.normals))
    with pytest.raises(ValueError):
        observe_legs(cam, geometry, R, t, min_visible_fraction=0.0)


def test_observe_edges_is_observe_legs_normals_and_visibility(
        geometry, other_geometry, rng: np.random.Generator) -> None:
    """observe_edges gives observe_legs' edge normals and visibility to the last bit
    (perspective and unified cameras, poses where some edges are hidden), with the batch
    shape of the poses."""
    hidden = 0
    for g in (geometry, other_geometry):
        R, t = sample_poses(g, 60, rng, max_translation=0.05, max_angle=0.3)
        R, t = R.reshape(3, 20, 3, 3), t.reshape(3, 20, 3)
        for cam in (front_camera(g), omni_camera(g), _camera_at([0.0, 0.3, 0.1], [0, 0, 0.2])):
            seen = observe_legs(cam, g, R, t)
            normals, visible = observe_edges(cam, g, R, t)
            assert normals.shape == (3, 20, 6, 2, 3) and visible.shape == (3, 20, 6, 2)
            assert visible.dtype == bool and np.array_equal(visible, seen.edge_visible)
            assert normals.tobytes() == np.asarray(seen.normals, float).tobytes()
            hidden += int((~visible).sum())
    assert hidden > 0  # the visibility was exercised, not only all-visible poses


def test_camera_inside_a_leg_sees_no_edge_of_it(geometry) -> None:
    R, t = np.eye(3), np.array([0.0, 0.0, geometry.home_height])
    legs = legs_in_frame(geometry, R, t)
    inside = legs.base_points[2] + 0.2 * legs.directions[2] + 0.005 * np.cross(
        legs.directions[2], [0, 0, 1.0]) / np.linalg.norm(np.cross(legs.directions[2], [0, 0, 1]))
    cam = _camera_at(inside, inside + legs.directions[2], "unified")
    obs = observe_legs(cam, geometry, R, t)
    assert not obs.exists[2] and not obs.edge_visible[2].any()
    assert np.all(np.isnan(obs.normals[2]))
    assert obs.exists[[0, 1, 3, 4, 5]].all()


def test_legs_outside_the_image_or_behind_are_not_observed(geometry) -> None:
    R, t = np.eye(3), np.array([0.0, 0.0, geometry.home_height])
    away = _camera_at([0.8, 0, 0.2], [2.0, 0, 0.2])  # looking away from the robot
    obs = observe_legs(away, geometry, R, t)
    assert obs.exists.all() and not obs.edge_visible.any()
    assert np.all(obs.visible_fraction == 0) and np.all(np.isnan(obs.visible_interval))
    obs = observe_legs(away, geometry, R, t, occlusion=False)
    assert not obs.edge_visible.any()
    # Only part of the robot in the image: some edges partially visible.
    side = _camera_at([0.8, 0, 0.2], [0.0, 0.45, 0.2])
    obs = observe_legs(side, geometry, R, t, occlusion=False)
    assert obs.edge_visible.any() and not obs.edge_visible.all()
    frac = obs.visible_fraction
    assert np.any((frac > 0) & (frac < 1))
    # The rule: observed iff at least min_visible_fraction of the samples are visible.
    for m in (0.25, 0.5, 0.9):
        o = observe_legs(side, geometry, R, t, min_visible_fraction=m, occlusion=False)
        assert np.array_equal(o.edge_visible, o.visible_fraction >= m - 1e-12)


def _brute_force_occlusion(P, A, u, q, r, disc, skip_own, M=4000):
    """Independent check: sample the segment from the projection centre to P densely
    and test every sample against every other leg (axial coordinate in [0, q] and
    distance to the axis < r) and against the disc (sign change of the distance to
    its plane at a radius < its radius). Returns (occluded, ambiguous)."""
    s = np.linspace(0.0, 1.0, M + 1)[1:-1]
    X = s[:, None] * P  # (M-1, 3)
    # X = s P: for each other leg j, the axial coordinate (X - A_j).u_j and the squared
    # distance |X - A_j|^2 are polynomials in s (the samples' distance to the axis follows)
    others = [j for j in range(6) if j != skip_own]
    Ao, uo = A[others][:, None], u[others][:, None]  # (5, 1, 3)
    ax = s * (uo @ P) - np.sum(Ao * uo, axis=2)  # (5, M-1)
    sq = s * s * (P @ P) - 2.0 * s * (Ao @ P) + np.sum(Ao * Ao, axis=2)
    d = np.sqrt(np.maximum(sq - ax * ax, 0.0))
    g = np.maximum(np.maximum(d - r, -ax), ax - q[others][:, None])  # < 0 inside a cylinder
    inside = bool(np.any(g < 0))
    clear = float(np.min(np.abs(g)))
    c, nd, rho = disc
    clear = min(clear, abs(float((P - c) @ nd)))  # a point on the plane: ambiguous
    e = (X - c) @ nd
    cross = np.nonzero(np.sign(e[:-1]) != np.sign(e[1:]))[0]
    for k in cross:
        radial = np.linalg.norm(X[k] - c - e[k] * nd)
        inside |= bool(radial < rho)
        clear = min(clear, abs(radial - rho))
    return inside, clear < 1e-3


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_occlusion_against_brute_force(geometry, seed: int) -> None:
    rng = np.random.default_rng(seed)
    R, t = sample_poses(geometry, 4, rng)
    cams = [front_camera(geometry)]
    for _ in range(3):  # random cameras around and above the robot, looking at it
        a = rng.uniform(0, 2 * np.pi)
        eye = [0.7 * np.cos(a), 0.7 * np.sin(a), rng.uniform(0.0, 0.9)]
        cams.append(_camera_at(eye, [0, 0, 0.25]))
    n_occ = n_disc = n_checked = 0
    for cam in cams:
        obs = observe_legs(cam, geometry, R, t)
        r = geometry.leg_radius
        s = np.linspace(0.02, 0.98, 9)
        P = limb_points(obs.base_points, obs.directions, r, obs.lengths, obs.normals, s)
        occ_l = occluded_by_legs(P, obs.base_points, obs.directions, obs.lengths, r)
        occ_d = occluded_by_disc(P, obs.platform_centre, obs.platform_normal, obs.platform_radius)
        for b in range(len(R)):
            disc = (obs.platform_centre[b], obs.platform_normal[b], obs.platform_radius)
            for i in range(6):
                for e in range(2):
                    for k in range(len(s)):
                        ref, ambiguous = _brute_force_occlusion(
                            P[b, i, e, k], obs.base_points[b], obs.directions[b],
                            obs.lengths[b], r, disc, skip_own=i)
                        if ambiguous:
                            continue
                        n_checked += 1
                        got = occ_l[b, i, e, k] or occ_d[b, i, e, k]
                        assert got == ref, (cam, b, i, e, k)
                        n_occ += int(ref)
                        n_disc += int(occ_d[b, i, e, k])
    # The configurations do exercise occlusions by legs and by the platform.
    assert n_checked > 1000 and n_occ > 20 and n_disc > 5


def test_front_camera_hides_legs_omni_does_not(geometry) -> None:
    R, t = sample_poses(geometry, 400, 11)
    front = observe_legs(front_camera(geometry), geometry, R, t)
    free = observe_legs(front_camera(geometry), geometry, R, t, occlusion=False)
    assert free.edge_visible.all()
    assert (~front.edge_visible).any()
    assert np.all(front.visible_fraction <= free.visible_fraction)
    omni = observe_legs(omni_camera(geometry), geometry, R, t)
    assert omni.edge_visible.all()


def test_platform_hides_legs_from_above(geometry) -> None:
    R, t = np.eye(3), np.array([0.0, 0.0, geometry.home_height])
    top = _camera_at([0.05, 0.0, 1.2], [0.0, 0.0, 0.0])
    obs = observe_legs(top, geometry, R, t)
    no_disc = observe_legs(top, geometry, R, t, platform_radius=1e-6)
    assert obs.visible_fraction.sum() < no_disc.visible_fraction.sum()
    # A huge platform hides everything.
    big = observe_legs(top, geometry, R, t, platform_radius=1.0)
    assert not big.edge_visible.any()


def test_edge_points(geometry, rng: np.random.Generator) -> None:
    R, t = sample_poses(geometry, 5, rng)
    cam = front_camera(geometry)
    obs = observe_legs(cam, geometry, R, t)
    pix, vis = edge_points(cam, obs.base_points, obs.directions, geometry.leg_radius,
                           obs.lengths, 11)
    assert pix.shape == (5, 6, 2, 11, 2) and vis.shape == (5, 6, 2, 11)
    # The default span is the whole edge: its ends are the segment ends.
    assert np.allclose(pix[..., 0, :], obs.segments[..., 0, :])
    assert np.allclose(pix[..., -1, :], obs.segments[..., 1, :])
    # Same as projecting limb points.
    P = limb_points(obs.base_points, obs.directions, geometry.leg_radius, obs.lengths,
                    obs.normals, np.linspace(0, 1, 11))
    assert np.allclose(pix, cam.project(P)[0])
    # Without occlusion test: visible == imaged.
    _, vis_all = edge_points(cam, obs.base_points, obs.directions, geometry.leg_radius,
                             obs.lengths, 11, occlusion=False)
    assert np.array_equal(vis_all, cam.project(P)[1])
    assert np.all(vis <= vis_all)
    # Per-edge spans and a single point.
    one, _ = edge_points(cam, obs.base_points, obs.directions, geometry.leg_radius,
                         obs.lengths, 1, span=(0.2, 0.4))
    mid = limb_points(obs.base_points, obs.directions, geometry.leg_radius, obs.lengths,
                      obs.normals, np.array([0.3]))
    assert np.allclose(one, cam.project(mid)[0])
    # observation_edge_points spreads the points over the visible interval.
    _, vis_v = observation_edge_points(cam, obs, 10)
    ok = obs.edge_visible
    assert vis_v[ok].mean() > 0.9


def test_observe_legs_takes_the_compiled_core_in_one_call(
        geometry, monkeypatch: pytest.MonkeyPatch) -> None:
    """A batch of poses seen by the front camera goes to the compiled core in one call
    for the whole batch, never to the numpy reference (the fast path). Its cost is not
    asserted here: ``python -m benchmarks.perf.study --breakdown`` times the core
    (``observation (C)``) in the study engine."""
    from vision import fast_observe
    from vision import legs as legs_module

    assert fast_observe.compiled()  # the test machines compile C kernels
    R, t = sample_poses(geometry, 100, 3)
    batches: list[int] = []
    core = fast_observe.observe_batch

    def counted(params: Any, rotations: np.ndarray, *args: Any, **kwargs: Any) -> Any:
        batches.append(len(rotations))
        return core(params, rotations, *args, **kwargs)

    def refused(*args: Any, **kwargs: Any) -> Any:
        raise AssertionError("observe_legs fell back to the numpy reference")

    monkeypatch.setattr(fast_observe, "observe_batch", counted)
    monkeypatch.setattr(legs_module, "observe_legs_numpy", refused)
    obs = observe_legs(front_camera(geometry), geometry, R, t)
    assert batches == [100]
    assert obs.edge_visible.shape == (100, 6, 2) and obs.edge_visible.any()


def test_directions_from_edges_compiled_is_the_numpy_path(
        rng: np.random.Generator, monkeypatch: pytest.MonkeyPatch) -> None:
    """The compiled directions are the numpy path's to the last bit, with NaN normals and
    parallel edges (NaN directions), for a batch, one leg and a non-contiguous view."""
    from vision import kernels

    assert kernels.available()  # the test machines compile C kernels
    n = rng.normal(size=(500, 6, 2, 3))
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    n[3, 2, 1] = np.nan
    n[4, 1, 1] = n[4, 1, 0]  # parallel edges: no direction
    cases = [n, n[7, 2], n[::2, :, ::-1]]
    compiled = [directions_from_edges(c) for c in cases]
    monkeypatch.setattr(kernels, "_load", lambda: None)
    with np.errstate(invalid="ignore", divide="ignore"):
        expected = [directions_from_edges(c) for c in cases]
    for c, e in zip(compiled, expected, strict=True):
        assert c.shape == e.shape and np.array_equal(c, e, equal_nan=True)
    assert np.isnan(compiled[0][3, 2]).all() and np.isnan(compiled[0][4, 1]).all()
    assert np.isfinite(compiled[0][5]).all()
