"""The compiled observation of the legs equals the numpy reference, item by item, for
batches whose items each have their own robot, camera and pose."""

from __future__ import annotations

import numpy as np
import pytest

from hexapod import deltalab
from hexapod.kinematics import Transform
from hexapod.se3 import exp_so3
from hexapod.workspace import sample_poses
from vision import fast_observe
from vision.cameras import front_camera, omni_camera
from vision.legs import observe_legs, observe_legs_numpy

FIELDS = ("normals", "edge_visible", "visible_fraction", "visible_interval", "base_points",
          "directions", "lengths", "platform_centre", "platform_normal", "exists")


def _worlds(kind: str, n: int, rng: np.random.Generator) -> tuple[list, list]:
    """Perturbed robots (base, platform points, radius) and cameras (pose, intrinsics)."""
    g0 = deltalab()
    cam0 = front_camera(g0) if kind == "front" else omni_camera(g0)
    geos, cams = [], []
    for _ in range(n):
        g = g0.replace(base_points=g0.base_points + 0.004 * rng.standard_normal((6, 3)),
                       platform_points=g0.platform_points + 0.004 * rng.standard_normal((6, 3)),
                       leg_radius=g0.leg_radius * (1 + 0.3 * rng.uniform(-1, 1)))
        T = cam0.camera_from_base
        dR = exp_so3(np.deg2rad(2.0) * rng.standard_normal(3))
        K = cam0.K.copy()
        K[0, 0] *= 1 + 0.05 * rng.standard_normal()
        K[1, 2] += 5 * rng.standard_normal()
        cams.append(cam0.replace(K=K, camera_from_base=Transform(
            dR @ T.rotation, dR @ T.translation + 0.01 * rng.standard_normal(3))))
        geos.append(g)
    return geos, cams


@pytest.mark.parametrize("kind", ["front", "omni"])
def test_batch_of_worlds_equals_the_numpy_reference(kind: str) -> None:
    assert fast_observe.compiled(), "the C core must build here (a C compiler is installed)"
    rng = np.random.default_rng(7)
    geos, cams = _worlds(kind, 60, rng)
    R, t = sample_poses(deltalab(), 60, rng=rng, margin=0.01)
    params = fast_observe.WorldParams.from_worlds(geos, cams)
    fast = fast_observe.observe_batch(params, R, t)
    hidden = 0
    for k in range(60):
        ref = observe_legs_numpy(cams[k], geos[k], R[k], t[k])
        hidden += int((~ref.edge_visible).sum())
        for f in FIELDS:
            a, b = getattr(fast, f)[k], np.asarray(getattr(ref, f))
            if a.dtype == bool:
                assert np.array_equal(a, b), (k, f)
            else:
                np.testing.assert_allclose(a, b, rtol=0, atol=1e-12, err_msg=f"{k} {f}")
    if kind == "front":
        assert hidden > 0, "the check must cover hidden edges (occlusions)"


@pytest.mark.parametrize("kind", ["front", "omni"])
def test_observe_legs_uses_the_core_and_matches(kind: str) -> None:
    g = deltalab()
    cam = front_camera(g) if kind == "front" else omni_camera(g)
    R, t = sample_poses(g, 200, rng=3)
    fast = observe_legs(cam, g, R, t)
    ref = observe_legs_numpy(cam, g, R, t)
    for f in (*FIELDS, "segments"):
        a, b = np.asarray(getattr(fast, f)), np.asarray(getattr(ref, f))
        if a.dtype == bool:
            assert np.array_equal(a, b), f
        else:
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-9, err_msg=f)
    # no occlusion and a different sampling go through the core too
    a = observe_legs(cam, g, R, t, n_samples=5, min_visible_fraction=0.9, occlusion=False)
    b = observe_legs_numpy(cam, g, R, t, n_samples=5, min_visible_fraction=0.9,
                           occlusion=False)
    assert np.array_equal(a.edge_visible, b.edge_visible)


@pytest.mark.parametrize(("kind", "coefficients"), [
    ("front", (-0.28, 0.08, 0.0, 0.0, -0.01)),
    ("omni", (-0.1, 0.02, 0.0, 0.0)),
    ("front", (-0.2, 0.05, 0.002, -0.001, 0.0)),   # tangential: the numpy reference runs
])
def test_distorted_cameras_equal_the_numpy_reference(kind: str,
                                                     coefficients: tuple[float, ...]) -> None:
    g = deltalab()
    cam = (front_camera(g) if kind == "front" else omni_camera(g)).replace(
        distortion=coefficients)
    assert fast_observe.supported(cam) == (coefficients[2:4] == (0.0, 0.0))
    R, t = sample_poses(g, 300, rng=5)
    a = observe_legs(cam, g, R, t)
    b = observe_legs_numpy(cam, g, R, t)
    assert np.array_equal(a.edge_visible, b.edge_visible)
    np.testing.assert_array_equal(a.visible_fraction, b.visible_fraction)
    np.testing.assert_allclose(a.segments, b.segments, rtol=0, atol=1e-9)
    undistorted = observe_legs_numpy(cam.replace(distortion=None), g, R, t)
    shift = np.nanmax(np.abs(undistorted.segments - b.segments))
    assert shift > 5.0, "the lens moves the edges by pixels (an ignored lens would show)"
