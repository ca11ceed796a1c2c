"""Exact-coverage polygon filling (the renderer's core, compiled C of
``vision/csrc/render_kernels.c`` in :mod:`vision.kernels`' library)."""

from __future__ import annotations

import numpy as np

from hexapod.compiled import CompilationError
from vision import kernels


class PolygonFiller:
    """Exact-coverage filling of polygons into (H, W) images (the renderer's core).

    A shape is one or more polygons (V, 2) in pixel coordinates (integers at pixel
    centres) filled together (nonzero rule, each polygon oriented to positive area);
    shapes are drawn in order, each blended by its coverage:
    ``v <- round(v + (level - v) * coverage)``. The coverage of one polygon is exact;
    where two polygons of one shape overlap, it is exact on pixels that one of them
    covers fully, and the sum of their coverages (capped at 1) on pixels that both
    cover only partially (in the renderer: a few pixels at the ends of each leg, where
    an end disc meets the leg's outline).

    Args:
        width: Image width [px].
        height: Image height [px].

    Raises:
        CompilationError: The kernels are not compiled (see :func:`available`).
    """

    def __init__(self, width: int, height: int) -> None:
        lib = kernels.library()
        if lib is None:
            raise CompilationError("the vision kernels are not compiled")
        self._lib = lib
        self.width, self.height = int(width), int(height)
        self._acc = np.zeros((self.height, self.width + 2))
        self._lo = np.empty(self.height, np.int64)
        self._hi = np.empty(self.height, np.int64)
        self._rx = np.empty((self.height, 16), np.int64)
        self._rn = np.empty(self.height, np.int64)
        self._work = tuple(a.ctypes.data for a in (self._acc, self._lo, self._hi, self._rx,
                                                   self._rn))

    def _call(self, img: int | None, cov: int | None,
              shapes: list[tuple[list[np.ndarray], float]]) -> None:
        polys = [np.asarray(c, float).reshape(-1, 2) for sh, _ in shapes for c in sh]
        sizes = [sum(1 for c in sh if len(c) >= 3) for sh, _ in shapes]
        polys = [c for c in polys if len(c) >= 3]
        if not polys:
            return
        xy = np.ascontiguousarray(np.concatenate(polys, axis=0), dtype=np.float64)
        counts = np.array([len(c) for c in polys], np.int64)
        per_shape = np.array(sizes, np.int64)
        levels = np.array([lv for _, lv in shapes], np.float64)
        if self._lib.fill_shapes(img, cov, self.width, self.height, xy.ctypes.data,
                                 counts.ctypes.data, per_shape.ctypes.data,
                                 levels.ctypes.data, len(shapes), *self._work):
            raise ValueError("fill_shapes: a vertex is not finite (nothing drawn)")

    def draw(self, image: np.ndarray, shapes: list[tuple[list[np.ndarray], float]]) -> None:
        """Draw shapes in order into ``image`` (in place), in one call.

        Args:
            image: (H, W) C-contiguous uint8 image.
            shapes: ``(polygons, level)`` pairs: polygons (V, 2) [px] filled as one
                shape (fewer than 3 vertices: skipped) at a grey level [0-255].

        Raises:
            ValueError: Wrong image, or a non-finite vertex (nothing is drawn).
        """
        if (image.shape != (self.height, self.width) or image.dtype != np.uint8
                or not image.flags.c_contiguous):
            raise ValueError(f"expected a C-contiguous uint8 image of shape "
                             f"{(self.height, self.width)}, got {image.dtype} {image.shape}")
        self._call(image.ctypes.data, None, shapes)

    def fill(self, image: np.ndarray, contours: list[np.ndarray], level: float) -> None:
        """Blend one shape into ``image`` (see :meth:`draw`)."""
        self.draw(image, [(contours, level)])

    def coverage(self, contours: list[np.ndarray]) -> np.ndarray:
        """(H, W) float coverage of one shape in [0, 1] (exact pixel-square areas)."""
        cov = np.zeros((self.height, self.width))
        self._call(None, cov.ctypes.data, [(contours, 1.0)])
        return cov


__all__ = ["PolygonFiller"]
