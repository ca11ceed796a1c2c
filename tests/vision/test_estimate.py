"""Estimation of edge normals and leg directions from edge pixels."""

from __future__ import annotations

import numpy as np
import pytest

from hexapod import sample_poses
from vision.cameras import PerspectiveCamera, UnifiedCamera, front_camera, omni_camera
from vision.estimate import (
    NormalFit,
    angle_between,
    average_normals,
    direction_from_normals,
    fit_normal,
    fit_normal_conic,
    radians_per_pixel,
)
from vision.exceptions import EstimationError
from vision.legs import observation_edge_points, observe_legs
from vision.noise import pixel_noise

FITS = [fit_normal, fit_normal_conic]


def _edges(camera, geometry, n_poses: int, n_points: int, seed: int):
    R, t = sample_poses(geometry, n_poses, seed)
    obs = observe_legs(camera, geometry, R, t)
    pix, vis = observation_edge_points(camera, obs, n_points)
    return obs, pix, vis


@pytest.mark.parametrize("fit", FITS)
@pytest.mark.parametrize("which", ["front", "omni"])
def test_noiseless_recovery(geometry, fit, which: str) -> None:
    cam = front_camera(geometry) if which == "front" else omni_camera(geometry)
    obs, pix, vis = _edges(cam, geometry, 40, 20, 1)
    res = fit(cam, pix, weights=vis, base_point=obs.base_points[..., None, :])
    assert isinstance(res, NormalFit)
    ok = obs.edge_visible
    err = angle_between(res.normal, obs.normals)[ok]
    assert err.max() < 1e-9
    assert res.residual[ok].max() < 1e-12
    assert np.array_equal(res.n_points, vis.sum(-1))
    # Direction from the two fitted normals, same convention as leg_edges.
    both = obs.direction_visible
    u = direction_from_normals(res.normal[..., 0, :], res.normal[..., 1, :])
    assert angle_between(u, obs.directions)[both].max() < 1e-8


@pytest.mark.parametrize("which", ["front", "omni"])
def test_two_points_per_edge_give_the_plane_of_the_edge(geometry, which: str) -> None:
    """The fewest points an edge may have (``noise.points_per_edge`` >= 2): the plane
    through the camera centre and two lifted points. The fit returned a vector in that
    plane, about 90 degrees from the normal (the reduced SVD of 2 rows has no third
    vector); the line fit of the perspective camera likewise."""
    cam = front_camera(geometry) if which == "front" else omni_camera(geometry)
    obs, pix, vis = _edges(cam, geometry, 20, 2, 4)
    ok = obs.edge_visible & (vis.sum(-1) == 2)
    assert ok.sum() > 100
    fits = [fit_normal] + ([fit_normal_conic] if which == "front" else [])
    for fit in fits:
        res = fit(cam, pix, weights=vis, base_point=obs.base_points[..., None, :])
        assert angle_between(res.normal, obs.normals)[ok].max() < 1e-9, fit.__name__


@pytest.mark.parametrize("xi", [0.0, 0.5, 1.0, 1.5])
def test_noiseless_random_lines(rng: np.random.Generator, xi: float) -> None:
    K = np.array([[420.0, 1.5, 330.0], [0.0, 410.0, 250.0], [0.0, 0.0, 1.0]])
    cam = UnifiedCamera(K, xi, 640, 480)
    for _ in range(30):
        P0 = rng.uniform(-0.4, 0.4, size=3) + np.array([0.0, 0.0, 1.5])
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        X = P0 + np.linspace(-0.3, 0.3, 15)[:, None] * d
        n = np.cross(P0, d)
        n /= np.linalg.norm(n)
        pix, _ = cam.project(X)
        assert np.all(np.isfinite(pix))
        for fit in FITS:
            res = fit(cam, pix, reference=n)
            tol = 1e-9 if fit is fit_normal or abs(n[2]) > 0.1 else 1e-6
            assert angle_between(res.normal, n) < tol, (fit.__name__, xi)


def test_perspective_and_xi_zero_give_the_same_fit(geometry) -> None:
    cam = front_camera(geometry)
    uni = UnifiedCamera(cam.K, 0.0, cam.width, cam.height, cam.camera_from_base)
    _obs, pix, vis = _edges(cam, geometry, 10, 20, 2)
    noisy = pixel_noise(pix, 0.5, 3)
    a = fit_normal(cam, noisy, weights=vis)
    b = fit_normal(uni, noisy, weights=vis)
    assert np.allclose(a.normal, b.normal, atol=1e-14, equal_nan=True)


@pytest.mark.parametrize("which", ["front", "omni"])
def test_degrades_gracefully_with_pixel_noise(geometry, which: str) -> None:
    cam = front_camera(geometry) if which == "front" else omni_camera(geometry)
    obs, pix, vis = _edges(cam, geometry, 150, 20, 4)
    ok = obs.edge_visible
    A = obs.base_points[..., None, :]
    med = {}
    for sigma in (0.1, 0.5, 2.0):
        res = fit_normal(cam, pixel_noise(pix, sigma, 5), weights=vis, base_point=A)
        err = np.degrees(angle_between(res.normal, obs.normals))[ok]
        assert np.all(np.isfinite(err))
        med[sigma] = np.median(err)
        # The residual measures the noise: about sigma / focal length (radians).
        assert np.median(res.residual[ok]) < 3 * sigma / cam.fx
    # Linear in the noise level, no breakdown.
    assert 3.0 < med[0.5] / med[0.1] < 7.0
    assert 2.5 < med[2.0] / med[0.5] < 6.0
    assert med[0.5] < (0.1 if which == "front" else 0.3)


def test_svd_fit_beats_conic_fit_on_the_omni_camera(geometry) -> None:
    """Seed 003, section III-B: the minimal fit on the sphere is the more robust."""
    cam = omni_camera(geometry)
    obs, pix, vis = _edges(cam, geometry, 100, 20, 6)
    noisy = pixel_noise(pix, 0.5, 7)
    ok = obs.edge_visible
    A = obs.base_points[..., None, :]
    e_svd = angle_between(fit_normal(cam, noisy, weights=vis, base_point=A).normal,
                          obs.normals)[ok]
    e_con = angle_between(fit_normal_conic(cam, noisy, weights=vis, base_point=A).normal,
                          obs.normals)[ok]
    assert np.median(e_svd) * 5 < np.median(e_con)


def test_sign_conventions(geometry) -> None:
    cam = omni_camera(geometry)
    obs, pix, vis = _edges(cam, geometry, 5, 20, 8)
    ok = obs.edge_visible
    # base_point: n . A <= 0 reproduces the leg_edges convention.
    res = fit_normal(cam, pix, weights=vis, base_point=obs.base_points[..., None, :])
    assert np.all(np.sum(res.normal * obs.normals, -1)[ok] > 0.999)
    # reference: oriented like the reference.
    res = fit_normal(cam, pix, weights=vis, reference=-obs.normals)
    assert np.all(np.sum(res.normal * obs.normals, -1)[ok] < -0.999)
    # Default: the order of the points, from the base end to the platform end, gives
    # edge 0 its own orientation and edge 1 the opposite one; reversed order flips.
    res = fit_normal(cam, pix, weights=vis)
    dots = np.sum(res.normal * obs.normals, -1)
    assert np.all(dots[..., 0][ok[..., 0]] > 0.999) and np.all(dots[..., 1][ok[..., 1]] < -0.999)
    rev = fit_normal(cam, pix[..., ::-1, :], weights=vis[..., ::-1])
    assert np.allclose(rev.normal[ok], -res.normal[ok])


def test_weights_nan_and_too_few_points(geometry, rng: np.random.Generator) -> None:
    cam = front_camera(geometry)
    obs, pix, _vis = _edges(cam, geometry, 3, 12, 9)
    i = np.nonzero(obs.edge_visible.reshape(-1))[0][0]
    p = pix.reshape(-1, 12, 2)[i]
    n_true = obs.normals.reshape(-1, 3)[i]
    garbage = np.r_[p, rng.uniform(0, 700, size=(5, 2))]
    w = np.r_[np.ones(12), np.zeros(5)]
    for fit in FITS:
        res = fit(cam, garbage, weights=w, reference=n_true)
        assert angle_between(res.normal, n_true) < 1e-9 and res.n_points == 12
        with_nan = np.r_[p, np.full((3, 2), np.nan)]
        res = fit(cam, with_nan, reference=n_true)
        assert angle_between(res.normal, n_true) < 1e-9 and res.n_points == 12
    # Too few points: NaN, not an exception.
    assert np.all(np.isnan(fit_normal(cam, p[:1]).normal))
    assert np.all(np.isfinite(fit_normal(cam, p[:2]).normal))
    omni = omni_camera(geometry)
    assert np.all(np.isnan(fit_normal_conic(omni, p[:4]).normal))
    assert np.all(np.isnan(fit_normal(cam, np.full((6, 2), np.nan)).normal))
    # Weighted fit: a weighted-out outlier has no influence, a weighted-in one has.
    bad = p.copy()
    bad[3] += [40.0, -40.0]
    w = np.ones(12)
    w[3] = 0
    assert angle_between(fit_normal(cam, bad, weights=w).normal, n_true, oriented=False) < 1e-9
    assert angle_between(fit_normal(cam, bad).normal, n_true, oriented=False) > 1e-4
    with pytest.raises(EstimationError):
        fit_normal(cam, np.zeros((5, 3)))
    with pytest.raises(EstimationError):
        fit_normal(cam, p, weights=-np.ones(12))


def test_direction_from_normals_convention(rng: np.random.Generator) -> None:
    from vision.legs import leg_edges

    A = rng.normal(size=(50, 6, 3))
    u = rng.normal(size=(50, 6, 3))
    u /= np.linalg.norm(u, axis=-1, keepdims=True)
    n, exists = leg_edges(A, u, 0.01)
    d = direction_from_normals(n[..., 0, :], n[..., 1, :])
    assert np.allclose(d[exists], u[exists], atol=1e-9)
    # Swapping the edges flips the direction.
    assert np.allclose(direction_from_normals(n[..., 1, :], n[..., 0, :])[exists], -u[exists],
                       atol=1e-9)


def test_angle_between() -> None:
    a = np.array([1.0, 0.0, 0.0])
    assert angle_between(a, -a) == pytest.approx(np.pi)
    assert angle_between(a, -a, oriented=False) == pytest.approx(0.0)
    b = np.array([np.cos(1e-9), np.sin(1e-9), 0.0])
    assert angle_between(a, b) == pytest.approx(1e-9, rel=1e-6)


def test_perspective_line_fit_is_the_conic_alternative(geometry) -> None:
    """For a perspective camera fit_normal_conic is the line fit in normalised pixel
    coordinates: on noisy data it agrees with the SVD fit to a fraction of its error."""
    cam = front_camera(geometry)
    assert isinstance(cam, PerspectiveCamera)
    obs, pix, vis = _edges(cam, geometry, 50, 20, 10)
    noisy = pixel_noise(pix, 0.5, 11)
    ok = obs.edge_visible
    a = fit_normal(cam, noisy, weights=vis, reference=obs.normals).normal
    b = fit_normal_conic(cam, noisy, weights=vis, reference=obs.normals).normal
    e = angle_between(a, obs.normals)[ok]
    assert np.median(angle_between(a, b)[ok]) < 0.2 * np.median(e)


@pytest.mark.slow
def test_accuracy_benchmark_runs(capsys, tmp_path) -> None:
    from benchmarks.perf.vision import accuracy_figures, main

    assert main(["--poses", "8", "--figure", str(tmp_path / "edges.png")]) == 0
    out = capsys.readouterr().out
    assert "front" in out and "omni" in out and "median [deg]" in out
    assert (tmp_path / "edges.png").stat().st_size > 10_000
    figs = {(f.camera, f.fit, f.feature): f for f in accuracy_figures(20, 20, 0.5, 1)}
    assert len(figs) == 8
    assert figs[("front", "svd", "normal")].median_deg < 0.1
    assert figs[("omni", "svd", "normal")].median_deg < 0.3


def test_average_normals_aligns_signs_and_renormalises(rng: np.random.Generator) -> None:
    """K noisy copies of each normal, some with the opposite sign: the average is the
    unit normal of the first frame's sign, and its error drops as 1/sqrt(K)."""
    from vision.noise import rotation_noise

    truth = rng.standard_normal((6, 2, 3))
    truth /= np.linalg.norm(truth, axis=-1, keepdims=True)
    frames = 16
    noisy = np.array([rotation_noise(truth, np.deg2rad(1.0), rng) for _ in range(frames)])
    flips = np.where(rng.uniform(size=(frames, 6, 2, 1)) < 0.5, -1.0, 1.0)
    flips[0] = 1.0
    mean, vis = average_normals(noisy * flips, np.ones((frames, 6, 2), bool))
    assert vis.all()
    assert np.allclose(np.linalg.norm(mean, axis=-1), 1.0)
    assert np.all(np.sum(mean * truth, axis=-1) > 0), "signs of the first frame"
    err_one = np.sqrt(np.mean(angle_between(noisy, truth) ** 2))
    err_mean = np.sqrt(np.mean(angle_between(mean, truth) ** 2))
    # independent noise: 1/sqrt(K), with a margin for 12 edges only
    assert err_mean < 1.5 / np.sqrt(frames) * err_one


def test_average_normals_uses_the_frames_where_an_edge_is_seen(rng: np.random.Generator
                                                               ) -> None:
    truth = rng.standard_normal((6, 2, 3))
    truth /= np.linalg.norm(truth, axis=-1, keepdims=True)
    frames = 4
    normals = np.repeat(truth[None], frames, axis=0)
    visible = np.ones((frames, 6, 2), bool)
    visible[:2, 0, 0] = False  # seen in exactly half of the frames: kept
    visible[:3, 1, 1] = False  # seen in one frame of four: missing
    visible[:, 2, 0] = False  # never seen
    visible[0, 3, 1] = False  # missing in the first frame: its sign from the second
    normals[~visible] = np.nan
    normals[2, 3, 1] *= -1.0
    mean, vis = average_normals(normals, visible)
    expected = np.ones((6, 2), bool)
    expected[1, 1] = expected[2, 0] = False
    assert np.array_equal(vis, expected)
    assert np.all(np.isnan(mean[~expected]))
    assert np.allclose(mean[0, 0], truth[0, 0])
    assert np.allclose(mean[3, 1], truth[3, 1])
    assert np.allclose(mean[expected], truth[expected])
    # a single frame is returned as it is
    one, vis_one = average_normals(normals[1:2], visible[1:2])
    assert np.array_equal(vis_one, visible[1])
    assert np.allclose(one[vis_one], truth[vis_one])


@pytest.mark.parametrize(("normals", "visible", "kwargs", "fragment"), [
    (np.zeros((3, 6, 2, 3)), np.ones((3, 6, 2), bool), {"min_fraction": 1.5}, "min_fraction"),
    (np.zeros((3, 6, 2, 3)), np.ones((3, 6), bool), {}, "expected"),
    (np.zeros((3, 6, 2, 2)), np.ones((3, 6, 2), bool), {}, "expected"),
    (np.zeros((0, 6, 2, 3)), np.ones((0, 6, 2), bool), {}, "no frame"),
])
def test_average_normals_rejects_bad_input(normals, visible, kwargs, fragment) -> None:
    with pytest.raises(EstimationError, match=fragment):
        average_normals(normals, visible, **kwargs)


def test_average_normals_ignores_frames_far_from_the_median(rng: np.random.Generator) -> None:
    """A frame where the detector took another edge (4 deg away) pulls the plain average;
    with ``max_deviation`` it does not count. An edge split half and half between two
    detections has no majority: it is missing."""
    from vision.noise import rotation_noise

    truth = rng.standard_normal((6, 2, 3))
    truth /= np.linalg.norm(truth, axis=-1, keepdims=True)
    frames = 10
    noise = np.deg2rad(0.01)
    n = np.array([rotation_noise(truth, noise, rng) for _ in range(frames)])
    side = np.cross(truth, rng.standard_normal(3))
    side /= np.linalg.norm(side, axis=-1, keepdims=True)
    wrong = np.cos(np.deg2rad(4.0)) * truth + np.sin(np.deg2rad(4.0)) * side
    n[3, 0, 0] = wrong[0, 0]  # one wrong frame
    n[:5, 1, 0] = wrong[1, 0]  # half of the frames wrong
    vis = np.ones((frames, 6, 2), bool)
    tolerance = np.deg2rad(0.5)
    plain, _ = average_normals(n, vis)
    robust, seen = average_normals(n, vis, max_deviation=tolerance)
    assert angle_between(plain[0, 0], truth[0, 0]) > 2 * noise
    assert angle_between(robust[0, 0], truth[0, 0]) < noise
    assert not seen[1, 0] and np.all(np.isnan(robust[1, 0]))
    others = np.ones((6, 2), bool)
    others[1, 0] = False
    assert np.all(seen[others])
    assert np.allclose(robust[others & ~np.eye(6, 2, dtype=bool)],
                       plain[others & ~np.eye(6, 2, dtype=bool)])
    with pytest.raises(EstimationError, match="max_deviation"):
        average_normals(n, vis, max_deviation=-1.0)


def test_radians_per_pixel(geometry) -> None:
    """A pixel next to the principal point subtends (1 + xi) / f radians."""
    for cam in (front_camera(geometry), omni_camera(geometry)):
        px = np.array([[cam.cx, cam.cy], [cam.cx + 1.0, cam.cy]])
        rays = cam.lift(px)
        measured = float(angle_between(rays[0], rays[1]))
        assert radians_per_pixel(cam) == pytest.approx(measured, rel=1e-3)
