"""Exceptions of the :mod:`hexapod` package.

Every exception derives from :class:`HexapodError` and carries the evidence
(the field, leg, value and bounds) that explains it, in the style of Pink's
``NotWithinConfigurationLimits``.
"""

from __future__ import annotations

from typing import Any


class HexapodError(Exception):
    """Base class of every error raised by :mod:`hexapod`."""


class GeometryError(HexapodError, ValueError):
    """A geometry is invalid.

    Attributes:
        field: Name of the offending field (``"base_points"``, ``"stroke"``...).
        problem: What is wrong with it.
        source: File the geometry was read from, if any.
    """

    def __init__(self, field: str, problem: str, source: str | None = None) -> None:
        self.field = field
        self.problem = problem
        self.source = source
        where = f"{source}: " if source else ""
        super().__init__(f"{where}{field}: {problem}")


class ConfigFileError(HexapodError, ValueError):
    """A TOML configuration file is missing, unreadable or has a bad key.

    Attributes:
        path: The file.
        key: The offending key (dotted), if any.
        problem: What is wrong.
        suggestion: The close valid key, for a misspelt one.
    """

    def __init__(
        self, path: str, problem: str, key: str | None = None, suggestion: str | None = None
    ) -> None:
        self.path = path
        self.key = key
        self.problem = problem
        self.suggestion = suggestion
        msg = f"{path}: "
        if key is not None:
            msg += f"key '{key}': "
        msg += problem
        if suggestion:
            msg += f" (did you mean '{suggestion}'?)"
        super().__init__(msg)


class StrokeLimitError(HexapodError, ValueError):
    """A leg length is outside its stroke.

    Attributes:
        leg: Index of the leg (0-based).
        value: Its length [m].
        lower: Lower stroke limit [m].
        upper: Upper stroke limit [m].
    """

    def __init__(self, leg: int, value: float, lower: float, upper: float) -> None:
        self.leg = leg
        self.value = value
        self.lower = lower
        self.upper = upper
        super().__init__(
            f"leg {leg}: length {value * 1e3:.3f} mm outside the stroke "
            f"[{lower * 1e3:.3f}, {upper * 1e3:.3f}] mm"
        )


class ForwardKinematicsError(HexapodError):
    """The forward kinematics did not converge.

    Attributes:
        method: The solver (``"pinocchio"`` or ``"newton"``).
        residual: Norm of the final residual [m].
        iterations: Iterations made.
        reason: Why it stopped.
    """

    def __init__(self, method: str, residual: float, iterations: int, reason: str) -> None:
        self.method = method
        self.residual = residual
        self.iterations = iterations
        self.reason = reason
        super().__init__(
            f"forward kinematics ({method}) failed after {iterations} iterations: "
            f"{reason} (residual {residual:.3e} m)"
        )


class ShapeError(HexapodError, ValueError):
    """An array argument has the wrong shape or non-finite values.

    Attributes:
        name: Argument name.
        expected: Expected shape, as text.
        got: What was received.
    """

    def __init__(self, name: str, expected: str, got: Any) -> None:
        self.name = name
        self.expected = expected
        self.got = got
        super().__init__(f"{name}: expected {expected}, got {got}")


class BackendError(HexapodError):
    """A robot backend failed (communication, protocol or robot error)."""
