"""Exceptions of the :mod:`vision` package.

They derive from :class:`hexapod.HexapodError` (and :class:`ValueError`) so a
caller can catch every error of the project with one clause, and carry the
evidence that explains them (field, problem, source file).
"""

from __future__ import annotations

from typing import Any

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


class DistortionError(CameraError):
    """Lens distortion coefficients whose mapping folds inside the image.

    The distortion map (normalised undistorted -> distorted coordinates) is then not
    one-to-one over the image: two directions give the same pixel, and pixels near the
    fold cannot be lifted. The evidence is the point of the fold (the curve where the
    Jacobian determinant of the map vanishes) that lies deepest inside the image.

    Attributes:
        coefficients: The coefficients, OpenCV's order ``(k1, k2, p1, p2[, k3])``.
        radius_undistorted: Radius of the fold point before distortion [normalised
            units, ``|(X/Z, Y/Z)|`` for a perspective camera].
        radius_normalised: Its radius after distortion, ``|K^-1 p|`` [normalised units].
        radius_px: Its distance from the principal point [px].
        pixel: Its pixel ``(u, v)``.
    """

    def __init__(self, coefficients: Any, radius_undistorted: float, radius_normalised: float,
                 radius_px: float, pixel: tuple[float, float],
                 source: str | None = None) -> None:
        self.coefficients = tuple(float(c) for c in coefficients)
        self.radius_undistorted = float(radius_undistorted)
        self.radius_normalised = float(radius_normalised)
        self.radius_px = float(radius_px)
        self.pixel = (float(pixel[0]), float(pixel[1]))
        coeffs = ", ".join(f"{c:.6g}" for c in self.coefficients)
        super().__init__(
            "distortion",
            f"coefficients ({coeffs}) fold inside the image: the mapping is not one-to-one "
            f"(its Jacobian determinant vanishes) at normalised radius "
            f"{self.radius_normalised:.6g} (undistorted {self.radius_undistorted:.6g}), "
            f"{self.radius_px:.1f} px from the principal point, at pixel "
            f"({self.pixel[0]:.1f}, {self.pixel[1]:.1f})",
            source,
        )


class DetectionError(VisionError, ValueError):
    """A detector cannot run on its input (wrong image size or type, bad settings).

    Attributes:
        field: The offending input or setting.
        problem: What is wrong with it.
    """

    def __init__(self, field: str, problem: str) -> None:
        self.field = field
        self.problem = problem
        super().__init__(f"{field}: {problem}")


class RenderError(VisionError, ValueError):
    """Invalid rendering settings or pose.

    Attributes:
        field: The offending setting.
        problem: What is wrong with it.
    """

    def __init__(self, field: str, problem: str) -> None:
        self.field = field
        self.problem = problem
        super().__init__(f"{field}: {problem}")


class EstimationError(VisionError, ValueError):
    """An estimation cannot run on its input (wrong shapes, too few points)."""


class CalibrationError(VisionError, ValueError):
    """The calibration observations cannot determine a base point (``docs/math.md`` section 7).

    Attributes:
        leg: Index of the leg (0-based), None when the problem is not one leg's.
        problem: What is wrong.
        singular_values: Singular values of the leg's stacked system, largest first
            (None when not computed).
        equations: Number of equations (visible edges) of the leg.
        configurations: Number of configurations where the leg has a visible edge.
    """

    def __init__(
        self,
        leg: int | None,
        problem: str,
        singular_values: Any = None,
        equations: int | None = None,
        configurations: int | None = None,
    ) -> None:
        self.leg = leg
        self.problem = problem
        self.singular_values = singular_values
        self.equations = equations
        self.configurations = configurations
        where = f"leg {leg}: " if leg is not None else ""
        super().__init__(f"calibration: {where}{problem}")


class SourceError(VisionError):
    """A camera source (device, video file) cannot deliver frames.

    Attributes:
        source: The device index or file path.
        problem: What went wrong.
    """

    def __init__(self, source: object, problem: str) -> None:
        self.source = source
        self.problem = problem
        super().__init__(f"camera source {source!r}: {problem}")


class SourceOpenError(SourceError):
    """The device or file cannot be opened (missing, unreadable, not a video)."""


class SourceSpecError(SourceError, ValueError):
    """A camera spec (``--camera sim|video:PATH|device:N``) that names no source."""

    def __str__(self) -> str:
        return f"--camera {self.source}: {self.problem}"


class SourceClosedError(SourceError):
    """Reading from a source that is closed, or a device that stopped answering."""


class FrameError(SourceError):
    """A frame is unusable: empty, wrong size or wrong type.

    Attributes:
        index: Index of the frame in the stream.
        expected: Expected (width, height), if relevant.
        got: What was received (shape), if relevant.
    """

    def __init__(self, source: object, problem: str, index: int = -1,
                 expected: tuple[int, int] | None = None,
                 got: tuple[int, ...] | None = None) -> None:
        self.index = index
        self.expected = expected
        self.got = got
        super().__init__(source, f"frame {index}: {problem}")


class VideoWriteError(SourceError):
    """A video file cannot be written (codec unavailable, bad path, wrong frame)."""
