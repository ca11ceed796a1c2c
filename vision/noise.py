"""Image noise models (``docs/math.md`` section 8), all batched and seeded.

- :func:`rotation_noise`: the noise of the seeds on reconstructed unit vectors
  (edge normals or leg directions): each vector is rotated by a random rotation
  whose axis is uniform on the unit sphere and whose angle is uniform in
  ``[0, a]``. (The angle between a vector and its perturbed copy is then at most
  ``a``, and smaller when the axis is close to the vector.)
- :func:`pixel_noise`: isotropic Gaussian noise on pixels of sampled edge points.
- :func:`add_outliers`: a fraction of the points replaced by gross errors.
- :func:`drop_edges`: edges missed by the detector, at random.

Every function takes a :class:`numpy.random.Generator` (or a seed) and works on
arrays with any leading batch shape.
"""

from __future__ import annotations

import ctypes
import logging
import math
import os
import subprocess
from collections.abc import Sequence
from importlib import resources
from pathlib import Path
from typing import Any, overload

import numpy as np

from hexapod.se3 import exp_so3, norms
from vision import kernels

log = logging.getLogger(__name__)

#: The compiled draws of :func:`rotation_noise_batch` (``vision/csrc/noise_draws.c``),
#: once tried: the function, or None (no compiler, no numpy ``libnpyrandom.a``).
_draws: list[Any] = []


def _compiled_draws() -> Any:
    """``hexapod_rotation_draws`` of ``vision/csrc/noise_draws.c`` linked with numpy's
    own ``libnpyrandom.a`` (compiled on first use, cached), or None: the Python loop
    over the generators is used then (the same numbers, about three times slower)."""
    if _draws:
        return _draws[0]
    from hexapod.compiled import CompilationError, build_shared_library

    _draws.append(None)
    if os.environ.get("HEXAPOD_NO_COMPILE", "") not in ("", "0"):
        return None
    archive = Path(np.random.__file__).parent / "lib" / "libnpyrandom.a"
    if not archive.is_file():
        log.info("no %s: the rotation noise draws in Python", archive)
        return None
    code = resources.files("vision").joinpath("csrc", "noise_draws.c").read_text()
    try:
        path = build_shared_library(
            "vision_noise_draws", code,
            ("-O2", "-Wl,--whole-archive", str(archive), "-Wl,--no-whole-archive", "-lm"),
            key=code + np.__version__ + str(archive))
        f = ctypes.CDLL(str(path)).hexapod_rotation_draws
    except (OSError, subprocess.SubprocessError, CompilationError, AttributeError) as exc:
        log.info("the rotation noise draws in Python (no compiled draws: %s)", exc)
        return None
    f.argtypes = [ctypes.c_void_p, ctypes.c_int64, ctypes.c_int64, ctypes.c_void_p,
                  ctypes.c_void_p]
    f.restype = None
    _draws[0] = f
    return f


def _rng(rng: np.random.Generator | int | None) -> np.random.Generator:
    return rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)


def random_unit_vectors(
    shape: tuple[int, ...] | int, rng: np.random.Generator | int | None
) -> np.ndarray:
    """Unit vectors uniform on the sphere, shape ``(*shape, 3)``."""
    shape = (shape,) if isinstance(shape, int) else tuple(shape)
    g = _rng(rng)
    v = g.normal(size=(*shape, 3))
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    # A zero draw has probability zero; guard anyway.
    bad = n[..., 0] < 1e-12
    if np.any(bad):
        v[bad] = [0.0, 0.0, 1.0]
        n[bad] = 1.0
    return v / n


def random_rotations(
    shape: tuple[int, ...] | int,
    max_angle_rad: float | np.ndarray,
    rng: np.random.Generator | int | None,
) -> np.ndarray:
    """Random rotations: axis uniform on the sphere, angle uniform in ``[0, a]``.

    Args:
        shape: Batch shape.
        max_angle_rad: ``a`` [rad], a scalar or broadcastable to ``shape``.
        rng: Generator or seed.

    Returns:
        (*shape, 3, 3) rotation matrices.
    """
    shape = (shape,) if isinstance(shape, int) else tuple(shape)
    g = _rng(rng)
    a = np.asarray(max_angle_rad, dtype=float)
    if np.any(a < 0) or not np.all(np.isfinite(a)):
        raise ValueError(f"max_angle_rad must be finite and >= 0, got {max_angle_rad}")
    axis = random_unit_vectors(shape, g)
    angle = g.uniform(0.0, 1.0, size=shape) * a
    return exp_so3(axis * angle[..., None])


def rotation_noise(
    vectors: np.ndarray,
    max_angle_rad: float | np.ndarray,
    rng: np.random.Generator | int | None,
    mask: np.ndarray | None = None,
) -> np.ndarray:
    """Rotate each vector (..., 3) by its own random rotation (seed noise model).

    Args:
        vectors: (..., 3) unit vectors (normals (..., 6, 2, 3) or directions (..., 6, 3)).
        max_angle_rad: Maximal rotation angle ``a`` [rad] (0.05 deg ~ 1 px at the ends
            of a 300-pixel segment).
        rng: Generator or seed.
        mask: Optional (...) bool, perturb only where True.

    Returns:
        The perturbed vectors (same norms); NaN stays NaN.
    """
    v = np.asarray(vectors, dtype=float)
    if v.shape[-1:] != (3,):
        raise ValueError(f"vectors: expected shape (..., 3), got {v.shape}")
    R = random_rotations(v.shape[:-1], max_angle_rad, rng)
    out = np.einsum("...ij,...j->...i", R, v)
    if mask is not None:
        out = np.where(np.asarray(mask, bool)[..., None], out, v)
    return out


class Generators(Sequence[Any]):
    """Generators of rows, with the addresses of their bit generators taken once.

    :func:`rotation_noise_batch` draws every row's numbers in one C call from the rows'
    bit generators; a caller that draws from the same generators every period (the
    simulator's sensor) keeps them in one of these and passes :meth:`take` of the rows
    it measures, so the addresses are not looked up again each period. It is a sequence
    of the generators (``g[k]``, ``len(g)``) for everything else.

    Args:
        rngs: The generators, one per row (anything when nothing is drawn: the
            addresses are then None and the draws go generator by generator).
        pointers: True: look the addresses up here; else the addresses of ``rngs``
            already known (:meth:`take` passes its rows'), or None.
    """

    def __init__(self, rngs: Sequence[Any], pointers: np.ndarray | bool | None = True
                 ) -> None:
        self.rngs = list(rngs)
        #: (n,) each generator's ``bitgen_t`` address, or None when some row is not a
        #: :class:`numpy.random.Generator` (the draws go generator by generator).
        self.pointers: np.ndarray | None
        if isinstance(pointers, np.ndarray) or pointers is None:
            self.pointers = pointers
        elif all(type(g) is np.random.Generator for g in self.rngs):
            self.pointers = np.array([g.bit_generator.ctypes.bit_generator.value
                                      for g in self.rngs], dtype=np.uintp)
        else:
            self.pointers = None

    def __len__(self) -> int:
        return len(self.rngs)

    @overload
    def __getitem__(self, k: int) -> Any: ...

    @overload
    def __getitem__(self, k: slice) -> list[Any]: ...

    def __getitem__(self, k: int | slice) -> Any:
        return self.rngs[k]

    def take(self, rows: np.ndarray) -> Generators:
        """The generators of ``rows`` (indices into these), their addresses with them."""
        rngs = self.rngs
        return Generators([rngs[k] for k in rows.tolist()],
                          None if self.pointers is None else self.pointers[rows])


def rotation_noise_batch(
    vectors: np.ndarray,
    max_angle_rad: float,
    rngs: Sequence[np.random.Generator] | Generators,
) -> np.ndarray:
    """:func:`rotation_noise` of ``vectors[k]`` with ``rngs[k]``, for every k at once.

    Each row draws exactly what :func:`rotation_noise` draws from its generator (its
    axes, then its angles), so a row's result does not depend on the other rows; the
    arithmetic is then done for all rows together, operation for operation as
    :func:`rotation_noise` does it (the same bits).

    Args:
        vectors: (n, ..., 3) unit vectors.
        max_angle_rad: Maximal rotation angle ``a`` [rad].
        rngs: n generators (a :class:`Generators` keeps their addresses between calls).

    Returns:
        (n, ..., 3) perturbed vectors.
    """
    v = np.asarray(vectors, dtype=float)
    if v.shape[-1:] != (3,) or v.shape[0] != len(rngs):
        raise ValueError(f"vectors: expected shape ({len(rngs)}, ..., 3), got {v.shape}")
    a = float(max_angle_rad)
    if a < 0 or not np.isfinite(a):
        raise ValueError(f"max_angle_rad must be finite and >= 0, got {max_angle_rad}")
    shape = v.shape[1:-1]
    n = len(rngs)
    axes = np.empty((n, *shape, 3))
    fractions = np.empty((n, *shape))
    # The draws of normal(size=...) and uniform(0, 1, size=...): the same numbers (loc 0,
    # scale 1; low 0, range 1) by numpy's own fill functions, every generator in one C
    # call when compiled, else written in place generator by generator (one
    # trial-step's noise, in the hot loop of every study).
    draws = _compiled_draws()
    gens = rngs if isinstance(rngs, Generators) else Generators(rngs)
    if draws is not None and gens.pointers is not None:
        pointers = np.ascontiguousarray(gens.pointers, dtype=np.uintp)
        draws(pointers.ctypes.data, n, math.prod(shape), axes.ctypes.data,
              fractions.ctypes.data)
    else:
        for g, ax, fr in zip(gens.rngs, axes.reshape(n, -1), fractions.reshape(n, -1),
                             strict=True):
            g.standard_normal(out=ax)
            g.random(out=fr)
    lib = kernels.library()
    if lib is not None and (fused := _rotation_mode(lib)) is not None:  # same bits, in C
        v = np.ascontiguousarray(v)
        out = np.empty_like(v)
        lib.hexapod_rotation_noise(axes.ctypes.data, fractions.ctypes.data, v.ctypes.data,
                                   fractions.size, a, fused, out.ctypes.data)
        return out
    return rotate_by_draws(v, axes, fractions, a)


def rotate_by_draws(v: np.ndarray, axes: np.ndarray, fractions: np.ndarray, a: float
                    ) -> np.ndarray:
    """The arithmetic of :func:`rotation_noise_batch` after its draws, in numpy (the
    compiled ``hexapod_rotation_noise`` gives its bits; without a compiler it runs):
    vectors ``v`` (..., 3) rotated by ``exp_so3(unit(axes) * fractions * a)``.

    Args:
        v: (..., 3) vectors.
        axes: (..., 3) standard normal draws (overwritten).
        fractions: (...) uniform draws in [0, 1) (overwritten).
        a: Maximal rotation angle [rad].
    """
    norm = norms(axes, keepdims=True)
    bad = norm[..., 0] < 1e-12
    if bad.any():
        axes[bad] = [0.0, 0.0, 1.0]
        norm[bad] = 1.0
    # (axes / norm) * (fractions * a), in place: random_unit_vectors, then the angles
    axes /= norm
    fractions *= a
    axes *= fractions[..., None]
    R = exp_so3(axes)
    return np.einsum("...ij,...j->...i", R, v)


def _rotation_mode(lib: Any) -> int | None:
    """:func:`vision.kernels.blas_mode` of ``hexapod_rotation_noise``, probed on
    vectors with NaN, a zero draw of the axis (the bad-norm branch), angles of 0 and
    below 1e-6 rad (the series of exp_so3) and up to 3 rad."""
    def draws() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        rng = np.random.default_rng(7)
        v, axes = rng.normal(size=(2, 64, 3))
        v[3, 1] = np.nan
        axes[5] = 0.0
        fractions = rng.random(64)
        fractions[:8] = [0.0, 1e-9, 3e-7, 1e-6, 0.9e-6, 1.0, 0.5, 0.99]
        return v, axes, fractions

    def compiled(fused: int) -> np.ndarray:
        v, axes, fractions = draws()
        out = np.empty_like(v)
        lib.hexapod_rotation_noise(axes.ctypes.data, fractions.ctypes.data, v.ctypes.data,
                                   64, 3.0, fused, out.ctypes.data)
        return out

    return kernels.blas_mode("hexapod_rotation_noise", compiled,
                             lambda: rotate_by_draws(*draws(), 3.0))


def pixel_noise(
    pixels: np.ndarray, sigma_px: float, rng: np.random.Generator | int | None
) -> np.ndarray:
    """Add isotropic Gaussian noise of standard deviation ``sigma_px`` to pixels (..., 2)."""
    p = np.asarray(pixels, dtype=float)
    if sigma_px < 0 or not np.isfinite(sigma_px):
        raise ValueError(f"sigma_px must be finite and >= 0, got {sigma_px}")
    return p + _rng(rng).normal(scale=sigma_px, size=p.shape)


def add_outliers(
    pixels: np.ndarray,
    fraction: float,
    rng: np.random.Generator | int | None,
    width: int | None = None,
    height: int | None = None,
    spread_px: float = 20.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Replace a random fraction of points (..., 2) by gross errors.

    Each point is an outlier independently with probability ``fraction``. An
    outlier is drawn uniformly in the image ``[-0.5, width - 0.5] x [-0.5,
    height - 0.5]`` when ``width`` and ``height`` are given, else displaced from its
    true position by a vector uniform in the disc of radius ``spread_px``.

    Returns:
        The new pixels and the (...) bool mask of the outliers.
    """
    if not 0.0 <= fraction <= 1.0:
        raise ValueError(f"fraction must be in [0, 1], got {fraction}")
    g = _rng(rng)
    p = np.asarray(pixels, dtype=float)
    shape = p.shape[:-1]
    is_out = g.random(size=shape) < fraction
    if width is not None and height is not None:
        repl = np.stack(
            [g.uniform(-0.5, width - 0.5, size=shape), g.uniform(-0.5, height - 0.5, size=shape)],
            axis=-1,
        )
    else:
        ang = g.uniform(0.0, 2 * np.pi, size=shape)
        rad = spread_px * np.sqrt(g.uniform(0.0, 1.0, size=shape))
        repl = p + np.stack([rad * np.cos(ang), rad * np.sin(ang)], axis=-1)
    return np.where(is_out[..., None], repl, p), is_out


def drop_edges(
    mask: np.ndarray, probability: float, rng: np.random.Generator | int | None
) -> np.ndarray:
    """Drop each observed edge independently with ``probability``: ``mask & keep``."""
    if not 0.0 <= probability <= 1.0:
        raise ValueError(f"probability must be in [0, 1], got {probability}")
    m = np.asarray(mask, dtype=bool)
    return m & (_rng(rng).random(size=m.shape) >= probability)
