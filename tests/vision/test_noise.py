"""Noise models: distributions checked statistically (KS tests), seeding, batching."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats
from scipy.spatial.transform import Rotation

from vision.noise import (
    add_outliers,
    drop_edges,
    pixel_noise,
    random_rotations,
    random_unit_vectors,
    rotation_noise,
)


def _angle_axis(R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    rv = Rotation.from_matrix(R.reshape(-1, 3, 3)).as_rotvec()
    ang = np.linalg.norm(rv, axis=1)
    return ang, rv / ang[:, None]


def test_random_rotations_distribution() -> None:
    a = np.deg2rad(5.0)
    R = random_rotations((40, 50), a, np.random.default_rng(3))
    assert R.shape == (40, 50, 3, 3)
    assert np.allclose(R @ np.swapaxes(R, -1, -2), np.eye(3), atol=1e-12)
    assert np.allclose(np.linalg.det(R), 1.0)
    ang, axis = _angle_axis(R)
    # Angle uniform in [0, a].
    assert ang.max() <= a + 1e-12
    assert stats.kstest(ang, stats.uniform(0, a).cdf).pvalue > 1e-3
    # Axis uniform on the sphere: each coordinate uniform in [-1, 1] (Archimedes),
    # azimuth uniform in [-pi, pi].
    for k in range(3):
        assert stats.kstest(axis[:, k], stats.uniform(-1, 2).cdf).pvalue > 1e-3
    az = np.arctan2(axis[:, 1], axis[:, 0])
    assert stats.kstest(az, stats.uniform(-np.pi, 2 * np.pi).cdf).pvalue > 1e-3
    # A distribution that is not the right one is rejected (the test has power).
    assert stats.kstest(ang, stats.uniform(0, 0.9 * a).cdf).pvalue < 1e-3


def test_rotation_noise_matches_independent_construction() -> None:
    """Deviation angle of a perturbed vector, against rotations built by SciPy from
    independently drawn axes and angles (two-sample KS)."""
    a = np.deg2rad(0.05)
    rng = np.random.default_rng(5)
    v = random_unit_vectors(5000, rng)
    w = rotation_noise(v, a, rng)
    assert np.allclose(np.linalg.norm(w, axis=-1), 1.0, atol=1e-12)
    dev = np.arctan2(np.linalg.norm(np.cross(v, w), axis=-1), np.sum(v * w, -1))
    assert dev.max() <= a * (1 + 1e-9)

    rng2 = np.random.default_rng(77)
    axis = rng2.normal(size=(5000, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    ang = rng2.uniform(0, a, 5000)
    w2 = Rotation.from_rotvec(axis * ang[:, None]).apply(v)
    dev2 = np.arctan2(np.linalg.norm(np.cross(v, w2), axis=-1), np.sum(v * w2, -1))
    assert stats.ks_2samp(dev, dev2).pvalue > 1e-3
    # The mean deviation is below a / 2 (axes close to the vector move it little).
    assert dev.mean() < 0.5 * a


def test_rotation_noise_shapes_seeds_and_mask() -> None:
    n = random_unit_vectors((3, 6, 2), 1)
    a = np.deg2rad(1.0)
    w1 = rotation_noise(n, a, np.random.default_rng(9))
    w2 = rotation_noise(n, a, np.random.default_rng(9))
    assert w1.shape == n.shape and np.array_equal(w1, w2)
    assert not np.array_equal(w1, rotation_noise(n, a, np.random.default_rng(10)))
    assert np.allclose(rotation_noise(n, 0.0, 1), n, atol=1e-15)
    mask = np.zeros((3, 6, 2), bool)
    mask[1] = True
    w = rotation_noise(n, a, 2, mask=mask)
    assert np.array_equal(w[0], n[0]) and not np.allclose(w[1], n[1], atol=1e-9)
    nan = n.copy()
    nan[0, 0, 0] = np.nan
    assert np.all(np.isnan(rotation_noise(nan, a, 3)[0, 0, 0]))
    with pytest.raises(ValueError, match=r"max_angle_rad must be finite and >= 0, got -1\.0"):
        random_rotations(3, -1.0, 1)
    with pytest.raises(ValueError, match=r"vectors: expected shape \(\.\.\., 3\), got \(4, 2\)"):
        rotation_noise(np.ones((4, 2)), a, 1)


def test_pixel_noise_statistics() -> None:
    p = np.zeros((200, 6, 2, 20, 2))
    q = pixel_noise(p, 0.5, np.random.default_rng(0))
    d = (q - p).reshape(-1, 2)
    assert q.shape == p.shape
    assert abs(d.mean()) < 0.01
    assert d.std() == pytest.approx(0.5, rel=0.01)
    # Gaussian, independent coordinates.
    assert stats.kstest(d[:5000, 0], stats.norm(0, 0.5).cdf).pvalue > 1e-3
    assert abs(np.corrcoef(d[:, 0], d[:, 1])[0, 1]) < 0.01
    assert np.array_equal(pixel_noise(p, 0.5, 4), pixel_noise(p, 0.5, 4))
    assert np.array_equal(pixel_noise(p, 0.0, 4), p)
    with pytest.raises(ValueError, match=r"sigma_px must be finite and >= 0, got -1\.0"):
        pixel_noise(p, -1.0, 0)


def test_outliers() -> None:
    rng = np.random.default_rng(1)
    p = rng.uniform(0, 600, size=(100, 12, 20, 2))
    q, out = add_outliers(p, 0.1, np.random.default_rng(2), width=640, height=480)
    assert out.shape == p.shape[:-1]
    assert out.mean() == pytest.approx(0.1, abs=0.01)
    assert np.array_equal(q[~out], p[~out])
    qo = q[out]
    assert np.all(qo >= -0.5) and np.all(qo[:, 0] <= 639.5) and np.all(qo[:, 1] <= 479.5)
    assert stats.kstest(qo[:, 0], stats.uniform(-0.5, 640).cdf).pvalue > 1e-3
    # Local outliers: within spread_px of the true point.
    q2, out2 = add_outliers(p, 0.3, 3, spread_px=15.0)
    dist = np.linalg.norm(q2 - p, axis=-1)
    assert np.all(dist[out2] <= 15.0) and np.all(dist[~out2] == 0)
    assert stats.kstest(dist[out2] / 15.0, lambda x: np.clip(x, 0, 1) ** 2).pvalue > 1e-3
    none, m = add_outliers(p, 0.0, 4)
    assert not m.any() and np.array_equal(none, p)
    with pytest.raises(ValueError, match=r"fraction must be in \[0, 1\], got 1\.5"):
        add_outliers(p, 1.5, 0)


def test_drop_edges() -> None:
    mask = np.random.default_rng(0).random((500, 6, 2)) < 0.8
    kept = drop_edges(mask, 0.25, np.random.default_rng(1))
    assert kept.shape == mask.shape
    assert not np.any(kept & ~mask)  # never adds an edge
    assert kept.sum() / mask.sum() == pytest.approx(0.75, abs=0.02)
    assert np.array_equal(drop_edges(mask, 0.0, 2), mask)
    assert not drop_edges(mask, 1.0, 2).any()
    assert np.array_equal(drop_edges(mask, 0.3, 5), drop_edges(mask, 0.3, 5))
    with pytest.raises(ValueError, match=r"probability must be in \[0, 1\], got -0\.1"):
        drop_edges(mask, -0.1, 0)


def test_rotation_noise_batch_equals_the_row_by_row_noise() -> None:
    """Each row draws from its own generator exactly what rotation_noise draws: the batch
    gives the per-row results to the last bit."""
    from vision.noise import rotation_noise, rotation_noise_batch

    rng = np.random.default_rng(0)
    v = rng.normal(size=(7, 6, 2, 3))
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    a = np.deg2rad(0.3)
    batch = rotation_noise_batch(v, a, [np.random.default_rng([5, k]) for k in range(7)])
    rows = np.array([rotation_noise(v[k], a, np.random.default_rng([5, k])) for k in range(7)])
    assert np.array_equal(batch, rows)
    assert np.abs(batch - v).max() > 1e-4  # the noise is there


@pytest.mark.parametrize("shape", [(9, 6, 2, 3), (5, 6, 3), (4, 3)])
def test_rotation_noise_batch_compiled_draws_are_numpys(shape: tuple[int, ...],
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    """The compiled draws (numpy's own fill functions, every generator in one C call)
    give the Python loop's numbers to the last bit and leave the generators in the same
    states, with a generator repeated (as a goal's frames share one) and a row of one
    vector; the compiled path is really taken."""
    from vision import noise

    assert noise._compiled_draws() is not None  # the test machines compile C kernels
    rng = np.random.default_rng(1)
    v = rng.normal(size=shape)
    v /= np.linalg.norm(v, axis=-1, keepdims=True)

    def generators() -> list[np.random.Generator]:
        gens = [np.random.default_rng([3, k]) for k in range(shape[0] - 1)]
        return [*gens, gens[0]]  # the first generator draws twice, in row order

    compiled_rngs, python_rngs = generators(), generators()
    calls: list[int] = []
    draws = noise._compiled_draws()
    monkeypatch.setattr(noise, "_draws", [lambda *a: calls.append(a[1]) or draws(*a)])
    compiled = noise.rotation_noise_batch(v, 0.01, compiled_rngs)
    assert calls == [shape[0]]
    monkeypatch.setattr(noise, "_draws", [None])
    python = noise.rotation_noise_batch(v, 0.01, python_rngs)
    assert compiled.tobytes() == python.tobytes()
    assert np.abs(compiled - v).max() > 1e-4  # the noise is there
    for a, b in zip(compiled_rngs, python_rngs, strict=True):
        assert a.bit_generator.state == b.bit_generator.state


def test_rotation_noise_batch_of_generators_taken_by_rows() -> None:
    """Generators keeps the bit generators' addresses; its rows taken (in another order,
    one twice) draw what the list of the same generators draws, to the last bit, and a
    batch of non-Generator rows (no addresses) draws generator by generator."""
    from vision.noise import Generators, rotation_noise_batch

    rng = np.random.default_rng(2)
    v = rng.normal(size=(4, 6, 2, 3))
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    rows = np.array([2, 0, 3, 2])
    held = Generators([np.random.default_rng([9, k]) for k in range(4)])
    listed = [np.random.default_rng([9, k]) for k in range(4)]
    assert held.pointers is not None and len(held) == 4
    taken = held.take(rows)
    assert taken.pointers is not None and taken[0] is held[2]
    batch = rotation_noise_batch(v, 0.02, taken)
    plain = rotation_noise_batch(v, 0.02, [listed[k] for k in rows])
    assert batch.tobytes() == plain.tobytes()
    assert np.abs(batch - v).max() > 1e-4
    assert Generators([None, None]).pointers is None
    assert Generators([None, None]).take(np.array([1])).pointers is None


def test_rotation_noise_compiled_arithmetic_is_the_numpy_paths() -> None:
    """The compiled arithmetic after the draws (``hexapod_rotation_noise``) gives the bits
    of the numpy path (:func:`vision.noise.rotate_by_draws`, the path without a compiler)
    on thousands of random vectors: NaN vectors, zero axis draws (the bad-norm branch),
    angles below 1e-6 rad (exp_so3's series) and up to 3 rad."""
    from vision import kernels, noise

    lib = kernels.library()
    assert lib is not None  # the test machines compile C kernels
    fused = noise._rotation_mode(lib)
    assert fused is not None  # this machine's BLAS sums as one of the kernel's modes
    rng = np.random.default_rng(11)
    for a in (np.deg2rad(0.01), np.deg2rad(1.0), 3.0):
        v = rng.normal(size=(300, 6, 2, 3))
        v /= np.linalg.norm(v, axis=-1, keepdims=True)
        v[rng.random((300, 6, 2)) < 0.05] = np.nan
        axes = rng.normal(size=(300, 6, 2, 3))
        axes[rng.random((300, 6, 2)) < 0.01] = 0.0
        fractions = rng.random((300, 6, 2))
        fractions[rng.random((300, 6, 2)) < 0.02] *= 1e-6 / a
        expected = noise.rotate_by_draws(v, axes.copy(), fractions.copy(), a)
        assert (np.isnan(expected).any(axis=-1) == np.isnan(v).any(axis=-1)).all()
        out = np.empty_like(v)
        lib.hexapod_rotation_noise(axes.ctypes.data, fractions.ctypes.data, v.ctypes.data,
                                   fractions.size, a, fused, out.ctypes.data)
        assert np.array_equal(out, expected, equal_nan=True)
    # at 3 rad the other mode differs (the probe's choice matters; at small angles the
    # last bits of b K^2 vanish in the sum with I)
    wrong = np.empty_like(v)
    lib.hexapod_rotation_noise(axes.ctypes.data, fractions.ctypes.data, v.ctypes.data,
                               fractions.size, 3.0, 1 - fused, wrong.ctypes.data)
    assert not np.array_equal(wrong, expected, equal_nan=True)


def test_rotation_noise_batch_takes_the_compiled_arithmetic(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """rotation_noise_batch gives the same bits with the compiled arithmetic (taken: its
    one call seen) and without a compiler (the numpy path)."""
    from vision import kernels, noise

    rng = np.random.default_rng(12)
    v = rng.normal(size=(40, 6, 2, 3))
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    lib = kernels.library()
    assert lib is not None
    calls: list[int] = []

    class Spy:
        def __getattr__(self, name: str) -> object:
            return getattr(lib, name)

        def hexapod_rotation_noise(self, *args: object) -> None:
            calls.append(1)
            lib.hexapod_rotation_noise(*args)

    monkeypatch.setattr(kernels, "_load", lambda: Spy())
    compiled = noise.rotation_noise_batch(v, 0.01, [np.random.default_rng([4, k])
                                                    for k in range(40)])
    assert calls == [1]
    monkeypatch.setattr(kernels, "_load", lambda: None)
    python = noise.rotation_noise_batch(v, 0.01, [np.random.default_rng([4, k])
                                                  for k in range(40)])
    assert compiled.tobytes() == python.tobytes()
    assert np.abs(compiled - v).max() > 1e-5  # the noise is there
