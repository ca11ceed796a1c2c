"""The lens models beyond OpenCV's five coefficients: OpenCV's full model (14
coefficients) against ``cv2.projectPoints``, the fisheye (Kannala-Brandt) against
``cv2.fisheye.projectPoints``, the double sphere and extended unified models against
their published closed forms (written here from the papers), round trips, Jacobians
against finite differences and the fold checks."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from vision.cameras import (
    DoubleSphereCamera,
    ExtendedUnifiedCamera,
    FisheyeCamera,
    PerspectiveCamera,
    front_camera,
)
from vision.cameras.distortion import RadialTangential
from vision.cameras.distortion_full import OpenCVLens
from vision.exceptions import CameraError, DistortionError

W, H = 1280, 800
K0 = np.array([[420.0, 0.0, 645.3], [0.0, 424.0, 396.8], [0.0, 0.0, 1.0]])


def _points(rng: np.random.Generator, n: int, half_angle_deg: float) -> np.ndarray:
    """Points in front of the camera within a cone of the given half-angle, 0.2..3 m."""
    th = np.deg2rad(half_angle_deg) * np.sqrt(rng.uniform(0, 1, n))
    ph = rng.uniform(0, 2 * np.pi, n)
    d = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1)
    return d * rng.uniform(0.2, 3.0, (n, 1))


def _full_coefficients(rng: np.random.Generator) -> np.ndarray:
    c = np.zeros(14)
    c[:5] = rng.normal(0.0, [0.15, 0.05, 2e-3, 2e-3, 0.01])
    c[5:8] = rng.normal(0.0, [0.1, 0.03, 0.005])
    c[8:12] = rng.normal(0.0, 2e-3, 4)
    c[12:] = rng.normal(0.0, 0.02, 2)
    return c


def _non_folding_full_cameras(n: int) -> list[PerspectiveCamera]:
    """Random full-model cameras that the fold check accepts (about half are)."""
    rng = np.random.default_rng(14)
    cams: list[PerspectiveCamera] = []
    tried = 0
    while len(cams) < n:
        tried += 1
        assert tried < 20 * n, "too few non-folding coefficient sets"
        try:
            cams.append(PerspectiveCamera(K0, W, H, distortion=_full_coefficients(rng)))
        except DistortionError:
            continue
    return cams


FULL = _non_folding_full_cameras(6)


# ---------------------------------------------------------------- OpenCV's full model
@pytest.mark.parametrize("cam", FULL, ids=[f"set{i}" for i in range(len(FULL))])
def test_full_model_projects_as_cv2_project_points(cam: PerspectiveCamera) -> None:
    assert isinstance(cam.lens, OpenCVLens) and cam.distortion.shape == (14,)
    X = _points(np.random.default_rng(3), 3000, 60.0)
    pix, visible = cam.project(X)
    ref = cv2.projectPoints(X.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), cam.K,
                            np.asarray(cam.distortion))[0].reshape(-1, 2)
    assert np.abs(pix - ref).max() < 1e-9
    assert visible.mean() > 0.5


@pytest.mark.parametrize("n", [8, 12])
def test_shorter_opencv_vectors(n: int) -> None:
    c = _full_coefficients(np.random.default_rng(n))[:n]
    c[n - 1] = 0.0 if n == 12 else c[n - 1]  # a 12-vector whose last term is zero
    cam = front_camera().replace(distortion=c)
    assert cam.distortion.size == (8 if n == 8 else 12 if np.any(c[8:]) else 8)
    X = _points(np.random.default_rng(5), 500, 25.0) + np.array([0.0, 0.0, 0.5])
    ref = cv2.projectPoints(X.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), cam.K,
                            c)[0].reshape(-1, 2)
    assert np.abs(cam.project(X)[0] - ref).max() < 1e-9


def test_zero_higher_terms_keep_the_five_coefficient_model_bit_for_bit() -> None:
    five = np.array([-0.28, 0.09, 5e-4, -3e-4, -0.012])
    a = front_camera().replace(distortion=five)
    b = front_camera().replace(distortion=np.concatenate([five, np.zeros(9)]))
    assert type(b.lens) is RadialTangential and b.distortion.shape == (5,) and a == b
    X = _points(np.random.default_rng(1), 400, 25.0) + np.array([0.0, 0.0, 0.5])
    assert np.array_equal(a.project(X)[0], b.project(X)[0])
    p = a.project(X)[0]
    assert np.array_equal(a.lift(p), b.lift(p), equal_nan=True)


def test_full_model_round_trip_and_fold() -> None:
    for cam in FULL:
        X = _points(np.random.default_rng(4), 2000, 60.0)
        pix, visible = cam.project(X)
        ray = cam.lift(pix[visible])
        unit = X[visible] / np.linalg.norm(X[visible], axis=-1, keepdims=True)
        assert np.abs(ray - unit).max() < 1e-10
    # A strong rational term that folds inside the image is refused, with evidence.
    with pytest.raises(DistortionError, match="fold inside the image") as info:
        PerspectiveCamera(K0, W, H, distortion=[0.0, 0.0, 0.0, 0.0, 0.0, 0.9, 0.0, 0.0])
    assert info.value.radius_undistorted > 0
    with pytest.raises(CameraError, match="tilt"):
        PerspectiveCamera(K0, W, H, distortion=[0.0] * 12 + [2.0, 0.0])


# ---------------------------------------------------------------- fisheye
KB = (0.032, -0.011, 0.0024, -0.0004)


def test_fisheye_projects_as_cv2_fisheye() -> None:
    rng = np.random.default_rng(7)
    for skew in (0.0, 0.7):
        K = K0.copy()
        K[0, 1] = skew
        cam = FisheyeCamera(K, W, H, distortion=KB)
        X = _points(rng, 4000, 89.0)
        pix, visible = cam.project(X)
        ref = cv2.fisheye.projectPoints(X.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K,
                                        np.array(KB), alpha=skew / K[0, 0])[0].reshape(-1, 2)
        assert np.abs(pix - ref).max() < 1e-9
        assert visible.mean() > 0.5
        unit = X[visible] / np.linalg.norm(X[visible], axis=-1, keepdims=True)
        assert np.abs(cam.lift(pix[visible]) - unit).max() < 1e-10


def test_fisheye_behind_and_beyond_the_field_of_view() -> None:
    cam = FisheyeCamera(K0, W, H, distortion=KB)
    pix, visible = cam.project(np.array([[0.1, 0.2, -1.0], [1.0, 0.0, 0.0]]))
    assert not visible.any() and np.isnan(pix).all()
    # A pixel beyond the image of the 90-degree circle has no ray in front.
    rho90 = cam.lens.rho_max
    far = np.array([[cam.cx + 1.01 * rho90 * cam.fx, cam.cy]])
    assert np.isnan(cam.lift(far)).all()
    # A lens whose radius stops growing (theta_d' = 0 at 60 deg) folds in the image.
    with pytest.raises(DistortionError, match="fold inside the image"):
        FisheyeCamera(K0, W, H, distortion=(-0.3, 0.0, 0.0, 0.0))


# ---------------------------------------------------------------- DS and EUCM
def _ds_project(X: np.ndarray, K: np.ndarray, xi: float, alpha: float) -> np.ndarray:
    """Usenko, Demmel & Cremers (3DV 2018), eq. (40)-(43)."""
    x, y, z = X[:, 0], X[:, 1], X[:, 2]
    d1 = np.sqrt(x * x + y * y + z * z)
    d2 = np.sqrt(x * x + y * y + (xi * d1 + z) ** 2)
    den = alpha * d2 + (1 - alpha) * (xi * d1 + z)
    return np.stack([K[0, 0] * x / den + K[0, 2], K[1, 1] * y / den + K[1, 2]], -1)


def _ds_unproject(p: np.ndarray, K: np.ndarray, xi: float, alpha: float) -> np.ndarray:
    """Usenko et al., eq. (44)-(50)."""
    mx = (p[:, 0] - K[0, 2]) / K[0, 0]
    my = (p[:, 1] - K[1, 2]) / K[1, 1]
    r2 = mx * mx + my * my
    mz = (1 - alpha * alpha * r2) / (alpha * np.sqrt(1 - (2 * alpha - 1) * r2) + 1 - alpha)
    k = (mz * xi + np.sqrt(mz * mz + (1 - xi * xi) * r2)) / (mz * mz + r2)
    return np.stack([k * mx, k * my, k * mz - xi], -1)


def _eucm_project(X: np.ndarray, K: np.ndarray, alpha: float, beta: float) -> np.ndarray:
    """Khomutenko, Garcia & Martinet (RA-L 2016), eq. (3)-(5)."""
    x, y, z = X[:, 0], X[:, 1], X[:, 2]
    d = np.sqrt(beta * (x * x + y * y) + z * z)
    den = alpha * d + (1 - alpha) * z
    return np.stack([K[0, 0] * x / den + K[0, 2], K[1, 1] * y / den + K[1, 2]], -1)


def _eucm_unproject(p: np.ndarray, K: np.ndarray, alpha: float, beta: float) -> np.ndarray:
    """Khomutenko et al. (as restated by Usenko et al., eq. (21)-(26)), unit rays."""
    mx = (p[:, 0] - K[0, 2]) / K[0, 0]
    my = (p[:, 1] - K[1, 2]) / K[1, 1]
    r2 = mx * mx + my * my
    mz = (1 - beta * alpha * alpha * r2) / (
        alpha * np.sqrt(1 - (2 * alpha - 1) * beta * r2) + 1 - alpha)
    v = np.stack([mx, my, mz], -1)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


CENTRAL = [
    ("ds", DoubleSphereCamera, (-0.18, 0.59), _ds_project, _ds_unproject),
    ("ds-positive-xi", DoubleSphereCamera, (0.25, 0.45), _ds_project, _ds_unproject),
    ("eucm", ExtendedUnifiedCamera, (0.63, 1.07), _eucm_project, _eucm_unproject),
    ("eucm-flat", ExtendedUnifiedCamera, (0.4, 0.6), _eucm_project, _eucm_unproject),
]


@pytest.mark.parametrize("name,model,params,proj,unproj", CENTRAL,
                         ids=[c[0] for c in CENTRAL])
def test_central_models_match_the_published_forms(name, model, params, proj,  # type: ignore[no-untyped-def]
                                                  unproj) -> None:
    cam = model(K0, W, H, distortion=params)
    X = _points(np.random.default_rng(11), 4000, 85.0)
    pix, visible = cam.project(X)
    assert np.abs(pix - proj(X, K0, *params)).max() < 1e-9
    assert visible.mean() > 0.3  # within the image
    ray = cam.lift(pix[visible])
    unit = X[visible] / np.linalg.norm(X[visible], axis=-1, keepdims=True)
    assert np.abs(ray - unit).max() < 1e-10  # lift(project(X)) along X
    ref = unproj(pix[visible], K0, *params)
    ref /= np.linalg.norm(ref, axis=-1, keepdims=True)
    assert np.abs(ray - ref).max() < 1e-10


def test_central_models_refuse_parameters_out_of_range() -> None:
    with pytest.raises(CameraError, match="xi") as info:
        DoubleSphereCamera(K0, W, H, distortion=(1.5, 0.5))
    assert info.value.field == "distortion"
    with pytest.raises(CameraError, match="beta"):
        ExtendedUnifiedCamera(K0, W, H, distortion=(0.5, -1.0))
    with pytest.raises(CameraError, match="2 finite numbers"):
        ExtendedUnifiedCamera(K0, W, H, distortion=(0.5, 1.0, 0.0))


# ---------------------------------------------------------------- Jacobians
def _models() -> list[PerspectiveCamera]:
    return [FULL[0], FULL[1], FisheyeCamera(K0, W, H, distortion=KB),
            DoubleSphereCamera(K0, W, H, distortion=(-0.18, 0.59)),
            ExtendedUnifiedCamera(K0, W, H, distortion=(0.63, 1.07))]


@pytest.mark.parametrize("cam", _models(), ids=["full0", "full1", "fisheye", "ds", "eucm"])
def test_jacobians_against_finite_differences(cam: PerspectiveCamera) -> None:
    rng = np.random.default_rng(21)
    X = _points(rng, 200, 50.0)
    J = cam.project_jacobian(X)
    h = 1e-6
    fd = np.stack([(cam.project(X + h * e)[0] - cam.project(X - h * e)[0]) / (2 * h)
                   for e in np.eye(3)], -1)
    assert np.abs(J - fd).max() < 1e-5 * max(1.0, np.abs(fd).max())
    pix, visible = cam.project(X)
    p = pix[visible]
    Jl = cam.lift_jacobian(p)
    hp = 1e-4
    fdl = np.stack([(cam.lift(p + hp * e) - cam.lift(p - hp * e)) / (2 * hp)
                    for e in np.eye(2)], -1)
    assert np.abs(Jl - fdl).max() < 1e-8
    m = np.column_stack([X[:, 0] / X[:, 2], X[:, 1] / X[:, 2]])
    Jd = cam.lens.jacobian(m)
    fdd = np.stack([(cam.lens.apply(m + 1e-7 * e) - cam.lens.apply(m - 1e-7 * e)) / 2e-7
                    for e in np.eye(2)], -1)
    assert np.abs(Jd - fdd).max() < 1e-6


def test_ignoring_the_lens_gives_the_pinhole() -> None:
    cam = FisheyeCamera(K0, W, H, distortion=KB)
    ideal = cam.lens_scaled(0.0)
    assert type(ideal) is PerspectiveCamera and not ideal.is_distorted
    assert np.array_equal(ideal.K, cam.K) and cam.lens_scaled(1.0) is cam
    with pytest.raises(CameraError, match="not in part"):
        cam.lens_scaled(0.5)
    assert front_camera().replace(distortion=FULL[0].distortion).lens_scaled(0.0) == \
        front_camera()


@pytest.mark.parametrize("cam", [*_models(), FisheyeCamera(K0, W, H)],
                         ids=["full0", "full1", "fisheye", "ds", "eucm", "equidistant"])
def test_every_model_round_trips_through_the_camera_toml(cam: PerspectiveCamera,
                                                         tmp_path: Path) -> None:
    from vision.cameras import Camera

    path = tmp_path / "cam.toml"
    cam.to_toml(path)
    back = Camera.from_toml(path)
    assert type(back) is type(cam) and back == cam
    X = _points(np.random.default_rng(2), 50, 40.0)
    assert np.array_equal(back.project(X)[0], cam.project(X)[0], equal_nan=True)
