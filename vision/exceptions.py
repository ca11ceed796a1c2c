"""Exceptions of the :mod:`vision` package.

They derive from :class:`hexapod.HexapodError` (and :class:`ValueError`) so a
caller can catch every error of the project with one clause, and carry the
evidence that explains them (field, problem, source file).
"""

from __future__ import annotations

from hexapod.exceptions import HexapodError


class VisionError(HexapodError):
    """Base class of every error raised by :mod:`vision`."""


class CameraError(VisionError, ValueError):
    """A camera is invalid (bad intrinsics, size, mirror parameter or pose).

    Attributes:
        field: Name of the offending field (``"K"``, ``"width"``, ``"xi"``...).
        problem: What is wrong with it.
        source: File the camera was read from, if any.
    """

    def __init__(self, field: str, problem: str, source: str | None = None) -> None:
        self.field = field
        self.problem = problem
        self.source = source
        where = f"{source}: " if source else ""
        super().__init__(f"{where}{field}: {problem}")


class EstimationError(VisionError, ValueError):
    """An estimation cannot run on its input (wrong shapes, too few points)."""
