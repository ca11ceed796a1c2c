"""Compiled cores of the image pipeline (``vision/csrc/*.c``).

- Detectors (``detect_kernels.c``): the circle scan of
  :class:`vision.detect.OmniDetector`, the search pass and the alignment of
  :class:`vision.detect.PerspectiveTracker` and the robust plane fit shared by both
  detectors are written once in numpy (the reference, in :mod:`vision.detect`) and
  once in C, with the same decisions and the same arithmetic (``-ffp-contract=off``:
  no fused multiply-add), which the tests check frame by frame; only the 3x3
  eigen-solve differs (Jacobi instead of LAPACK, equal to about 1e-15). The
  tracker's search takes one direction per sample (the normal of a curved
  prediction through a distorted lens) and gate coordinates of its own (the ideal
  image); the lift through the distortion stays in numpy (its lens evaluations
  through :func:`lens_parts`), shared by both paths
  (:func:`vision.detect.curves.lift_near`).
- Lens maps (``lens_kernels.c``): the map and Jacobian of OpenCV's 14- and
  5-coefficient distortions, the Kannala-Brandt fisheye, the double sphere and the
  extended unified model (:func:`lens_parts`), the arithmetic of their numpy
  ``parts_numpy`` operation by operation (the tests check them equal); the tracker
  evaluates the lens four times per pass through a distorted lens.
- The simulated camera (``sensor_kernels.c``): the rotation noise's arithmetic after its
  draws (:func:`vision.noise.rotation_noise_batch`), the image lines and the estimated
  camera's normals (:func:`vision.cameras.perspective.lines_and_normals`) and the leg
  directions from the edges (:func:`vision.legs.directions_from_edges`), each the bits
  of its numpy path; numpy's matmul sums through its BLAS, which fuses the products or
  not by processor: the kernels take which (:func:`blas_mode`, probed once).
- Renderer (``render_kernels.c``): exact-coverage polygon filling
  (:class:`vision.polygon_fill.PolygonFiller`): a pixel's value is blended by the exact area of its
  unit square inside the shape, so that a rendered edge has no bias whatever its
  direction and sub-pixel position. The tests check the coverage against an
  independent polygon clipping.

The sources ship with the package; they are compiled on first use by the system C
compiler through :func:`hexapod.compiled.build_shared_library` (cached under the
hash of the source) and called through :mod:`ctypes`. Without a compiler, or with
``HEXAPOD_NO_COMPILE=1`` in the environment, the detectors and the simulated camera
run their numpy path (same results, a few times slower), the renderer falls back to OpenCV's
anti-aliased polygons (edges biased by up to about 0.1 px, see
:class:`vision.render.RenderStyle`), and a warning is logged once.
"""

from __future__ import annotations

import ctypes
import logging
import os
import subprocess
from collections.abc import Callable
from importlib import resources
from typing import Any

import numpy as np

from hexapod.compiled import CompilationError, build_shared_library

log = logging.getLogger(__name__)

#: Compiler flags: optimised, and no fused multiply-add (the numpy path rounds each
#: product; a contracted a*b+c would differ in the last bit). ``-O3`` keeps every IEEE
#: operation (no ``-ffast-math``) and observes the legs about 20 % faster than ``-O2``
#: (the same bits).
FLAGS = ("-O3", "-ffp-contract=off", "-fno-math-errno")

_P: Any = ctypes.c_void_p
_I: Any = ctypes.c_int64
_D: Any = ctypes.c_double

#: The C sources, in the order they are concatenated into one library.
SOURCES = ("detect_kernels.c", "render_kernels.c", "observe_kernels.c", "lens_kernels.c",
           "sensor_kernels.c")

_lib: ctypes.CDLL | None = None
_tried = False


def _load() -> ctypes.CDLL | None:
    global _lib, _tried
    if _tried:
        return _lib
    _tried = True
    if os.environ.get("HEXAPOD_NO_COMPILE", "") not in ("", "0"):
        log.info("HEXAPOD_NO_COMPILE is set: the detectors use their numpy path")
        return None
    src = resources.files("vision").joinpath("csrc")
    code = "\n".join(src.joinpath(name).read_text() for name in SOURCES)
    try:
        lib = ctypes.CDLL(str(build_shared_library("vision_kernels", code, FLAGS)))
    except (OSError, subprocess.SubprocessError, CompilationError) as exc:
        detail = getattr(exc, "stderr", b"") or b""
        log.warning("vision kernels: C compilation unavailable (%s %s); the detectors use "
                    "numpy, the renderer OpenCV's anti-aliased polygons", exc,
                    detail.decode(errors="replace")[:500])
        return None
    lib.omni_scan.argtypes = [_P] * 5 + [_I] * 3 + [_P] * 4 + [_D, _D, _P]
    lib.omni_scan.restype = ctypes.c_int
    lib.fit_planes.argtypes = [_P] * 4 + [_I, _I, _D, _I, _D, _I] + [_P] * 5
    lib.fit_planes.restype = None
    lib.omni_detect.argtypes = ([_P] * 5 + [_I] * 3 + [_P] * 4 + [_D, _D] + [_P] * 3
                                + [_D, _D, _P, _D, _I, _D, _I] + [_P] * 10)
    lib.omni_detect.restype = ctypes.c_int
    lib.track_points.argtypes = ([_P, _I, _I, _P, _P, _P, _I, _I] + [_P] * 5
                                 + [_D, _D] + [_P] * 5)
    lib.track_points.restype = None
    lib.track_pass.argtypes = ([_P, _I, _I, _P, _P, _P, _I, _I] + [_P] * 5
                               + [_D, _D, _P, _D, _D, _D, _P, _I, _D, _I] + [_P] * 12)
    lib.track_pass.restype = ctypes.c_int
    lib.align_shift.argtypes = [_P, _I, _I] + [_P] * 6 + [_I, _I, _D] + [_P] * 4
    lib.align_shift.restype = None
    lib.fill_shapes.argtypes = [_P, _P, _I, _I, _P, _P, _P, _P, _I, _P, _P, _P, _P, _P]
    lib.fill_shapes.restype = ctypes.c_int
    lib.hexapod_observe_batch.argtypes = [_P, _P, _I, _D, _D, _I, _I, _D, _I]
    lib.hexapod_observe_batch.restype = ctypes.c_int
    lib.hexapod_segments_imaged.argtypes = [_P, _I, _P, _I, _D, _D, _P]
    lib.hexapod_segments_imaged.restype = None
    lib.lens_parts.argtypes = [_I, _P, _P, _I, _P, _P, _I, _P]
    lib.lens_parts.restype = None
    lib.hexapod_rotation_noise.argtypes = [_P, _P, _P, _I, _D, _I, _P]
    lib.hexapod_rotation_noise.restype = None
    lib.hexapod_lines_normals.argtypes = [_P, _I, _I, _P, _P, _I, _P, _P]
    lib.hexapod_lines_normals.restype = None
    lib.hexapod_directions_from_edges.argtypes = [_P, _I, _P]
    lib.hexapod_directions_from_edges.restype = None
    _lib = lib
    return lib


#: :func:`blas_mode` of each kernel, once probed.
_modes: dict[str, int | None] = {}


def blas_mode(name: str, compiled: Callable[[int], np.ndarray],
              numpy_path: Callable[[], np.ndarray]) -> int | None:
    """The ``fused`` argument with which the compiled arithmetic ``name``
    (``sensor_kernels.c``) gives the bits of its numpy path on this machine: numpy's
    matmul sums through its BLAS, whose kernels fuse the products (1: on processors with
    FMA) or round each (0). Probed once: ``compiled(fused)`` against ``numpy_path()`` on
    the same inputs; None (the numpy path is used, a warning logged) when neither gives
    its bits."""
    if name not in _modes:
        reference = numpy_path()
        _modes[name] = next((f for f in (1, 0)
                             if np.array_equal(compiled(f), reference, equal_nan=True)), None)
        if _modes[name] is None:
            log.warning("%s: the compiled arithmetic does not reproduce numpy's here (its "
                        "BLAS sums otherwise); the numpy path is used", name)
    return _modes[name]


def available() -> bool:
    """Whether the compiled cores are loaded (compiles them on the first call)."""
    return _load() is not None


def library() -> ctypes.CDLL | None:
    """The compiled cores' library, its functions typed (compiled on the first call), or
    None without a compiler or with ``HEXAPOD_NO_COMPILE=1`` (the callers then run their
    numpy path)."""
    return _load()


def _c(a: np.ndarray, dtype: type) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=dtype)


class _FitOutputs:
    """Preallocated outputs of one compiled detection (fit_planes and the points)."""

    def __init__(self, n_points: int) -> None:
        self.normals = np.empty((6, 2, 3))
        self.visible = np.empty((6, 2), np.uint8)
        self.count = np.empty((6, 2), np.int64)
        self.rms = np.empty((6, 2))
        self.inliers = np.empty((6, 2, n_points), np.uint8)
        self.points = np.empty((6, 2, n_points, 2))
        self.pointers = tuple(a.ctypes.data for a in (
            self.normals, self.visible, self.count, self.rms, self.inliers, self.points))

    def result(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Fresh copies: normals, visible (bool), count, rms, points."""
        return (self.normals.copy(), self.visible.astype(bool), self.count.copy(),
                self.rms.copy(), self.points.copy())


class OmniKernel:
    """The compiled omnidirectional detection for one circle layout.

    The constant arrays are converted once and their addresses cached; the
    association references are converted once per prediction (the detector caches
    them per prediction object), so a frame costs one C call.

    Args:
        idx: (C, N) nearest-pixel flat indices of the samples.
        base: (C, N) flat index of the top-left pixel of each bilinear sample.
        fx: (C, N) horizontal bilinear weights.
        fy: (C, N) vertical bilinear weights.
        width: Image width [px].
        radii: (C,) circle radii [px].
        z: (C,) elevation (z of the unit ray) of each circle (isotropic camera).
        px_per_rad: (C,) pixels per radian across each circle.
        centre: (cx, cy) principal point [px].
    """

    def __init__(self, idx: np.ndarray, base: np.ndarray, fx: np.ndarray, fy: np.ndarray,
                 width: int, radii: np.ndarray, z: np.ndarray, px_per_rad: np.ndarray,
                 centre: tuple[float, float]) -> None:
        lib = _load()
        if lib is None:
            raise CompilationError("the detector kernels are not compiled")
        self._lib = lib
        self._keep = [_c(idx, np.int64), _c(base, np.int64), _c(fx, np.float64),
                      _c(fy, np.float64), _c(radii, np.float64), _c(z, np.float64),
                      _c(px_per_rad, np.float64)]
        C, N = self._keep[0].shape
        self.C = int(C)
        ptr = [a.ctypes.data for a in self._keep]
        self._layout = (*ptr[:4], int(width), int(C), int(N))
        self._circles = (*ptr[4:], float(centre[0]), float(centre[1]))
        self._pts_a = np.empty((6, 2, C))
        self._rays = np.empty((6, 2, C, 3))
        self._valid = np.empty((6, 2, C), np.uint8)
        self._ppr = np.empty((6, 2, C))
        self._pred = np.empty((6, 2, 3))
        self._out = _FitOutputs(int(C))
        self._buffers = (*(a.ctypes.data for a in (self._pts_a, self._rays, self._valid,
                                                   self._ppr)), *self._out.pointers)
        self._pred_ptr = self._pred.ctypes.data
        self._ref_key: tuple[np.ndarray, ...] | None = None
        self._ref_arrays: list[np.ndarray] = []
        self._ref_ptrs: tuple[int, ...] = ()

    def _refs(self, refs: tuple[np.ndarray, ...]) -> tuple[int, ...]:
        if refs is not self._ref_key:
            self._ref_arrays = [_c(refs[0], np.float64), _c(refs[1], np.float64),
                                _c(refs[2], np.float64), _c(refs[3], np.uint8)]
            self._ref_ptrs = tuple(a.ctypes.data for a in self._ref_arrays)
            self._ref_key = refs
        return self._ref_ptrs

    def scan(self, image: np.ndarray, refs: tuple[np.ndarray, ...], min_contrast: float,
             width_tolerance: float) -> np.ndarray:
        """Azimuths (6, 2, C) of the edge points [rad], NaN where none (a fresh array):
        the compiled :meth:`vision.detect.OmniDetector._scan`.

        Args:
            image: (H, W) uint8 image of the layout's size (checked by the caller).
            refs: ``(axis, gate, width, e1_first)``, each (6, C), as returned by
                :meth:`vision.detect.OmniDetector._reference`.
            min_contrast: Minimal grey-level range of a circle.
            width_tolerance: Band width tolerance factor.
        """
        img = _c(image, np.uint8)
        if self._lib.omni_scan(img.ctypes.data, *self._layout, *self._refs(refs),
                               float(min_contrast), float(width_tolerance),
                               self._pts_a.ctypes.data):
            raise MemoryError("omni_scan: out of memory")
        return self._pts_a.copy()

    def detect(self, image: np.ndarray, refs: tuple[np.ndarray, ...], predicted: np.ndarray,
               min_contrast: float, width_tolerance: float, outlier_px: float,
               min_points: int, max_rms_px: float, iterations: int,
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """One frame, isotropic camera: scan, rays, robust fit, inlier pixels.

        Returns:
            Fresh arrays ``normals`` (6, 2, 3), ``visible`` (6, 2), ``count`` (6, 2),
            ``rms`` (6, 2) and ``points`` (6, 2, C, 2), as
            :meth:`vision.detect.OmniDetector.detect` with ``use_compiled=False``.
        """
        img = _c(image, np.uint8)
        self._pred[...] = predicted
        if self._lib.omni_detect(img.ctypes.data, *self._layout, *self._refs(refs),
                                 float(min_contrast), float(width_tolerance), *self._circles,
                                 self._pred_ptr, float(outlier_px), int(min_points),
                                 float(max_rms_px), int(iterations), *self._buffers):
            raise MemoryError("omni_detect: out of memory")
        return self._out.result()


class TrackKernel:
    """The compiled search pass of :class:`vision.detect.PerspectiveTracker`.

    Args:
        width: Image width [px].
        height: Image height [px].
        n_samples: Samples per edge.
    """

    def __init__(self, width: int, height: int, n_samples: int) -> None:
        lib = _load()
        if lib is None:
            raise CompilationError("the vision kernels are not compiled")
        self._lib = lib
        self.width, self.height, self.M = int(width), int(height), int(n_samples)
        M = self.M
        self._offset = np.empty((12, M))
        self._valid = np.empty((12, M), np.uint8)
        self._rays = np.empty((12, M, 3))
        self._ppr = np.empty((12, M))
        self._pairs = np.empty(max(M * (M - 1) // 2, M))
        self._prof = np.empty(3)
        self._out = _FitOutputs(M)

    def _check(self, image: np.ndarray, R: int) -> np.ndarray:
        if image.shape != (self.height, self.width) or image.dtype != np.uint8:
            raise ValueError(f"expected a uint8 image of shape {(self.height, self.width)}")
        if self._prof.size < 2 * R + 1:
            self._prof = np.empty(2 * R + 1)
        return _c(image, np.uint8)

    def _gate_arrays(self, P: np.ndarray, out: np.ndarray, search: np.ndarray,
                     t: np.ndarray, gate: np.ndarray | None, seg: np.ndarray,
                     lines: np.ndarray, margin: np.ndarray | float) -> list[np.ndarray]:
        """Contiguous copies of the per-sample inputs (out, gate and margin broadcast to
        every sample)."""
        M = self.M
        Pc = _c(P, np.float64)
        return [Pc, _c(np.broadcast_to(np.asarray(out, float).reshape(6, 2, -1, 2),
                                       (6, 2, M, 2)), np.float64),
                _c(search, np.float64), _c(t, np.float64),
                Pc if gate is None else _c(gate, np.float64), _c(seg, np.float64),
                _c(lines, np.float64),
                _c(np.broadcast_to(np.asarray(margin, float), (6, 2, M)), np.float64)]

    def track(self, image: np.ndarray, P: np.ndarray, out: np.ndarray, search: np.ndarray,
              R: int, t: np.ndarray, seg: np.ndarray, lines: np.ndarray,
              predicted: np.ndarray, margin: float, min_contrast: float, outlier_px: float,
              Kinv: np.ndarray, f: float, centre: tuple[float, float], min_points: int,
              max_rms_px: float, iterations: int,
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """One pass of an ideal lens (arguments as in
        :meth:`vision.detect.PerspectiveTracker._pass`; ``out`` (6, 2, 2) per edge).

        Returns:
            Fresh ``normals`` (6, 2, 3), ``visible`` (6, 2), ``count`` (6, 2), ``rms``
            (6, 2) and ``points`` (6, 2, M, 2).
        """
        img = self._check(image, R)
        arrays = self._gate_arrays(P, out[:, :, None, :], search, t, None, seg, lines, margin)
        arrays += [_c(Kinv, np.float64), _c(predicted, np.float64)]
        Pp, op, sp, tp, gp, segp, lp, mp, kp, prp = (a.ctypes.data for a in arrays)
        self._lib.track_pass(
            img.ctypes.data, self.width, self.height, Pp, op, sp, int(R), self.M, tp, gp, segp,
            lp, mp, float(min_contrast), float(outlier_px), kp, float(f),
            float(centre[0]), float(centre[1]), prp, int(min_points), float(max_rms_px),
            int(iterations), self._offset.ctypes.data, self._valid.ctypes.data,
            self._rays.ctypes.data, self._ppr.ctypes.data, self._prof.ctypes.data,
            self._pairs.ctypes.data, *self._out.pointers)
        return self._out.result()

    def points(self, image: np.ndarray, P: np.ndarray, out: np.ndarray, search: np.ndarray,
               R: int, t: np.ndarray, gate: np.ndarray, seg: np.ndarray, lines: np.ndarray,
               margin: np.ndarray, min_contrast: float, outlier_px: float,
               ) -> tuple[np.ndarray, np.ndarray]:
        """The edge points of one pass before the fit (profiles along the per-sample
        normals ``out`` (6, 2, M, 2), gradient peak, occlusion gate on ``gate``
        (6, 2, M, 2) with ``seg``, ``lines`` and the per-sample ``margin`` (6, 2, M),
        Theil-Sen): the compiled :meth:`vision.detect.PerspectiveTracker._edge_offsets`.

        Returns:
            Fresh ``offset`` (6, 2, M) [px] along ``out`` and ``valid`` (6, 2, M).
        """
        img = self._check(image, R)
        arrays = self._gate_arrays(P, out, search, t, gate, seg, lines, margin)
        Pp, op, sp, tp, gp, segp, lp, mp = (a.ctypes.data for a in arrays)
        self._lib.track_points(
            img.ctypes.data, self.width, self.height, Pp, op, sp, int(R), self.M, tp, gp, segp,
            lp, mp, float(min_contrast), float(outlier_px), self._offset.ctypes.data,
            self._valid.ctypes.data, self._prof.ctypes.data, self._pairs.ctypes.data,
            self._out.points.ctypes.data)
        M = self.M
        return self._offset.reshape(6, 2, M).copy(), self._valid.reshape(6, 2, M).astype(bool)


def align_shift(image: np.ndarray, P: np.ndarray, out: np.ndarray, seg: np.ndarray,
                lines: np.ndarray, margin: np.ndarray | float, R: int, max_shift: float,
                gate: np.ndarray | None = None) -> np.ndarray:
    """The compiled core of :meth:`vision.detect.PerspectiveTracker.align`: the image
    translation (2,) [px] (arguments as there; ``R = ceil(max_shift) + 1``; ``out``
    (6, 2, 2) per edge; ``gate`` (6, 2, M, 2): the samples in the occlusion gate's
    coordinates, default ``P``; ``margin`` scalar or (6, 2, M))."""
    lib = _load()
    if lib is None:
        raise CompilationError("the vision kernels are not compiled")
    img = _c(image, np.uint8)
    H, W = img.shape
    Pc, oc, sc, lc = (_c(a, np.float64) for a in (P, out, seg, lines))
    M = Pc.shape[2]
    gc = Pc if gate is None else _c(gate, np.float64)
    mc = _c(np.broadcast_to(np.asarray(margin, float), (6, 2, M)), np.float64)
    L = 2 * int(R) - 1
    G = np.empty(12 * max(L, 1))
    prof = np.empty(2 * int(R) + 1)
    d = np.empty(max(L, 1))
    shift = np.zeros(2)
    lib.align_shift(img.ctypes.data, W, H, Pc.ctypes.data, oc.ctypes.data, gc.ctypes.data,
                    sc.ctypes.data, lc.ctypes.data, mc.ctypes.data, int(M), int(R),
                    float(max_shift), G.ctypes.data, prof.ctypes.data, d.ctypes.data,
                    shift.ctypes.data)
    return shift


#: The lens maps of :func:`lens_parts`, by kind.
LENS_KINDS = {"opencv-full": 0, "radial-tangential": 1, "kannala-brandt": 2,
              "double-sphere": 3, "extended-unified": 4}


_EYE3 = np.eye(3)
_EYE3.flags.writeable = False


def lens_parts(kind: str, x: np.ndarray, y: np.ndarray, coefficients: np.ndarray,
               tilt: np.ndarray | None = None, tilted: bool = False
               ) -> tuple[np.ndarray, ...] | None:
    """The compiled ``parts_numpy`` of a lens map (:data:`LENS_KINDS`): ``(x_d, y_d,
    j11, j12, j21, j22)`` at ``(x, y)`` (broadcast shape), or None when the kernels are
    not compiled. ``coefficients``: the lens's, in its order; ``tilt`` (3, 3) and
    ``tilted`` (a tilt angle is nonzero): OpenCV's full model only."""
    lib = _load()
    if lib is None:
        return None
    xb, yb = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    if xb.shape != yb.shape:
        xb, yb = np.broadcast_arrays(xb, yb)
    xc, yc = _c(xb, np.float64), _c(yb, np.float64)
    c = _c(coefficients, np.float64)
    T = _EYE3 if tilt is None else _c(tilt, np.float64)
    out = np.empty((6, *xb.shape))
    lib.lens_parts(LENS_KINDS[kind], xc.ctypes.data, yc.ctypes.data, int(xc.size),
                   c.ctypes.data, T.ctypes.data, int(bool(tilted)), out.ctypes.data)
    return tuple(out)


def fit_planes(
    rays: np.ndarray, valid: np.ndarray, px_per_rad: np.ndarray | float,
    predicted: np.ndarray, outlier_px: float, min_points: int, max_rms_px: float,
    iterations: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The compiled :func:`vision.detect.common._robust_fit` (same arguments and results)."""
    lib = _load()
    if lib is None:
        raise CompilationError("the detector kernels are not compiled")
    lead = valid.shape[:-1]
    N = valid.shape[-1]
    E = int(np.prod(lead, dtype=np.int64))
    X = _c(np.broadcast_to(rays, (*valid.shape, 3)), np.float64)
    v = _c(valid, np.uint8)
    ppr = _c(np.broadcast_to(np.asarray(px_per_rad, float), valid.shape), np.float64)
    pred = _c(np.broadcast_to(predicted, (*lead, 3)), np.float64)
    normals = np.empty((*lead, 3))
    visible = np.empty(lead, np.uint8)
    count = np.empty(lead, np.int64)
    rms = np.empty(lead)
    inliers = np.empty(valid.shape, np.uint8)
    lib.fit_planes(X.ctypes.data, v.ctypes.data, ppr.ctypes.data, pred.ctypes.data, E, N,
                   float(outlier_px), int(min_points), float(max_rms_px), int(iterations),
                   normals.ctypes.data, visible.ctypes.data, count.ctypes.data,
                   rms.ctypes.data, inliers.ctypes.data)
    return normals, visible.view(bool), count, rms, inliers.view(bool)


__all__ = ["FLAGS", "LENS_KINDS", "SOURCES", "OmniKernel", "TrackKernel", "align_shift",
           "available", "fit_planes", "lens_parts"]
