"""The compiled detector cores (vision/kernels.py) compute what the numpy path computes."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from hexapod.workspace import sample_poses
from tests.vision.detection_checks import same_detection
from vision import kernels
from vision.cameras import FRONT_DISTORTION, front_camera, omni_camera
from vision.detect import LegPrediction, OmniDetector, PerspectiveTracker, _robust_fit
from vision.polygon_fill import PolygonFiller
from vision.render import Renderer, RenderStyle


def test_the_kernels_compile_here() -> None:
    """CI has a C compiler: the compiled path must be the one measured and tested."""
    assert kernels.available()


@pytest.mark.parametrize("background", ["plain", "cluttered"])
def test_compiled_omni_detection_equals_numpy(geometry, rng, background) -> None:
    """Frame by frame, on noisy rendered images (and on clutter, where the scan finds
    spurious bands, rejects and misses edges): same edges, same points, same normals."""
    cam = omni_camera(geometry)
    style = RenderStyle(background=background, blur_px=0.8, noise_std=4.0)
    r = Renderer(cam, geometry, style, rng=rng)
    det = OmniDetector(cam)
    assert det._isotropic
    Rs, ts = sample_poses(geometry, 25, rng)
    missing = 0
    for k in range(25):
        img = r.render(Rs[k], ts[k])
        pred = LegPrediction.from_pose(cam, geometry, Rs[k], ts[k]) if k % 2 else None
        a = det.detect(img, pred, geometry=geometry, use_compiled=True)
        b = det.detect(img, pred, geometry=geometry, use_compiled=False)
        same_detection(a, b)
        missing += int((~a.edge_visible).sum())
    if background == "cluttered":
        assert missing > 0  # the comparison covered rejected edges too


def test_compiled_scan_of_an_anisotropic_camera_equals_numpy(geometry, rng) -> None:
    """fx != fy: the compiled scan, then the camera's own lift, then the compiled fit."""
    cam0 = omni_camera(geometry)
    K = cam0.K.copy()
    K[1, 1] *= 1.03
    cam = cam0.replace(K=K)
    det = OmniDetector(cam)
    assert not det._isotropic
    r = Renderer(cam, geometry, RenderStyle(blur_px=0.8, noise_std=3.0), rng=rng)
    Rs, ts = sample_poses(geometry, 10, rng)
    for k in range(10):
        img = r.render(Rs[k], ts[k])
        a = det.detect(img, geometry=geometry, use_compiled=True)
        b = det.detect(img, geometry=geometry, use_compiled=False)
        same_detection(a, b)
        assert a.edge_visible.sum() >= 10


@pytest.mark.parametrize(("lens", "poses", "least"), [(None, 12, 300),
                                                     (FRONT_DISTORTION, 8, 150)])
@pytest.mark.parametrize("background", ["plain", "cluttered"])
def test_compiled_tracker_pass_equals_numpy(geometry, rng, background, lens, poses,
                                            least) -> None:
    """The perspective tracker through both paths (profiles, gradient peak, occlusion
    gate, Theil-Sen, three fits): tracking passes, a wide search then a refinement with
    per-edge half-lengths, a stripe of wrong edges, predictions off by several pixels
    and running out of the image, an edge without prediction; with an ideal lens and
    through a distorting one (profiles along the curves' normals, the occlusion gate in
    the ideal image)."""
    from unittest import mock

    cam = front_camera(geometry).replace(distortion=lens)
    style = RenderStyle(background=background, blur_px=0.8, noise_std=3.0)
    r = Renderer(cam, geometry, style, rng=rng)
    tr = PerspectiveTracker(cam)
    Rs, ts = sample_poses(geometry, poses, rng)
    compared = 0
    for k in range(poses):
        img = r.render(Rs[k], ts[k])
        if k % 3 == 0:
            img[300:310] = 255 - img[300:310]  # a stripe of wrong edges
        pred = LegPrediction.from_pose(cam, geometry, Rs[k], ts[k] + rng.normal(0, 0.004, 3))
        if k == 5:
            n = pred.normals.copy()
            n[2, 1] = np.nan
            pred = LegPrediction(pred.base_points, pred.directions, pred.lengths, n,
                                 pred.radius)
        if k == 7:  # shifted so that samples and profiles leave the image
            pred = LegPrediction.from_pose(cam, geometry, Rs[k], ts[k] + [0.0, 0.25, 0.0])
        for search, refine in ((None, None), (40.0, 4.0), (3.0, 0.0)):
            a = tr.detect(img, pred, search, refine)
            with mock.patch.object(kernels, "available", return_value=False):
                b = tr.detect(img, pred, search, refine)
            same_detection(a, b)
            compared += int(a.edge_visible.sum())
        if k == 5:
            assert not a.edge_visible[2, 1]
    assert compared > least


def test_fit_kernel_degenerate_edges(rng) -> None:
    """Edges with 0, 1 or 2 points, all-invalid rays, NaN predictions: same outputs."""
    rays = rng.standard_normal((6, 2, 8, 3))
    rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
    valid = rng.uniform(size=(6, 2, 8)) < 0.7
    valid[0, 0] = False
    valid[0, 1] = False
    valid[0, 1, 3] = True
    valid[1, 0] = False
    valid[1, 0, :2] = True
    pred = rng.standard_normal((6, 2, 3))
    pred[2, 1] = np.nan
    args = (rays, valid, 50.0, pred, 5.0, 2, 100.0, 2)
    a = _robust_fit(*args, use_compiled=True)
    b = _robust_fit(*args, use_compiled=False)
    for x, y in zip(a, b, strict=True):
        assert x.shape == y.shape
        assert np.allclose(x, y, rtol=0, atol=1e-12, equal_nan=True)
    assert not a[1][0, 0] and not a[1][0, 1] and a[2][0, 1] == 1
    assert not a[1][2, 1]


def test_without_a_compiler_the_numpy_path_runs(monkeypatch, caplog, geometry, rng) -> None:
    """No compiler: a warning once, then the numpy path (same detection)."""
    cam = omni_camera(geometry)
    Rs, ts = sample_poses(geometry, 1, rng)
    img = Renderer(cam, geometry, RenderStyle(blur_px=0.8), rng=rng).render(Rs[0], ts[0])
    reference = OmniDetector(cam).detect(img, geometry=geometry)
    monkeypatch.setattr(kernels, "_lib", None)
    monkeypatch.setattr(kernels, "_tried", False)
    monkeypatch.setenv("CC", "no-such-compiler-xyz")
    with caplog.at_level(logging.WARNING, logger="vision.kernels"):
        assert not kernels.available()
        assert not kernels.available()
    assert sum("C compilation unavailable" in r.message for r in caplog.records) == 1
    same_detection(OmniDetector(cam).detect(img, geometry=geometry), reference)


def test_no_compile_environment_variable(monkeypatch) -> None:
    monkeypatch.setattr(kernels, "_lib", None)
    monkeypatch.setattr(kernels, "_tried", False)
    monkeypatch.setenv("HEXAPOD_NO_COMPILE", "1")
    assert not kernels.available()


def _clip_area(polygon: np.ndarray, x: float, y: float) -> float:
    """Area of a convex polygon inside the pixel square centred on (x, y): the square
    clipped by each edge of the polygon (Sutherland-Hodgman), then the shoelace."""
    P = np.asarray(polygon, float)
    lo, hi = P.min(axis=0), P.max(axis=0)
    if x + 0.5 <= lo[0] or x - 0.5 >= hi[0] or y + 0.5 <= lo[1] or y - 0.5 >= hi[1]:
        return 0.0  # the square is outside the polygon's bounding box
    if np.sum(P[:, 0] * np.roll(P[:, 1], -1) - np.roll(P[:, 0], -1) * P[:, 1]) < 0:
        P = P[::-1]
    out = [(x - 0.5, y - 0.5), (x + 0.5, y - 0.5), (x + 0.5, y + 0.5), (x - 0.5, y + 0.5)]
    for k in range(len(P)):
        a, b = P[k], P[(k + 1) % len(P)]

        def side(p, a=a, b=b):
            return (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])

        pts, out = out, []
        for m in range(len(pts)):
            p, q = pts[m], pts[(m + 1) % len(pts)]
            sp, sq = side(p), side(q)
            if sq >= 0:
                if sp < 0:
                    out.append((p[0] + sp / (sp - sq) * (q[0] - p[0]),
                                p[1] + sp / (sp - sq) * (q[1] - p[1])))
                out.append(q)
            elif sp >= 0:
                out.append((p[0] + sp / (sp - sq) * (q[0] - p[0]),
                            p[1] + sp / (sp - sq) * (q[1] - p[1])))
        if not out:
            return 0.0
    Q = np.array(out)
    return 0.5 * abs(float(np.sum(Q[:, 0] * np.roll(Q[:, 1], -1)
                                  - np.roll(Q[:, 0], -1) * Q[:, 1])))


def test_polygon_coverage_is_the_exact_pixel_area(rng) -> None:
    """Random convex polygons (some leaving the image, thin slivers, both
    orientations): the coverage of every pixel equals the area of its square inside
    the polygon (independent clipping), to 1e-12."""
    import cv2

    W, H = 40, 30
    f = PolygonFiller(W, H)
    for k in range(40):
        centre = rng.uniform([-5.0, -5.0], [W + 5.0, H + 5.0])
        ang = np.sort(rng.uniform(0.0, 2.0 * np.pi, 6))
        rad = rng.uniform(0.3, 15.0, 6) * (rng.uniform(0.02, 0.2) if k % 3 == 0 else 1.0)
        pts = centre + np.stack([rad * np.cos(ang), rad * np.sin(ang)], -1)
        hull = cv2.convexHull(pts.astype(np.float32)).reshape(-1, 2).astype(float)
        if k % 2:
            hull = hull[::-1]
        cov = f.coverage([hull])
        ref = np.array([[_clip_area(hull, x, y) for x in range(W)] for y in range(H)])
        assert np.abs(cov - ref).max() < 1e-12, k


def test_polygon_union_and_blending(rng) -> None:
    """Two overlapping contours of one shape fill their union (coverage 1, not 2) where
    one of them covers the shared pixels fully; where both cover a pixel partially their
    coverages add (capped at 1). Blending is ``round(v + (level - v) * coverage)``; a
    NaN vertex draws nothing."""
    f = PolygonFiller(20, 10)
    a = np.array([[2.3, 0.5], [12.6, 0.5], [12.6, 8.5], [2.3, 8.5]])  # rows 1..8 whole
    b = a + np.array([5.0, 0.0])
    cov = f.coverage([a, b[::-1]])  # opposite orientations: still the union
    assert cov.max() == pytest.approx(1.0) and cov.min() >= 0.0
    assert cov.sum() == pytest.approx((17.6 - 2.3) * 8.0, abs=1e-9)
    c = a + np.array([5.0, 0.2])  # shares partially covered pixels with a
    ref = [np.array([[_clip_area(poly, x, y) for x in range(20)] for y in range(10)])
           for poly in (a, c)]
    assert np.abs(f.coverage([a, c]) - np.minimum(ref[0] + ref[1], 1.0)).max() < 1e-12
    img = np.full((10, 20), 200, np.uint8)
    f.fill(img, [a], 50.0)
    expected = np.rint(200.0 + (50.0 - 200.0) * f.coverage([a]))
    assert np.array_equal(img, expected.astype(np.uint8))
    before = img.copy()
    with pytest.raises(ValueError, match="not finite"):
        f.fill(img, [np.array([[1.0, 1.0], [np.nan, 2.0], [3.0, 5.0]])], 0.0)
    assert np.array_equal(img, before)
    with pytest.raises(ValueError, match="uint8"):
        f.fill(img.astype(float), [a], 0.0)


@pytest.mark.parametrize("background", ["plain", "cluttered"])
def test_compiled_alignment_equals_numpy(geometry, rng, background) -> None:
    """The alignment's shift through both paths, for predictions of the platform
    displaced by up to 30 mm sideways (tens of pixels; some beyond the 12.5 px
    range), on noisy frames."""
    cam = front_camera(geometry)
    r = Renderer(cam, geometry, RenderStyle(background=background, blur_px=0.8,
                                            noise_std=3.0), rng=rng)
    tr = PerspectiveTracker(cam)
    Rs, ts = sample_poses(geometry, 10, rng)
    for k in range(10):
        img = r.render(Rs[k], ts[k])
        offset = np.array([*rng.uniform(-0.03, 0.03, 2), 0.0])  # platform moved [m]
        pred = LegPrediction.from_pose(cam, geometry, Rs[k], ts[k] + offset)
        for max_shift in (40.0, 12.5):
            a, pa = tr.align(img, pred, max_shift, use_compiled=True)
            b, pb = tr.align(img, pred, max_shift, use_compiled=False)
            assert np.array_equal(a, b), (k, max_shift, a, b)
            assert np.allclose(pa.normals, pb.normals, atol=1e-12, equal_nan=True)



def _lenses() -> list[tuple[str, object]]:
    """Every lens map of the compiled core, with coefficients of a real lens and
    stronger ones: OpenCV's full model (rational 8, thin prism 12, tilted 14 as in
    ``hexapod-bench perf detect``, a strong tilt), its five coefficients, the fisheye,
    the double sphere and the extended unified lens."""
    from vision.cameras import FRONT_DISTORTION
    from vision.cameras.distortion import RadialTangential
    from vision.cameras.distortion_full import OpenCVLens
    from vision.cameras.presets import FISHEYE_DISTORTION
    from vision.cameras.radial import DoubleSphere, ExtendedUnified, KannalaBrandt

    full = (-0.28, 0.09, 5e-4, -3e-4, -0.012, 0.02, 0.004, 0.0, 2e-4, -1e-4, 3e-4, 1e-4,
            0.002, -0.001)
    return [("opencv-8", OpenCVLens(full[:8])), ("opencv-12", OpenCVLens(full[:12])),
            ("opencv-14", OpenCVLens(full)),
            ("opencv-tilt", OpenCVLens((0.1, -0.05, 1e-3, 2e-3, 0.01, 0.3, -0.02, 0.005,
                                        1e-3, 0.0, -2e-3, 5e-4, 0.3, -0.2))),
            ("radtan", RadialTangential(FRONT_DISTORTION)),
            ("radtan-4", RadialTangential((-0.08, 0.012, 4e-4, -2e-4))),
            ("fisheye", KannalaBrandt(FISHEYE_DISTORTION)),
            ("fisheye-strong", KannalaBrandt((0.3, -0.1, 0.05, -0.01))),
            ("double-sphere", DoubleSphere((-0.15, 0.57))),
            ("double-sphere-2", DoubleSphere((0.6, 0.3))),
            ("eucm", ExtendedUnified((0.6, 1.1))), ("eucm-2", ExtendedUnified((1.0, 0.4)))]


@pytest.mark.parametrize("label, lens", _lenses(), ids=[n for n, _ in _lenses()])
def test_compiled_lens_maps_equal_numpy(rng, label, lens) -> None:
    """The compiled lens map and Jacobian of every model equal its numpy reference bit
    for bit (same operations, no fused multiply-add), also far beyond the fold, at the
    centre, below the fisheye's small-radius limit, on NaN and infinite coordinates
    and on a scalar point."""
    assert type(lens).parts is not type(lens).parts_numpy
    x = rng.uniform(-3.0, 3.0, (6, 2, 23))
    y = rng.uniform(-3.0, 3.0, (6, 2, 23))
    x[0, 0, :5] = np.nan, 0.0, np.inf, 3e-9, 1e-12
    y[0, 0, :5] = 0.1, 0.0, 0.2, -2e-9, 0.0
    x[1] *= 0.2  # inside the image of a real lens
    y[1] *= 0.2
    with np.errstate(all="ignore"):
        reference = lens.parts_numpy(x, y)
        compiled = lens.parts(x, y)
    # The fisheye map's atan: numpy >= 2.4 has its own vectorised arctan, which differs
    # from the C library's atan by one unit in the last place on some inputs (about 0.1 %
    # of them), and the Jacobian's (rho'/(1 + r^2) - f) / r^2 amplifies it by
    # cancellation near the centre; where numpy's arctan is the C library's, bitwise
    # equality is required.
    atan_rtol = 0.0 if _numpy_arctan_is_libm() or "fisheye" not in label else 1e-14
    for a, b in zip(compiled, reference, strict=True):
        assert a.shape == x.shape
        _equal_within(a, b, atan_rtol)
    for a, b in zip(lens.parts(0.3, -0.2), lens.parts_numpy(0.3, -0.2), strict=True):
        assert np.ndim(a) == 0
        _equal_within(np.asarray(a), np.asarray(b), atan_rtol)


def _numpy_arctan_is_libm() -> bool:
    """Whether numpy's arctan is the C library's atan on a dense sample (bitwise)."""
    import math

    x = np.linspace(0.0, 30.0, 20001)
    return bool(np.array_equal(np.arctan(x), np.array([math.atan(v) for v in x])))


def _equal_within(a: np.ndarray, b: np.ndarray, rtol: float) -> None:
    """Equal bit for bit (``rtol`` 0), or within ``rtol`` of the array's largest finite
    magnitude (NaN and infinities at the same places, equal)."""
    if rtol == 0.0:
        np.testing.assert_array_equal(a, b)
        return
    finite = np.isfinite(b)
    np.testing.assert_array_equal(a[~finite], b[~finite])
    scale = float(np.max(np.abs(b[finite]), initial=1.0))
    np.testing.assert_allclose(a[finite], b[finite], rtol=0.0, atol=rtol * scale)


@pytest.mark.parametrize("label, lens", _lenses()[2:7:2], ids=["opencv-14", "radtan",
                                                                "fisheye"])
def test_lens_maps_without_the_kernels_use_numpy(monkeypatch, rng, label, lens) -> None:
    """Without the compiled cores a lens map runs its numpy reference."""
    x, y = rng.uniform(-0.8, 0.8, (2, 40))
    expected = lens.parts_numpy(x, y)
    monkeypatch.setattr(kernels, "_lib", None)
    monkeypatch.setattr(kernels, "_tried", False)
    monkeypatch.setenv("HEXAPOD_NO_COMPILE", "1")
    assert kernels.lens_parts("opencv-full", x, y, np.zeros(14)) is None
    for a, b in zip(lens.parts(x, y), expected, strict=True):
        np.testing.assert_array_equal(a, b)


def test_blas_mode_is_the_fused_argument_that_gives_the_numpy_bits(
        monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture) -> None:
    """blas_mode probes once the compiled arithmetic in each mode against the numpy path:
    the mode that gives its bits (NaN as NaN), or None with a warning when none does."""
    monkeypatch.setattr(kernels, "_modes", {})
    reference = np.array([1.0, np.nan])
    probed: list[int] = []

    def compiled(fused: int) -> np.ndarray:
        probed.append(fused)
        return reference + (fused == 1)

    assert kernels.blas_mode("a", compiled, lambda: reference) == 0
    assert kernels.blas_mode("a", compiled, lambda: reference) == 0
    assert probed == [1, 0]  # once
    assert kernels.blas_mode("b", lambda f: reference + 1, lambda: reference) is None
    assert "b: the compiled arithmetic does not reproduce numpy's" in caplog.text
