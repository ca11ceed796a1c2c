"""The layout of a kernel's packed input or output row: ordered named blocks, each with a
shape (:class:`Layout`). A kernel's expression reads its input by name and its callers
read and write rows by name (:mod:`hexapod.compiled`)."""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np

from hexapod.exceptions import LayoutError

#: A block's shape: a number of values, or the shape of its view (row-major).
Shape = int | tuple[int, ...]


class Layout:
    """Ordered named blocks of a packed row, each with a shape.

    Declared where a kernel is built, it says where each quantity lies in the kernel's
    input or output row: the kernel's expression reads its input by name
    (:meth:`split`) and the callers write and read rows through views by name
    (:meth:`views`, :meth:`index`), so no caller reads ``row[42:60]`` by hand and a
    kernel change cannot silently misalign an offset (:class:`CompiledFunction` checks
    the sizes).

    Args:
        blocks: ``(name, shape)`` in row order; a shape is a number of values or a tuple
            (the shape of the block's view, row-major; ``()`` or 1 is one number).
        name: What the row is (for error messages).
    """

    def __init__(self, blocks: Sequence[tuple[str, Shape]], name: str = "row") -> None:
        self.name = name
        #: Each block's slice of the row.
        self.slices: dict[str, slice] = {}
        #: Each block's shape (its view's).
        self.shapes: dict[str, tuple[int, ...]] = {}
        k = 0
        for block, shape in blocks:
            if block in self.slices:
                raise LayoutError(name, f"block {block!r} named twice")
            dims = (shape,) if isinstance(shape, int) else tuple(shape)
            size = int(np.prod(dims, dtype=int))
            if size < 0 or any(d < 0 for d in dims):
                raise LayoutError(name, f"block {block!r}: negative shape {shape}")
            self.slices[block] = slice(k, k + size)
            self.shapes[block] = dims
            k += size
        #: Number of values in a row.
        self.size = k

    def __repr__(self) -> str:
        blocks = ", ".join(f"{b}{list(s) if len(s) != 1 else s[0]}" for b, s in self.shapes.items())
        return f"Layout({self.name}: {blocks}; {self.size})"

    def __contains__(self, block: object) -> bool:
        return block in self.slices

    def __iter__(self) -> Iterator[str]:
        return iter(self.slices)

    def __getitem__(self, block: str) -> slice:
        """The slice of ``block``."""
        try:
            return self.slices[block]
        except KeyError:
            raise LayoutError(self.name, f"no block {block!r} (blocks: "
                              f"{', '.join(self.slices)})") from None

    def index(self, block: str) -> int:
        """The position of a one-number block."""
        s = self[block]
        if s.stop - s.start != 1:
            raise LayoutError(self.name, f"block {block!r} holds {s.stop - s.start} numbers, "
                              "not one")
        return s.start

    def extended(self, blocks: Sequence[tuple[str, Shape]], name: str | None = None) -> Layout:
        """This layout with ``blocks`` appended."""
        return Layout([*((b, self.shapes[b]) for b in self.slices), *blocks],
                      self.name if name is None else name)

    def _check_row(self, row: np.ndarray) -> None:
        """Refuse rows (..., n) that are not this layout's: ``n`` not :attr:`size`, or the
        last axis not contiguous (a block's slice would then be a copy, not a view)."""
        if row.shape[-1] != self.size or row.strides[-1] != row.itemsize:
            raise LayoutError(self.name, f"a row of {row.shape[-1]} numbers (stride "
                              f"{row.strides[-1]} bytes): the layout has {self.size}, "
                              "contiguous")

    def view(self, row: np.ndarray, block: str) -> np.ndarray:
        """The view of ``block`` in ``row`` (..., :attr:`size`), shaped as declared (a
        one-number block of shape 1 is a (1,) view; of shape ``()`` a 0-d view)."""
        self._check_row(row)
        # the last axis is contiguous: splitting a block of it is a view, never a copy
        return row[..., self[block]].reshape((*row.shape[:-1], *self.shapes[block]))

    def views(self, row: np.ndarray) -> dict[str, np.ndarray]:
        """Every block's :meth:`view` of ``row`` (write into them to fill the row; the row
        checked once: every trial's reset makes its kernel's views)."""
        self._check_row(row)
        lead, shapes = row.shape[:-1], self.shapes
        return {block: row[..., s].reshape((*lead, *shapes[block]))
                for block, s in self.slices.items()}

    def split(self, v: Any) -> dict[str, Any]:
        """The pieces of a symbolic (or numeric) vector ``v`` (:attr:`size`, 1) by block
        (flat columns)."""
        if v.shape[0] != self.size:
            raise LayoutError(self.name, f"a vector of {v.shape[0]} numbers, the layout "
                              f"has {self.size}")
        return {block: v[s] for block, s in self.slices.items()}

    def check(self, size: int, function: str, which: str) -> None:
        """Raise :class:`LayoutError` unless the layout has ``size`` numbers."""
        if size != self.size:
            raise LayoutError(function, f"{which} layout {self!r} has {self.size} numbers, "
                              f"the function's {which} has {size}")


def read_pose(block: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Copies of the pose ``(R, t)`` (3, 3), (3,) [m] in a kernel's pose block (12,): ``R``
    column-major, then ``t``."""
    return block[0:9].reshape(3, 3).T.copy(), block[9:12].copy()


def write_pose(block: np.ndarray, rotation: np.ndarray, translation: np.ndarray) -> None:
    """Write the pose ``(R, t)`` [m] into a kernel's pose block (12,) (:func:`read_pose`'s
    order)."""
    block[0:9] = np.asarray(rotation).T.ravel()
    block[9:12] = translation
