"""Camera models, checked numerically: against OpenCV, by round trips, by sampling
3D lines; presets against the seeds' figures; TOML files and bad input."""

from __future__ import annotations

import re
from pathlib import Path

import cv2
import numpy as np
import pytest

from hexapod import ConfigFileError, Transform, sample_poses
from hexapod.se3 import exp_so3
from vision.cameras import (
    Camera,
    PerspectiveCamera,
    UnifiedCamera,
    camera_preset,
    front_camera,
    load_camera,
    omni_camera,
)
from vision.exceptions import CameraError
from vision.legs import limb_points, observe_legs


def _random_pose(rng: np.random.Generator) -> Transform:
    return Transform(exp_so3(rng.normal(size=3)), rng.normal(scale=0.3, size=3))


def _K(fx: float = 800.0, fy: float = 790.0, cx: float = 330.0, cy: float = 245.0,
       s: float = 0.0) -> np.ndarray:
    return np.array([[fx, s, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


def _points_in_front(rng: np.random.Generator, n: int) -> np.ndarray:
    X = rng.uniform(-1, 1, size=(n, 3))
    X[:, 2] = rng.uniform(0.5, 3.0, size=n)
    return X


# ---------------------------------------------------------------- projection
def test_perspective_projection_matches_opencv(rng: np.random.Generator) -> None:
    pose = _random_pose(rng)
    cam = PerspectiveCamera(_K(), 640, 480, pose)
    # Points in the base frame that are in front of the camera.
    Xc = _points_in_front(rng, 200)
    Xb = pose.inverse().apply(Xc)
    rvec, _ = cv2.Rodrigues(pose.rotation)
    ref, _ = cv2.projectPoints(Xb.reshape(-1, 1, 3), rvec, pose.translation, cam.K, None)
    pix, _ = cam.project_base(Xb)
    assert np.allclose(pix, ref.reshape(-1, 2), atol=1e-8)
    pix_c, _ = cam.project(Xc)
    assert np.allclose(pix_c, ref.reshape(-1, 2), atol=1e-8)


@pytest.mark.parametrize("xi", [0.3, 0.8, 1.0, 1.6])
def test_unified_projection_matches_opencv_on_shifted_sphere(
    rng: np.random.Generator, xi: float
) -> None:
    """The unified model is a pinhole looking at the sphere point from (0, 0, -xi)."""
    cam = UnifiedCamera(_K(300, 310, 320, 240), xi, 640, 480)
    X = rng.normal(size=(300, 3))
    Xs = X / np.linalg.norm(X, axis=1, keepdims=True)
    keep = Xs[:, 2] > -min(xi, 1 / xi) + 0.05
    shifted = Xs[keep] + [0.0, 0.0, xi]
    ref, _ = cv2.projectPoints(shifted.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), cam.K, None)
    pix, _ = cam.project(X[keep] * rng.uniform(0.1, 10, size=(keep.sum(), 1)))
    assert np.allclose(pix, ref.reshape(-1, 2), atol=1e-8)


@pytest.mark.parametrize(
    "cam",
    [
        PerspectiveCamera(_K(s=2.0), 640, 480),
        UnifiedCamera(_K(300, 310, 320, 240, 1.5), 1.0, 640, 480),
        UnifiedCamera(_K(300, 310, 320, 240), 0.6, 640, 480),
        UnifiedCamera(_K(300, 310, 320, 240), 1.7, 640, 480),
    ],
)
def test_lift_of_projection_is_parallel_to_point(
    cam: Camera, rng: np.random.Generator
) -> None:
    X = rng.normal(size=(500, 3)) * rng.uniform(0.05, 20, size=(500, 1))
    pix, _ = cam.project(X)
    ok = np.all(np.isfinite(pix), axis=1)
    assert ok.sum() > 100
    S = cam.lift(pix[ok])
    Xu = X[ok] / np.linalg.norm(X[ok], axis=1, keepdims=True)
    assert np.allclose(np.linalg.norm(S, axis=1), 1.0, atol=1e-12)
    # Same direction (parallel AND same sense): the lifted point is the point itself.
    assert np.allclose(S, Xu, atol=1e-10)


def test_batched_shapes(rng: np.random.Generator) -> None:
    for cam in (front_camera(), omni_camera()):
        X = rng.normal(size=(2, 3, 4, 3)) + np.array([0.0, 0.0, 3.0])
        pix, vis = cam.project(X)
        assert pix.shape == (2, 3, 4, 2) and vis.shape == (2, 3, 4)
        assert cam.lift(pix).shape == (2, 3, 4, 3)
        pix1, vis1 = cam.project(X[1, 2, 3])
        assert np.allclose(pix1, pix[1, 2, 3]) and vis1 == vis[1, 2, 3]


def test_xi_zero_is_exactly_the_perspective_camera(rng: np.random.Generator) -> None:
    pose = _random_pose(rng)
    K = _K(s=1.0)
    per = PerspectiveCamera(K, 640, 480, pose)
    uni = UnifiedCamera(K, 0.0, 640, 480, pose)
    X = rng.normal(size=(400, 3)) * 2
    p1, v1 = per.project(X)
    p2, v2 = uni.project(X)
    assert np.array_equal(p1, p2, equal_nan=True)
    assert np.array_equal(v1, v2)
    pix = rng.uniform(0, 640, size=(100, 2))
    assert np.array_equal(per.lift(pix), uni.lift(pix))
    # Conic of a line = the double pixel line of the perspective camera.
    n = rng.normal(size=(20, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    l = per.normal_to_pixel_line(n)
    C = uni.normal_to_conic(n)
    ll = np.einsum("...i,...j->...ij", l, l)
    assert np.allclose(C, ll / np.linalg.norm(ll, axis=(-2, -1), keepdims=True), atol=1e-12)


def test_visibility_mask() -> None:
    cam = PerspectiveCamera(_K(), 640, 480)
    X = np.array([[0, 0, 1.0], [0, 0, -1.0], [10.0, 0, 1.0], [0, 0, 0.0], [0.1, 0.1, 2.0]])
    pix, vis = cam.project(X)
    assert vis.tolist() == [True, False, False, False, True]
    assert np.all(np.isnan(pix[1])) and np.all(np.isnan(pix[3]))
    assert np.all(np.isfinite(pix[2]))  # imaged, only outside the image
    # Image bounds: pixel centres at integers, the image is [-0.5, w - 0.5] x [-0.5, h - 0.5].
    assert cam.in_image(np.array([[-0.5, -0.5], [639.5, 479.5]])).all()
    assert not cam.in_image(np.array([[-0.51, 0.0], [0.0, 479.51]])).any()
    # Unified, xi = 0.5: imaged iff X_s,z > -0.5.
    uni = UnifiedCamera(_K(100, 100, 320, 240), 0.5, 640, 480)
    d = np.array([[np.sqrt(1 - 0.45**2), 0, -0.45], [np.sqrt(1 - 0.55**2), 0, -0.55]])
    pix, _ = uni.project(d)
    assert np.all(np.isfinite(pix[0])) and np.all(np.isnan(pix[1]))
    assert np.allclose(uni.lift(pix[0]), d[0])
    # Parabolic: everything but the point straight behind the mirror.
    par = UnifiedCamera(_K(100, 100, 320, 240), 1.0, 640, 480)
    pix, v = par.project(np.array([[0.0, 0.0, -1.0], [0.0, 0.0, 1.0]]))
    assert v.tolist() == [False, True] and np.all(np.isnan(pix[0]))


# ---------------------------------------------------------------- lines and conics
def _line_points(
    rng: np.random.Generator, n: int, depth: float = 2.0
) -> tuple[np.ndarray, np.ndarray]:
    """Points on a random 3D line (around (0, 0, depth)) and its plane normal."""
    P0 = rng.uniform(-0.5, 0.5, size=3) + np.array([0.0, 0.0, depth])
    d = rng.normal(size=3)
    d /= np.linalg.norm(d)
    X = P0 + np.linspace(-0.4, 0.4, n)[:, None] * d
    nrm = np.cross(P0, d)
    return X, nrm / np.linalg.norm(nrm)


def test_points_of_a_3d_line_lie_on_the_pixel_line(rng: np.random.Generator) -> None:
    cam = PerspectiveCamera(_K(s=0.5), 640, 480)
    for _ in range(20):
        X, n = _line_points(rng, 30)
        pix, _ = cam.project(X)
        ph = np.c_[pix, np.ones(len(pix))]
        l = cam.normal_to_pixel_line(n)
        assert np.isclose(np.linalg.norm(l), 1.0)
        dist = ph @ l / np.linalg.norm(l[:2])  # pixel distance to the line
        assert np.abs(dist).max() < 1e-9
        # Normalised pixel coordinates ((u - w/2)/w, (v - h/2)/w).
        ln = cam.normal_to_line(n)
        c = np.c_[(pix[:, 0] - 320) / 640, (pix[:, 1] - 240) / 640, np.ones(len(pix))]
        assert np.abs(c @ ln).max() < 1e-12
        assert np.allclose(cam.line_to_normal(ln), n, atol=1e-12)
        assert np.allclose(cam.pixel_line_to_normal(l), n, atol=1e-12)
        # Positive scale: the sign follows n.
        assert np.allclose(cam.normal_to_line(-n), -ln)
        # A point off the line is off the line.
        off = cam.project(X[0] + 0.05 * n)[0]
        assert abs(np.r_[off, 1.0] @ l / np.linalg.norm(l[:2])) > 1.0


@pytest.mark.parametrize("xi", [0.4, 0.9, 1.0])
def test_points_of_a_3d_line_lie_on_the_conic(rng: np.random.Generator, xi: float) -> None:
    cam = UnifiedCamera(_K(250, 260, 320, 240, 0.3), xi, 640, 480)
    for _ in range(20):
        X, n = _line_points(rng, 40, depth=rng.uniform(-0.3 if xi == 1 else 0.3, 2.0))
        pix, _ = cam.project(X)
        ok = np.all(np.isfinite(pix), axis=1)
        assert ok.sum() >= 5
        ph = np.c_[pix[ok], np.ones(ok.sum())]
        C = cam.normal_to_conic(n)
        assert np.isclose(np.linalg.norm(C), 1.0) and np.allclose(C, C.T)
        # Algebraic residual scaled by the gradient: first-order pixel distance.
        val = np.einsum("ni,ij,nj->n", ph, C, ph)
        grad = 2 * (ph @ C)[:, :2]
        assert np.abs(val / np.linalg.norm(grad, axis=1)).max() < 1e-8
        off = cam.project(X[ok][ok.sum() // 2] + 0.05 * n)[0]
        po = np.r_[off, 1.0]
        assert abs(po @ C @ po / np.linalg.norm(2 * (po @ C)[:2])) > 0.5


# ---------------------------------------------------------------- presets
def test_front_preset_matches_the_seed(geometry) -> None:
    cam = front_camera()
    assert cam.kind == "perspective" and cam.xi == 0.0
    assert (cam.width, cam.height) == (1024, 780)
    assert cam.fx == pytest.approx(4.8e-3 / 4.65e-6)
    c = cam.centre_in_base
    assert np.hypot(c[0], c[1]) == pytest.approx(0.8)
    # Looking at the robot: the base centre and the platform centre are in the image.
    _, vis = cam.project_base(np.array([[0, 0, 0.0], [0, 0, geometry.home_height]]))
    assert vis.all()


def test_front_preset_sees_every_leg_and_hides_some(geometry) -> None:
    cam = front_camera(geometry)
    R, t = sample_poses(geometry, 1500, 7)
    obs = observe_legs(cam, geometry, R, t, n_samples=16)
    P = limb_points(obs.base_points, obs.directions, geometry.leg_radius, obs.lengths,
                    obs.normals, np.linspace(0.0, 1.0, 21))
    _, imaged = cam.project(P)
    assert imaged.all(), "a leg leaves the image of the front camera"
    hidden = ~obs.edge_visible
    assert 0.02 < hidden.any(axis=(-2, -1)).mean() < 0.6  # occlusions in part of the workspace
    assert hidden.mean() < 0.05


def test_omni_preset_annulus_and_no_hidden_leg(geometry) -> None:
    cam = omni_camera(geometry)
    assert cam.kind == "unified" and cam.xi == 1.0 and (cam.width, cam.height) == (640, 480)
    R, t = sample_poses(geometry, 1500, 8)
    obs = observe_legs(cam, geometry, R, t)
    assert obs.edge_visible.all()
    P = limb_points(obs.base_points, obs.directions, geometry.leg_radius, obs.lengths,
                    obs.normals, np.linspace(0.0, 1.0, 41))
    pix, imaged = cam.project(P)
    assert imaged.all()
    radius = np.linalg.norm(pix - [cam.cx, cam.cy], axis=-1)
    # Every edge crosses the whole annulus of diameters 184 to 370 pixels.
    assert radius.max(axis=-1).min() > 370 / 2
    assert radius.min(axis=-1).max() < 184 / 2


def test_camera_preset_by_name(geometry) -> None:
    assert camera_preset("front") == front_camera()
    assert camera_preset("omni", geometry) == omni_camera(geometry)
    with pytest.raises(CameraError, match="did you mean 'front'"):
        camera_preset("fornt")
    with pytest.raises(CameraError, match="available: front, omni"):
        camera_preset("zzz")


def test_load_camera_missing_file_without_extension(tmp_path: Path) -> None:
    # a name with a folder separator is a file, never a preset: "file not found", as a
    # missing .toml says
    missing = tmp_path / "nope_camera"
    with pytest.raises(ConfigFileError, match=rf"^{re.escape(str(missing))}: file not found$"):
        load_camera(str(missing))
    with pytest.raises(ConfigFileError, match=r"^nope_camera: file not found$"):
        load_camera(Path("nope_camera"))
    with pytest.raises(ConfigFileError,
                       match=rf"^{re.escape(str(missing))}\.toml: file not found$"):
        load_camera(f"{missing}.toml")
    with pytest.raises(CameraError, match="unknown camera preset 'nope_camera'"):
        load_camera("nope_camera")
    assert load_camera(Path("front")) == front_camera()


# ---------------------------------------------------------------- validation
def test_constructor_validation(rng: np.random.Generator) -> None:
    with pytest.raises(CameraError, match="shape"):
        PerspectiveCamera(np.eye(2), 640, 480)
    with pytest.raises(CameraError, match="positive"):
        PerspectiveCamera(_K(fx=-5), 640, 480)
    with pytest.raises(CameraError, match="NaN"):
        PerspectiveCamera(_K(cx=np.nan), 640, 480)
    with pytest.raises(CameraError, match="width"):
        PerspectiveCamera(_K(), 0, 480)
    with pytest.raises(CameraError, match="height"):
        PerspectiveCamera(_K(), 640, 480.5)
    with pytest.raises(CameraError, match="xi"):
        UnifiedCamera(_K(), -0.1, 640, 480)
    bad_K = _K()
    bad_K[2, 0] = 1.0
    with pytest.raises(CameraError, match="fx, s, cx"):
        UnifiedCamera(bad_K, 1.0, 640, 480)
    with pytest.raises(CameraError, match="rotation"):
        PerspectiveCamera(_K(), 640, 480, Transform(2 * np.eye(3), np.zeros(3)))
    with pytest.raises(CameraError, match="rotation"):
        PerspectiveCamera(_K(), 640, 480, Transform(np.diag([1.0, 1.0, -1.0]), np.zeros(3)))
    # The arrays are read-only (cameras are values).
    cam = PerspectiveCamera(_K(), 640, 480)
    with pytest.raises(ValueError):
        cam.K[0, 0] = 1.0


def test_replace_validates_and_suggests() -> None:
    cam = omni_camera()
    c2 = cam.replace(xi=0.8)
    assert isinstance(c2, UnifiedCamera) and c2.xi == 0.8 and cam.xi == 1.0
    assert c2.replace(xi=1.0) == cam
    with pytest.raises(CameraError, match="xi"):
        cam.replace(xi=-1.0)
    with pytest.raises(CameraError, match="did you mean 'width'"):
        cam.replace(widht=3)
    with pytest.raises(CameraError):
        front_camera().replace(xi=1.0)  # not a field of the perspective camera


# ---------------------------------------------------------------- TOML
@pytest.mark.parametrize("factory", [front_camera, omni_camera])
def test_toml_round_trip(tmp_path: Path, factory) -> None:
    cam = factory()
    path = tmp_path / "cam.toml"
    cam.to_toml(path)
    back = Camera.from_toml(path)
    assert type(back) is type(cam)
    assert np.allclose(back.K, cam.K, atol=1e-12, rtol=0)
    assert (back.width, back.height, back.xi) == (cam.width, cam.height, cam.xi)
    assert np.allclose(back.camera_from_base.rotation, cam.camera_from_base.rotation, atol=1e-12)
    assert np.allclose(back.camera_from_base.translation, cam.camera_from_base.translation,
                       atol=1e-12)
    assert back.name == cam.name
    assert type(cam).from_toml(path) == back
    assert load_camera(path) == back
    # Same projections.
    X = np.array([[0.1, -0.2, 0.3], [0.0, 0.05, 0.4]])
    assert np.allclose(back.project_base(X)[0], cam.project_base(X)[0], atol=1e-8)


def _write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "c.toml"
    p.write_text(text)
    return p


_GOOD = """
kind = "unified"
width_px = 640
height_px = 480
fx_px = 200.0
fy_px = 200.0
cx_px = 319.5
cy_px = 239.5
xi = 1.0
[camera_from_base]
translation_mm = [0.0, 0.0, 10.0]
rotation_vector_deg = [0.0, 0.0, 90.0]
"""


def test_toml_file_values(tmp_path: Path) -> None:
    cam = Camera.from_toml(_write(tmp_path, _GOOD))
    assert isinstance(cam, UnifiedCamera) and cam.name == "c"
    assert np.allclose(cam.camera_from_base.translation, [0, 0, 0.01])
    assert np.allclose(cam.camera_from_base.rotation, [[0, -1, 0], [1, 0, 0], [0, 0, 1]])
    rot = _GOOD.replace("rotation_vector_deg = [0.0, 0.0, 90.0]",
                        "rotation_matrix = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]")
    cam2 = Camera.from_toml(_write(tmp_path, rot))
    assert np.allclose(cam2.camera_from_base.rotation, cam.camera_from_base.rotation, atol=1e-15)
    assert cam2.replace(camera_from_base=cam.camera_from_base) == cam


@pytest.mark.parametrize(
    ("change", "match"),
    [
        (("fx_px = 200.0", "fxx_px = 200.0"), "fxx_px.*did you mean 'fx_px'"),
        (("fx_px = 200.0", ""), "fx_px.*missing"),
        (("xi = 1.0", ""), "xi.*missing"),
        (("fx_px = 200.0", "fx_px = -200.0"), "fx_px.*positive"),
        (("fy_px = 200.0", "fy_px = nan"), "fy_px.*finite"),
        (("width_px = 640", "width_px = 640.5"), "width_px.*integer"),
        (("height_px = 480", "height_px = 0"), "height_px.*integer"),
        (("xi = 1.0", "xi = -1.0"), "xi.*>= 0"),
        (('kind = "unified"', 'kind = "unifed"'), "kind.*did you mean 'unified'"),
        (("translation_mm = [0.0, 0.0, 10.0]", "translation_mm = [0.0, 10.0]"),
         r"camera_from_base.translation_mm.*shape"),
        (("translation_mm", "translaton_mm"), "did you mean 'translation_mm'"),
        (("rotation_vector_deg = [0.0, 0.0, 90.0]", "rotation_vector_deg = [0.0, nan, 9.0]"),
         "rotation_vector_deg.*NaN"),
        (("rotation_vector_deg = [0.0, 0.0, 90.0]",
          "rotation_vector_deg = [0.0, 0.0, 90.0]\nrotation_matrix = [[1,0,0],[0,1,0],[0,0,1]]"),
         "not both"),
        (("width_px = 640", "width_px = 640\nwidth_px = 3"), "not valid TOML"),
        # a principal point outside the image: the size swapped, or millimetres
        (("cx_px = 319.5", "cx_px = 639.6"), r"cx_px.*principal point must lie in the image, "
         r"\[-0\.5, 639\.5\] px for width_px = 640, got 639\.6"),
        (("cy_px = 239.5", "cy_px = -0.6"), r"cy_px.*\[-0\.5, 479\.5\] px for height_px = 480"),
    ],
)
def test_toml_bad_input(tmp_path: Path, change: tuple[str, str], match: str) -> None:
    text = _GOOD.replace(*change)
    with pytest.raises(ConfigFileError, match=match):
        Camera.from_toml(_write(tmp_path, text))


def test_toml_bad_rotation_and_kind_mismatch(tmp_path: Path,
                                            caplog: pytest.LogCaptureFixture) -> None:
    bad = _GOOD.replace("rotation_vector_deg = [0.0, 0.0, 90.0]",
                        "rotation_matrix = [[1, 0, 0], [0, 2, 0], [0, 0, 1]]")
    with pytest.raises(ConfigFileError, match="not a rotation matrix") as info:
        Camera.from_toml(_write(tmp_path, bad))
    assert info.value.key == "camera_from_base.rotation_matrix"
    mirror = bad.replace("[0, 2, 0]", "[0, -1, 0]")
    with pytest.raises(ConfigFileError, match="a mirror"):
        Camera.from_toml(_write(tmp_path, mirror))
    # a rotation written to 3 decimals (as a datasheet prints it): its nearest rotation,
    # said; it was refused at 1e-6
    c, s_ = np.cos(np.radians(30.0)), np.sin(np.radians(30.0))
    rounded = bad.replace("[[1, 0, 0], [0, 2, 0], [0, 0, 1]]",
                          f"[[{c:.3f}, {-s_:.3f}, 0], [{s_:.3f}, {c:.3f}, 0], [0, 0, 1]]")
    with caplog.at_level("WARNING"):
        cam = Camera.from_toml(_write(tmp_path, rounded))
    R = cam.camera_from_base.rotation
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(R[:2, :2], [[c, -s_], [s_, c]], atol=1e-3)
    assert "rotation_matrix is a rotation to" in caplog.text and "(rounded?)" in caplog.text
    with pytest.raises(ConfigFileError, match="cannot be loaded as PerspectiveCamera"):
        PerspectiveCamera.from_toml(_write(tmp_path, _GOOD))
    per = _GOOD.replace('kind = "unified"', 'kind = "perspective"')
    with pytest.raises(ConfigFileError, match="xi"):
        Camera.from_toml(_write(tmp_path, per))
    cam = Camera.from_toml(_write(tmp_path, per.replace("xi = 1.0", "")))
    assert isinstance(cam, PerspectiveCamera)
    with pytest.raises(ConfigFileError, match="not found"):
        Camera.from_toml(tmp_path / "missing.toml")


def test_line_matrix_is_the_normalisation_of_K() -> None:
    cam = front_camera()
    pix = np.array([[0.0, 0.0], [1024.0, 780.0], [512.0, 390.0]])
    ph = np.c_[pix, np.ones(3)]
    rays = ph @ np.linalg.inv(cam.K).T
    norm = rays @ cam.line_matrix.T
    assert np.allclose(norm[:, :2] / norm[:, 2:], [[-0.5, -390 / 1024], [0.5, 390 / 1024],
                                                   [0.0, 0.0]])
    assert np.allclose(cam.pixels_to_line_coordinates(pix), norm[:, :2] / norm[:, 2:])


def test_normals_to_lines_is_each_rows_normal_to_line_bitwise(
        rng: np.random.Generator) -> None:
    """The batched image lines (every row through its own camera, as the simulator's
    sensor takes them) are the per-camera ``normal_to_line`` to the last bit, NaN rows
    included; a matrix per row is required."""
    from vision.cameras.perspective import normals_to_lines

    cams = [PerspectiveCamera(_K(fx=700.0 + 50 * k, cy=240.0 + k), 1024, 780,
                              _random_pose(rng)) for k in range(5)]
    n = rng.normal(size=(5, 6, 2, 3))
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    n[2, 3, 1] = np.nan
    out = normals_to_lines(n, np.stack([c.normal_to_line_matrix for c in cams]))
    expected = np.stack([c.normal_to_line(n[k]) for k, c in enumerate(cams)])
    assert np.array_equal(out, expected, equal_nan=True)
    assert np.isnan(out[2, 3, 1]).all() and np.isfinite(out[2, 3, 0]).all()
    with pytest.raises(CameraError, match="matrices"):
        normals_to_lines(n, np.stack([c.normal_to_line_matrix for c in cams[:4]]))


def test_packaged_preset_files_match_the_presets() -> None:
    data = Path(__file__).resolve().parents[2] / "vision" / "data"
    for name, factory in (("front", front_camera), ("omni", omni_camera)):
        cam = Camera.from_toml(data / f"{name}.toml")
        ref = factory()
        assert type(cam) is type(ref) and cam.name == name
        assert np.allclose(cam.K, ref.K) and cam.xi == ref.xi
        assert np.allclose(cam.camera_from_base.as_matrix(), ref.camera_from_base.as_matrix(),
                           atol=1e-12)


def test_every_former_public_name_still_imports_from_vision_cameras() -> None:
    """``vision.cameras`` was split (checks, file format, presets): its public names stay."""
    import vision.cameras as cameras
    import vision.cameras.presets as presets

    names = ("Camera", "PerspectiveCamera", "UnifiedCamera", "camera_preset", "front_camera",
             "omni_camera", "load_camera", "FRONT_PIXEL_SIZE", "FRONT_FOCAL_LENGTH",
             "FRONT_DISTANCE", "FRONT_AZIMUTH_DEG", "FRONT_EYE_HEIGHT", "FRONT_TARGET_HEIGHT",
             "OMNI_FOCAL")
    missing = [n for n in names if not hasattr(cameras, n)]
    assert not missing
    assert set(names) <= set(cameras.__all__)
    assert cameras.front_camera is presets.front_camera
    assert cameras.FRONT_DISTANCE == presets.FRONT_DISTANCE == 0.80


def test_front_camera_distance_moves_the_eye_along_its_azimuth() -> None:
    from vision.cameras.presets import FRONT_DISTANCE

    base = front_camera()
    assert np.allclose(front_camera(distance=FRONT_DISTANCE).K, base.K)
    eye0 = base.base_from_camera.translation
    eye = front_camera(distance=0.7).base_from_camera.translation
    assert np.hypot(eye[0], eye[1]) == pytest.approx(0.7 / FRONT_DISTANCE * np.hypot(*eye0[:2]))
    assert eye[2] == pytest.approx(eye0[2])
    assert np.arctan2(eye[1], eye[0]) == pytest.approx(np.arctan2(eye0[1], eye0[0]))
    for bad in (0.0, -0.8, float("nan")):
        with pytest.raises(CameraError, match="distance: front camera: must be positive"):
            front_camera(distance=bad)


def test_lines_and_normals_are_the_numpy_paths_bitwise(
        rng: np.random.Generator, monkeypatch: pytest.MonkeyPatch) -> None:
    """The image lines through each row's camera and the normals the estimated camera
    lifts them to, in one C call, are normals_to_lines and line_to_normal to the last
    bit, NaN rows included, on rows of cameras of different intrinsics; without a
    compiler the numpy path runs; a matrix per row is required."""
    from vision import kernels
    from vision.cameras.perspective import (
        _lines_mode,
        _lines_normals,
        lines_and_normals,
        normals_to_lines,
    )

    lib = kernels.library()
    fused = None if lib is None else _lines_mode(lib)
    assert fused is not None  # compiled, and this machine's BLAS sums as one of its modes
    cams = [PerspectiveCamera(_K(fx=700.0 + 5 * k, cy=240.0 + 0.1 * k, s=0.01 * k), 1024,
                              780, _random_pose(rng)) for k in range(201)]
    n = rng.normal(size=(200, 6, 2, 3))
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    n[rng.random((200, 6, 2)) < 0.05] = np.nan
    maps = np.stack([c.normal_to_line_matrix for c in cams[:200]])
    expected_lines = normals_to_lines(n, maps)
    expected_normals = cams[200].line_to_normal(expected_lines)
    for load in (kernels._load, lambda: None):
        monkeypatch.setattr(kernels, "_load", load)
        lines, normals = lines_and_normals(n, maps, cams[200])
        assert np.array_equal(lines, expected_lines, equal_nan=True)
        assert np.array_equal(normals, expected_normals, equal_nan=True)
        with pytest.raises(CameraError, match="matrices"):
            lines_and_normals(n, maps[:4], cams[200])
    assert np.isnan(expected_normals).any() and np.isfinite(expected_normals).any()
    other = _lines_normals(lib, 1 - fused, n, maps, cams[200].line_matrix)  # the mode matters
    assert not np.array_equal(other[0], expected_lines, equal_nan=True)
