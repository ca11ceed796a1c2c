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


@pytest.mark.parametrize("n_samples", [5, 20, 33])
def test_sample_counts_that_are_not_one_chunk_equal_the_numpy_reference(n_samples: int
                                                                        ) -> None:
    """The core tests samples 16 at a time (its table of sample positions padded to whole
    chunks): fewer, more, and a partial last chunk, with occlusions, decide as the numpy
    reference does."""
    g = deltalab()
    cam = front_camera(g)
    R, t = sample_poses(g, 150, rng=4)
    fast = observe_legs(cam, g, R, t, n_samples=n_samples)
    ref = observe_legs_numpy(cam, g, R, t, n_samples=n_samples)
    assert np.array_equal(fast.edge_visible, ref.edge_visible)
    assert np.array_equal(fast.visible_fraction, ref.visible_fraction)
    np.testing.assert_allclose(fast.visible_interval, ref.visible_interval, rtol=0, atol=1e-12)
    assert (ref.visible_fraction % 1 != 0).any()  # some edges partly hidden


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


@pytest.mark.parametrize(("kind", "skew", "crop"), [("front", 0.0, 0.9), ("front", 20.0, 0.9),
                                                   ("omni", 0.0, 0.7), ("omni", 40.0, 0.7)])
def test_edges_across_the_image_border_equal_the_numpy_reference(kind: str, skew: float,
                                                                 crop: float) -> None:
    """A cropped image with an off-centre principal point: many edges leave the image
    part-way (the compiled core skips the per-sample projection only for an edge it
    proves inside; everything else must still be tested sample by sample)."""
    g = deltalab()
    cam = front_camera(g) if kind == "front" else omni_camera(g)
    K = cam.K.copy()
    K[0, 1] = skew
    K[0, 2] *= crop + 0.05
    K[1, 2] *= crop
    cam = cam.replace(K=K, width=int(cam.width * crop), height=int(cam.height * crop))
    R, t = sample_poses(g, 300, rng=11)
    a = observe_legs(cam, g, R, t)
    b = observe_legs_numpy(cam, g, R, t)
    np.testing.assert_array_equal(a.visible_fraction, b.visible_fraction)
    assert np.array_equal(a.edge_visible, b.edge_visible)
    np.testing.assert_allclose(a.visible_interval, b.visible_interval, rtol=0, atol=1e-12)
    partial = (b.visible_fraction > 0) & (b.visible_fraction < 1)
    whole = b.visible_fraction == 1
    assert partial.sum() > 100 and whole.sum() > 100, (partial.sum(), whole.sum())


@pytest.mark.parametrize(("kind", "skew", "zoom"), [
    ("front", 0.0, 1.0), ("front", 25.0, 1.0),
    ("omni", 0.0, 1.0), ("omni", 60.0, 1.0),       # the image shows past the horizon
    ("omni", 0.0, 1.6), ("omni", 60.0, 1.6),       # the horizon leaves the image
])
def test_segments_proved_inside_the_image_are_inside_at_every_point(kind: str, skew: float,
                                                                    zoom: float) -> None:
    """The shortcut of the compiled core (an edge proved wholly inside the image is not
    projected sample by sample), against the camera's own projection of 1001 points of
    each segment. The ends are lifted from pixels anywhere in the image and, for half
    of them, within 6 px of its border (inside or out), where a loose proof would
    show."""
    g = deltalab()
    cam = front_camera(g) if kind == "front" else omni_camera(g)
    K = cam.K.copy()
    K[0, 0] *= zoom
    K[1, 1] *= zoom
    K[0, 1] = skew
    cam = cam.replace(K=K)
    rng = np.random.default_rng(5)
    n = 3000
    w, h = float(cam.width), float(cam.height)
    pix = rng.uniform([-0.5, -0.5], [w - 0.5, h - 0.5], (n, 2, 2))
    near = rng.random(n) < 0.5
    side = rng.integers(0, 4, n)
    along = rng.uniform(0.0, 1.0, n)[:, None] * np.array([w, h])[side // 2 ^ 1, None] \
        + rng.uniform(-30.0, 30.0, (n, 2)) - 0.5
    band = rng.uniform(-6.0, 6.0, (n, 2))
    for k in np.flatnonzero(near):  # short segments across and along one border
        axis = side[k] // 2
        edge = -0.5 if side[k] % 2 == 0 else (w, h)[axis] - 0.5
        pix[k, :, axis] = edge + band[k]
        pix[k, :, 1 - axis] = along[k]
    rays = cam.lift(pix.reshape(-1, 2)).reshape(n, 2, 3)
    ends = rays * rng.uniform(0.2, 2.0, (n, 2, 1))
    ok = np.isfinite(ends).all(axis=(1, 2))
    ends = ends[ok]
    proved = fast_observe.segments_certainly_imaged(cam, ends)
    s = np.linspace(0.0, 1.0, 1001)[:, None, None]
    points = ends[:, 0] + s * (ends[:, 1] - ends[:, 0])        # (1001, n, 3)
    _, vis = cam.project(points)
    whole = vis.all(axis=0)
    assert whole[proved].all(), "a segment proved inside leaves the image"
    # the proof fires, and the check has teeth (segments near the border that leave it)
    assert proved.sum() > 200, int(proved.sum())
    assert (~whole).sum() > 200, int((~whole).sum())


def test_the_c_core_reads_and_writes_the_rows_as_the_layouts_say() -> None:
    """The C core's row sizes and the offsets of its named pointers are the Python
    layouts' (a block moved on one side only fails here, not as wrong observations)."""
    import re
    from pathlib import Path

    src = (Path(fast_observe.__file__).parent / "csrc" / "observe_kernels.c").read_text()
    sizes = dict(re.findall(r"#define (OBS_N_(?:IN|OUT)) (\d+)", src))
    assert int(sizes["OBS_N_IN"]) == fast_observe.INPUTS.size
    assert int(sizes["OBS_N_OUT"]) == fast_observe.OUTPUTS.size
    # where the C points into an item's row: `*name = p + k` or `name = p[k]` (p: the
    # parameters, o: the outputs)
    found = {(row, name): int(k or 0) for name, row, k in re.findall(
        r"\*?(\w+) = ([po])(?: \+ (\d+))?[,;]", src)}
    found.update({("p", name): int(k) for name, k in re.findall(r"(\w+) = p\[(\d+)\]", src)})
    c_names = {  # the C's names of the layouts' blocks
        "p": {"R": "R", "t": "t", "Ab": "base_points", "E": "platform_points",
              "r": "leg_radius", "rho_disc": "platform_radius", "Rc": "camera_rotation",
              "tc": "camera_translation", "cam": "camera"},
        "o": {"normals": "normals", "exists": "exists", "frac": "visible_fraction",
              "vis": "edge_visible", "Ac": "base_points", "uc": "directions",
              "qc": "lengths", "interval": "visible_interval", "centre": "platform_centre",
              "dnormal": "platform_normal"}}
    layouts = {"p": fast_observe.INPUTS, "o": fast_observe.OUTPUTS}
    for row, names in c_names.items():
        assert set(names.values()) == set(layouts[row])  # every block is read or written
        for c_name, block in names.items():
            assert found[(row, c_name)] == layouts[row][block].start, (row, c_name, block)


@pytest.mark.parametrize("observe", [observe_legs, observe_legs_numpy])
def test_a_pose_not_finite_or_not_a_rotation_is_refused_as_the_reference_refuses_it(
        observe: object) -> None:
    """The compiled observation refuses what its numpy reference refuses: a NaN pose
    (it gave NaN normals and no visible edge) and a matrix that is not a rotation (``2 I``
    gave twelve visible edges of no robot)."""
    from hexapod.exceptions import ShapeError
    from vision.legs import observe_edges

    g = deltalab()
    cam = front_camera(g)
    R, t = sample_poses(g, 2, rng=np.random.default_rng(3))
    bad_t = t.copy()
    bad_t[1, 0] = np.nan
    for look in (observe, observe_edges):
        with pytest.raises(ShapeError, match="pose: expected finite values"):
            look(cam, g, R, bad_t)  # type: ignore[operator]
        with pytest.raises(ShapeError, match=r"rotation: expected rotation matrices"):
            look(cam, g, 2 * R, t)  # type: ignore[operator]
