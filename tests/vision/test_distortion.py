"""Lens distortion of the camera models, checked against OpenCV: ``cv2.projectPoints``
for the perspective camera, the formula of ``cv::omnidir`` (written here: the contrib
module is not in opencv-python-headless) for the unified one; round trips over the
image, finite differences of every Jacobian, the fold check against a brute-force
search, and the features that depend on the lens."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from hexapod import Transform
from hexapod.se3 import exp_so3
from vision.cameras import Camera, PerspectiveCamera, UnifiedCamera
from vision.cameras.distortion import RadialTangential
from vision.cameras.projection import domain_radius
from vision.estimate import fit_normal, fit_normal_conic
from vision.exceptions import CameraError, DistortionError

W, H = 640, 480


def _K(fx: float = 800.0, fy: float = 790.0, cx: float = 330.0, cy: float = 245.0,
       s: float = 0.0) -> np.ndarray:
    return np.array([[fx, s, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


#: OpenCV coefficient vectors (k1, k2, p1, p2[, k3]) of the perspective tests.
PERSPECTIVE_SETS = {
    "mild-4": (-0.08, 0.02, 0.0005, -0.0003),
    "mild-5": (-0.12, 0.05, -0.0008, 0.0006, -0.01),
    "strong-barrel-5": (-0.45, 0.22, 0.001, -0.002, -0.04),
    "strong-pincushion-5": (0.35, 0.4, 0.0, 0.0, 0.3),
    "tangential-4": (0.0, 0.0, 0.02, -0.015),
    "webcam-5": (-0.28, 0.07, 0.0008, -0.0005, -0.008),
}
#: (xi, (k1, k2, p1, p2)) of the unified tests.
UNIFIED_SETS = {
    "para-mild": (1.0, (-0.05, 0.01, 0.001, -0.0005)),
    "mirror-0.8": (0.8, (-0.2, 0.05, 0.003, -0.002)),
    "fisheye-1.6": (1.6, (0.05, -0.01, 0.001, 0.001)),
    "small-xi": (0.3, (-0.25, 0.06, 0.001, 0.0)),
}


def _perspective(name: str, s: float = 0.0) -> PerspectiveCamera:
    return PerspectiveCamera(_K(s=s), W, H, distortion=PERSPECTIVE_SETS[name])


def _unified(name: str) -> UnifiedCamera:
    xi, d = UNIFIED_SETS[name]
    return UnifiedCamera(_K(300, 310, 320, 240, 1.5), xi, W, H, distortion=d)


def _all_cameras() -> list[Camera]:
    return ([_perspective(n) for n in PERSPECTIVE_SETS]
            + [_unified(n) for n in UNIFIED_SETS])


def _camera_ids() -> list[str]:
    return [f"perspective-{n}" for n in PERSPECTIVE_SETS] + [f"unified-{n}" for n in
                                                             UNIFIED_SETS]


def _image_grid(step: float = 8.0) -> np.ndarray:
    """Pixels over the whole image, its border and corners included."""
    u = np.r_[np.arange(-0.5, W - 0.5, step), W - 0.5]
    v = np.r_[np.arange(-0.5, H - 0.5, step), H - 0.5]
    uu, vv = np.meshgrid(u, v)
    return np.stack([uu.ravel(), vv.ravel()], -1)


def _angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, axis=-1))


# ---------------------------------------------------------------- projection
@pytest.mark.parametrize("name", list(PERSPECTIVE_SETS))
def test_perspective_projection_equals_cv2_projectPoints(name: str,
                                                         rng: np.random.Generator) -> None:
    cam0 = _perspective(name)
    pose = Transform(exp_so3(rng.normal(size=3)), rng.normal(scale=0.3, size=3))
    cam = cam0.replace(camera_from_base=pose)
    # Points in front of the camera whose rays cover the image and beyond (1.3 x the
    # image's half-diagonal in normalised units).
    m = rng.uniform(-1, 1, size=(4000, 2)) * [0.55, 0.42]
    Xc = np.c_[m, np.ones(len(m))] * rng.uniform(0.2, 5.0, size=(len(m), 1))
    Xb = pose.inverse().apply(Xc)
    rvec, _ = cv2.Rodrigues(pose.rotation)
    dist = np.array(PERSPECTIVE_SETS[name])
    ref, _ = cv2.projectPoints(Xb.reshape(-1, 1, 3), rvec, pose.translation, cam.K, dist)
    pix, vis = cam.project_base(Xb)
    assert vis.sum() > 1000
    assert np.abs(pix - ref.reshape(-1, 2)).max() < 1e-6
    # The distortion is there: an ideal camera differs by pixels.
    ideal, _ = cam.replace(distortion=None).project_base(Xb)
    assert np.abs(ideal - pix).max() > 1.0


def test_perspective_skew_is_applied_as_omnidir_does() -> None:
    """cv2.projectPoints ignores K[0, 1]; the model keeps it: u = fx x_d + s y_d + cx."""
    X = np.array([[0.1, -0.2, 1.0], [-0.3, 0.25, 1.5], [0.0, 0.0, 2.0]])
    plain, _ = _perspective("mild-5").project(X)
    skewed, _ = _perspective("mild-5", s=3.0).project(X)
    y_d = (plain[:, 1] - 245.0) / 790.0
    assert np.allclose(skewed[:, 0] - plain[:, 0], 3.0 * y_d, atol=1e-12)
    assert np.array_equal(skewed[:, 1], plain[:, 1])


def _omnidir_reference(X: np.ndarray, K: np.ndarray, xi: float, D: tuple) -> np.ndarray:
    """``cv::omnidir::projectPoints`` as documented (opencv_contrib, ccalib/omnidir):
    unit sphere, shift by xi, radial-tangential distortion, then K with its skew."""
    Xs = X / np.linalg.norm(X, axis=-1, keepdims=True)
    xu = Xs[:, 0] / (Xs[:, 2] + xi)
    yu = Xs[:, 1] / (Xs[:, 2] + xi)
    k1, k2, p1, p2 = D
    r2 = xu * xu + yu * yu
    r4 = r2 * r2
    xd = xu * (1 + k1 * r2 + k2 * r4) + 2 * p1 * xu * yu + p2 * (r2 + 2 * xu * xu)
    yd = yu * (1 + k1 * r2 + k2 * r4) + p1 * (r2 + 2 * yu * yu) + 2 * p2 * xu * yu
    return np.stack([K[0, 0] * xd + K[0, 1] * yd + K[0, 2], K[1, 1] * yd + K[1, 2]], -1)


@pytest.mark.parametrize("name", list(UNIFIED_SETS))
def test_unified_projection_equals_omnidir_formula(name: str,
                                                   rng: np.random.Generator) -> None:
    cam = _unified(name)
    xi, D = UNIFIED_SETS[name]
    X = rng.normal(size=(5000, 3)) * rng.uniform(0.1, 10, size=(5000, 1))
    pix, vis = cam.project(X)
    ref = _omnidir_reference(X, cam.K, xi, D)
    assert vis.sum() > 1000
    assert np.abs(pix[vis] - ref[vis]).max() < 1e-6
    # Not imaged by the mirror: NaN; the rest agrees wherever the pixel is not huge.
    imaged = np.isfinite(pix[:, 0])
    near = imaged & (np.abs(ref - [W / 2, H / 2]).max(axis=-1) < 10 * W)
    assert np.abs(pix[near] - ref[near]).max() < 1e-6


def test_unified_xi_zero_is_the_perspective_camera_with_distortion(
        rng: np.random.Generator) -> None:
    d = PERSPECTIVE_SETS["webcam-5"][:4]
    per = PerspectiveCamera(_K(s=1.0), W, H, distortion=d)
    uni = UnifiedCamera(_K(s=1.0), 0.0, W, H, distortion=d)
    X = rng.normal(size=(500, 3)) + np.array([0.0, 0.0, 3.0])
    assert np.array_equal(per.project(X)[0], uni.project(X)[0], equal_nan=True)
    pix = _image_grid(20.0)
    assert np.array_equal(per.lift(pix), uni.lift(pix))


# ---------------------------------------------------------------- round trips
@pytest.mark.parametrize("cam", _all_cameras(), ids=_camera_ids())
def test_lift_inverts_project_over_the_image(cam: Camera, rng: np.random.Generator) -> None:
    # Pixels -> rays -> pixels over the whole image (corners included).
    pix = _image_grid(4.0)
    rays = cam.lift(pix)
    lifted = np.all(np.isfinite(rays), axis=-1)
    if cam.xi <= 1:
        assert lifted.all()
    assert lifted.mean() > 0.5
    assert np.allclose(np.linalg.norm(rays[lifted], axis=-1), 1.0, atol=1e-14)
    back, _ = cam.project(rays[lifted])
    assert np.abs(back - pix[lifted]).max() < 1e-7
    # Points -> pixels in the image -> rays parallel to the points (same sense).
    X = rng.normal(size=(20000, 3)) * rng.uniform(0.1, 10, size=(20000, 1))
    if cam.kind == "perspective":
        X[:, 2] = np.abs(X[:, 2])
    p, vis = cam.project(X)
    assert vis.sum() > 1000
    S = cam.lift(p[vis])
    assert _angle(S, X[vis]).max() < 1e-10


def test_points_beyond_the_fold_are_not_visible() -> None:
    """Past its fold (r = 0.861) the barrel ``r - 0.45 r^3`` comes back into the image
    (OpenCV projects such points there); such points are not imaged by the lens."""
    d = np.array([-0.45, 0.0, 0.0, 0.0, 0.0])
    cam = PerspectiveCamera(_K(), W, H, distortion=d)
    X = np.array([[1.4, 0.0, 1.0], [0.3, 0.0, 1.0]])
    ref, _ = cv2.projectPoints(X, np.zeros(3), np.zeros(3), cam.K, d)
    pix, vis = cam.project(X)
    assert np.allclose(pix, ref.reshape(-1, 2), atol=1e-6)  # OpenCV's pixel...
    assert cam.in_image(pix).all()  # ...in the image for both,
    assert vis.tolist() == [False, True]  # but the first is beyond the fold
    assert _angle(cam.lift(pix[1]), X[1]) < 1e-12


# ---------------------------------------------------------------- Jacobians
def _fd(f, x: np.ndarray, h: float) -> np.ndarray:
    """Central differences of f (..., k) -> (..., n) at x (..., k): (..., n, k)."""
    cols = []
    for j in range(x.shape[-1]):
        e = np.zeros(x.shape[-1])
        e[j] = h
        cols.append((f(x + e) - f(x - e)) / (2 * h))
    return np.stack(cols, axis=-1)


@pytest.mark.parametrize("cam", _all_cameras(), ids=_camera_ids())
def test_jacobians_match_finite_differences(cam: Camera, rng: np.random.Generator) -> None:
    pix = rng.uniform([0, 0], [W - 1, H - 1], size=(300, 2))
    rays = cam.lift(pix)
    # Away from the edge of the mirror's field (xi > 1), where the lift has a square-root
    # singularity that finite differences do not resolve.
    radius = np.linalg.norm(cam.pixels_to_normalised(pix), axis=-1)
    ok = np.all(np.isfinite(rays), axis=-1) & (radius < 0.98 * domain_radius(cam.xi))
    assert ok.sum() > 100
    pix, rays = pix[ok], rays[ok]
    X = rays * rng.uniform(0.5, 3.0, size=(len(rays), 1))
    # d pixel / d point [px/m]
    J = cam.project_jacobian(X)
    num = _fd(lambda Y: cam.project(Y)[0], X, 1e-6)
    assert J.shape == (len(X), 2, 3)
    assert np.abs(J - num).max() < 1e-5 * np.abs(J).max()
    # d ray / d pixel [1/px]
    L = cam.lift_jacobian(pix)
    num = _fd(cam.lift, pix, 1e-3)
    assert L.shape == (len(pix), 3, 2)
    assert np.abs(L - num).max() < 1e-6 * np.abs(L).max()
    # Chain rule: project o lift = identity on pixels.
    P = cam.project_jacobian(rays) @ L
    assert np.allclose(P, np.eye(2), atol=1e-8)
    # d m_d / d m of the distortion map
    m = cam.pixels_to_normalised(pix)
    D = cam.distortion_jacobian(m)
    num = _fd(cam.distort, m, 1e-7)
    assert np.abs(D - num).max() < 1e-6


# ---------------------------------------------------------------- folds
def _brute_force_fold_in_image(d: tuple, K: np.ndarray) -> tuple[bool, float]:
    """Independent fold search: sample rays of the undistorted plane densely, find the
    first radius where det(dD/dm) <= 0 (the determinant by central differences of
    RadialTangential.apply), map it to pixels, test the image. Returns (found, distance
    in pixels of the deepest fold point from the image border)."""
    lens = RadialTangential(d)
    theta = np.linspace(-np.pi, np.pi, 360, endpoint=False)
    r = np.linspace(1e-3, 3.0, 1500)
    m = r[None, :, None] * np.stack([np.cos(theta), np.sin(theta)], -1)[:, None, :]
    h = 1e-6
    ex, ey = np.array([h, 0.0]), np.array([0.0, h])
    dx = (lens.apply(m + ex) - lens.apply(m - ex)) / (2 * h)
    dy = (lens.apply(m + ey) - lens.apply(m - ey)) / (2 * h)
    det = dx[..., 0] * dy[..., 1] - dx[..., 1] * dy[..., 0]
    neg = det <= 0
    has = neg.any(axis=1)
    first = np.argmax(neg, axis=1)
    md = lens.apply(m[np.arange(len(theta)), first])[has]
    pix = md @ K[:2, :2].T + K[:2, 2]
    depth = np.minimum.reduce([pix[:, 0] + 0.5, W - 0.5 - pix[:, 0],
                               pix[:, 1] + 0.5, H - 0.5 - pix[:, 1]])
    if depth.size == 0:
        return False, -np.inf
    return bool((depth >= 0).any()), float(depth.max())


@pytest.mark.slow
def test_fold_check_agrees_with_a_brute_force_search(rng: np.random.Generator) -> None:
    K = _K()
    decided = 0
    for _ in range(32):
        d = (rng.uniform(-0.9, 0.3), rng.uniform(-0.2, 0.6), rng.uniform(-0.05, 0.05),
             rng.uniform(-0.05, 0.05), rng.uniform(-0.3, 0.3))
        found, depth = _brute_force_fold_in_image(d, K)
        if abs(depth) < 3.0:
            continue  # within the sampling accuracy of the brute force
        decided += 1
        if found:
            with pytest.raises(DistortionError):
                PerspectiveCamera(K, W, H, distortion=d)
        else:
            PerspectiveCamera(K, W, H, distortion=d)
    assert decided > 20


def test_fold_at_the_corners_only_is_refused_with_evidence() -> None:
    """Pure k1: the fold is the circle r = 1/sqrt(-3 k1), imaged at the distorted radius
    2 / (3 sqrt(-3 k1)). Between the edge midpoints (0.413 normalised) and the corners
    (0.517) only the corners fold."""
    K = _K()
    r_d = 0.45
    k1 = -((2.0 / (3.0 * r_d)) ** 2) / 3.0
    with pytest.raises(DistortionError) as info:
        PerspectiveCamera(K, W, H, distortion=(k1, 0.0, 0.0, 0.0))
    e = info.value
    assert e.field == "distortion" and e.coefficients == (k1, 0.0, 0.0, 0.0, 0.0)
    assert e.radius_normalised == pytest.approx(r_d, rel=1e-6)
    assert e.radius_undistorted == pytest.approx(1.0 / np.sqrt(-3.0 * k1), rel=1e-9)
    u, v = e.pixel
    assert np.hypot(u - K[0, 2], v - K[1, 2]) == pytest.approx(e.radius_px)
    assert -0.5 <= u <= W - 0.5 and -0.5 <= v <= H - 0.5
    assert min(u + 0.5, W - 0.5 - u) < 60 and min(v + 0.5, H - 0.5 - v) < 60  # a corner
    for word in ("fold", "normalised radius 0.45", "px from the principal point"):
        assert word in str(e)
    # A milder k1 whose fold circle passes beyond the corners is accepted.
    k1_ok = -((2.0 / (3.0 * 0.53)) ** 2) / 3.0
    cam = PerspectiveCamera(K, W, H, distortion=(k1_ok, 0.0, 0.0, 0.0))
    assert np.isfinite(cam.lift(_image_grid(2.0))).all()


@pytest.mark.parametrize(
    ("d", "xi"),
    [((0.0, 0.0, 0.2, 0.2), None), ((-0.6, 0.0, 0.0, 0.0, 0.0), None),
     ((-0.9, 0.1, 0.0, 0.0), 0.8)],
)
def test_folding_coefficients_are_refused(d: tuple, xi: float | None) -> None:
    with pytest.raises(DistortionError, match="fold inside the image"):
        if xi is None:
            PerspectiveCamera(_K(), W, H, distortion=d)
        else:
            UnifiedCamera(_K(300, 310, 320, 240), xi, W, H, distortion=d)


def test_bad_distortion_vectors() -> None:
    lengths = "4 or 5 or 8 or 12 or 14 numbers"  # OpenCV's vectors, rational to tilted
    for bad, match in (((0.1, 0.2, 0.0), lengths), ((0.1,) * 6, lengths),
                       ((0.1, np.nan, 0, 0), "NaN"), ("abc", "numbers"),
                       (((0.1, 0.2), (0, 0)), "shape")):
        with pytest.raises(CameraError, match=f"distortion.*{match}"):
            PerspectiveCamera(_K(), W, H, distortion=bad)
    with pytest.raises(CameraError, match=r"distortion.*4 numbers"):
        UnifiedCamera(_K(), 1.0, W, H, distortion=(0.1, 0.0, 0.0, 0.0, 0.01))


# ---------------------------------------------------------------- fields and files
def test_distortion_is_a_field_of_the_camera(tmp_path: Path) -> None:
    cam = _perspective("webcam-5")
    assert cam.is_distorted and cam.distortion.tolist() == list(PERSPECTIVE_SETS["webcam-5"])
    with pytest.raises(ValueError):
        cam.distortion[0] = 0.0  # read-only
    four = PerspectiveCamera(_K(), W, H, distortion=(0.1, 0.0, 0.0, 0.0))
    assert four.distortion.tolist() == [0.1, 0.0, 0.0, 0.0, 0.0]  # k3 = 0 appended
    ideal = cam.replace(distortion=None)
    assert not ideal.is_distorted and ideal != cam
    assert ideal == PerspectiveCamera(_K(), W, H, distortion=(0, 0, 0, 0, 0))
    assert cam.replace(distortion=(-0.28, 0.07, 0.0008, -0.0005, -0.008)) == cam
    assert "distortion=(-0.28, 0.07, 0.0008, -0.0005, -0.008)" in repr(cam)
    assert "distortion" not in repr(ideal)
    with pytest.raises(DistortionError):
        cam.replace(distortion=(-0.9, 0.0, 0.0, 0.0))
    for c in (cam, _unified("mirror-0.8")):
        path = tmp_path / f"{c.kind}.toml"
        c.to_toml(path)
        text = path.read_text()
        assert "distortion = [" in text
        back = Camera.from_toml(path)
        assert back == c.replace(name=path.stem) or back == c
        assert np.array_equal(back.distortion, c.distortion)
    assert "distortion" not in ideal.to_dict()


@pytest.mark.parametrize(
    ("line", "match"),
    [("distortion = [0.1, 0.0]", "distortion.*4 or 5 or 8 or 12 or 14 numbers"),
     ("distortion = [0.1, 0.0, 0.0, nan]", "distortion.*NaN"),
     ('distortion = "none"', "distortion.*numbers"),
     ("distortion = [-0.9, 0.0, 0.0, 0.0]", "fold inside the image")],
)
def test_bad_distortion_in_a_toml_file(tmp_path: Path, line: str, match: str) -> None:
    path = tmp_path / "c.toml"
    path.write_text("kind = 'perspective'\nwidth_px = 640\nheight_px = 480\nfx_px = 800.0\n"
                    f"fy_px = 790.0\ncx_px = 330.0\ncy_px = 245.0\n{line}\n")
    with pytest.raises((CameraError, ValueError), match=match) as info:
        Camera.from_toml(path)
    assert str(path) in str(info.value)


# ---------------------------------------------------------------- features
def _line_pixels(cam: Camera, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Pixels of a 3D line crossing the image and the normal of its plane."""
    ends = [[30.0, 440.0], [610.0, 400.0]] if cam.kind == "perspective" else [
        [150.0, 380.0], [490.0, 390.0]]
    a, b = cam.lift(np.array(ends)) * [[2.0], [2.5]]
    X = a + np.linspace(0.0, 1.0, 60)[:, None] * (b - a)
    n = np.cross(a, b)
    pix, vis = cam.project(X)
    assert vis.sum() >= 30
    return pix[vis], n / np.linalg.norm(n)


def test_line_features_are_those_of_the_ideal_image(rng: np.random.Generator) -> None:
    cam = _perspective("webcam-5")
    pix, n = _line_pixels(cam, rng)
    # The raw image of the line is a curve...
    l_raw = np.polyfit(pix[:, 0], pix[:, 1], 1)
    assert np.abs(np.polyval(l_raw, pix[:, 0]) - pix[:, 1]).max() > 2.0
    # ...whose ideal-image coordinates lie on the line of the normal.
    c = cam.pixels_to_line_coordinates(pix)
    assert np.abs(np.c_[c, np.ones(len(c))] @ cam.normal_to_line(n)).max() < 1e-12
    for method in (cam.normal_to_pixel_line, cam.pixel_line_to_normal):
        with pytest.raises(CameraError, match="ideal lens"):
            method(n)
    with pytest.raises(CameraError, match="ideal lens"):
        _unified("mirror-0.8").normal_to_conic(n)


@pytest.mark.parametrize("cam", [_perspective("webcam-5"), _unified("mirror-0.8")],
                         ids=["perspective", "unified"])
def test_normal_fits_remove_the_distortion(cam: Camera, rng: np.random.Generator) -> None:
    pix, n = _line_pixels(cam, rng)
    for fit in (fit_normal, fit_normal_conic):
        est = fit(cam, pix, reference=n).normal
        assert _angle(est, n) < 1e-9, fit.__name__
        naive = fit(cam.replace(distortion=None), pix, reference=n).normal
        assert _angle(naive, n) > 1e-3  # ignoring the lens would be wrong
