"""Exceptions of the :mod:`hexapod` package.

Every exception derives from :class:`HexapodError` and carries the evidence
(the field, leg, value and bounds) that explains it, in the style of Pink's
``NotWithinConfigurationLimits``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hexapod.error_base import PicklableError


class HexapodError(PicklableError):
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


class InertiaError(GeometryError):
    """An ``[inertia]`` value of a robot is physically impossible (negative mass,
    inertia not positive definite or violating the triangle inequality, centre of mass
    outside the leg). ``field`` is the dotted key, e.g. ``"inertia.body_mass"``."""


class DriveError(GeometryError):
    """A ``[drives]`` value of a robot is invalid; ``field`` is the dotted key, e.g.
    ``"drives.force_limit"``, and the message names the leg."""


class DynamicsError(HexapodError, ValueError):
    """The dynamics have no finite answer at a state (a singular pose: the legs cannot
    hold or move the platform, or a singular mass matrix).

    Attributes:
        what: The computation (``"forward"``, ``"inverse"``, ``"terms"``, ``"legs"``,
            ``"jacobian"``).
        item: Index of the first offending state in the batch.
    """

    def __init__(self, what: str, item: int) -> None:
        self.what = what
        self.item = item
        super().__init__(f"dynamics ({what}): no finite result at state {item} of the batch "
                         "(singular pose or mass matrix)")


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


class WorkspaceError(HexapodError, RuntimeError):
    """Random poses asked of a region that (nearly) misses the robot's workspace.

    Attributes:
        robot: The robot's name.
        found: Poses found inside the strokes.
        attempts: Poses drawn.
        max_translation: Half-width of the translation box [m].
        max_angle: Largest rotation [rad].
        margin: Distance kept from the stroke limits [m].
    """

    def __init__(self, robot: str, found: int, attempts: int, max_translation: float,
                 max_angle: float, margin: float) -> None:
        self.robot = robot
        self.found = found
        self.attempts = attempts
        self.max_translation = max_translation
        self.max_angle = max_angle
        self.margin = margin
        super().__init__(
            f"{robot}: only {found} of {attempts} random poses (translations within "
            f"{max_translation * 1e3:g} mm of the home pose, rotations up to "
            f"{np.degrees(max_angle):g} deg) keep every leg {margin * 1e3:g} mm inside its "
            "stroke: the box hardly intersects the workspace (a robot far from the nominal "
            "one, or a box too large)")


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


class LayoutError(HexapodError, ValueError):
    """A packed row's layout does not fit the compiled function it describes, or a
    block of it is misused.

    Attributes:
        function: The compiled function's name.
        problem: What does not fit (sizes, the block's name).
    """

    def __init__(self, function: str, problem: str) -> None:
        self.function = function
        self.problem = problem
        super().__init__(f"{function}: {problem}")


class BackendError(HexapodError):
    """A robot backend failed (communication, protocol or robot error)."""


class ActuationError(BackendError, ValueError):
    """A command of a kind (leg velocities or forces) that its receiver cannot apply.

    Attributes:
        controller: The controller (name or label) that commands it.
        actuation: What it commands (``"velocity"`` or ``"force"``).
        accepted: What the receiver applies.
        receiver: The world, backend or board that refuses it.
    """

    def __init__(self, controller: str, actuation: str, accepted: tuple[Any, ...],
                 receiver: str, problem: str | None = None, quantity: str | None = None,
                 accepted_quantities: list[str] | None = None) -> None:
        self.controller = controller
        self.actuation = actuation
        self.accepted = accepted
        self.receiver = receiver
        if problem is None:
            what = quantity or actuation
            can = " or ".join(accepted_quantities or [str(a) for a in accepted])
            problem = (f"controller '{controller}' commands {what}, but {receiver} applies "
                       f"only {can} (a command is never converted from one kind to the "
                       f"other)")
        super().__init__(problem)


class UnknownBackendError(BackendError, KeyError):
    """No backend is registered under this name.

    Attributes:
        name: The name asked for.
        available: The registered names.
        suggestion: The close registered name, if any.
    """

    def __init__(self, name: str, available: list[str], suggestion: str | None = None) -> None:
        self.name = name
        self.available = sorted(available)
        self.suggestion = suggestion
        hint = f" (did you mean '{suggestion}'?)" if suggestion else ""
        super().__init__(f"unknown backend {name!r}{hint}; registered: "
                         f"{', '.join(self.available)}; or name a class as module:attr[:ARGS]")

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0])


class BackendPluginError(BackendError):
    """A backend plugin could not be loaded, or does not build a :class:`Backend`.

    Attributes:
        spec: The backend name or ``module:attr`` spec.
        source: Where it comes from (a distribution, or "command line").
        problem: What is wrong.
    """

    def __init__(self, spec: str, source: str, problem: str) -> None:
        self.spec = spec
        self.source = source
        self.problem = problem
        super().__init__(f"backend {spec!r} ({source}): {problem}")


class RecordError(HexapodError, ValueError):
    """A trial record (``.npz``) is missing, unreadable, lacks a key or has a bad shape.

    Attributes:
        path: The file (``"<memory>"`` for arrays not read from a file).
        key: The missing or malformed key (None for the file itself).
        problem: What is wrong.
    """

    def __init__(self, path: str, problem: str, key: str | None = None) -> None:
        self.path = path
        self.key = key
        self.problem = problem
        super().__init__(f"{path}: " + (f"key '{key}': " if key else "") + problem)


class ViewerError(HexapodError):
    """The MeshCat server could not be started or reached within its timeout.

    Attributes:
        url: The ZeroMQ address tried (None when starting a server).
        timeout: How long it was waited for [s].
        problem: What happened.
    """

    def __init__(self, problem: str, url: str | None = None, timeout: float = 0.0) -> None:
        self.url = url
        self.timeout = timeout
        self.problem = problem
        where = f"MeshCat server {url}" if url else "MeshCat server"
        super().__init__(f"{where}: {problem} (waited {timeout:g} s)")


class TrajectoryError(HexapodError, ValueError):
    """A reference trajectory cannot be built from its parameters.

    Attributes:
        field: The offending parameter (``"speed"``, ``"shape"``...).
        problem: What is wrong with it.
    """

    def __init__(self, field: str, problem: str) -> None:
        self.field = field
        self.problem = problem
        super().__init__(f"trajectory {field}: {problem}")


class UnsafeNameError(HexapodError, ValueError):
    """A name that becomes part of a file name (a scenario, a controller label, a plugin
    name) is not allowed: a separator, ``..``, a control character, a bad character.

    Attributes:
        what: What the name is (``"scenario name"``, ``"controller label"``...).
        value: The name as given.
        problem: What is wrong with it.
    """

    def __init__(self, what: str, value: str, problem: str) -> None:
        self.what = what
        self.value = value
        self.problem = problem
        super().__init__(f"{what} {value!r}: {problem}")


class OutputError(HexapodError):
    """An output would leave its directory, or would replace or mix with files the project
    did not write (nothing was written).

    Attributes:
        path: The file or directory.
        problem: What is there and how to proceed.
    """

    def __init__(self, path: str, problem: str) -> None:
        self.path = path
        self.problem = problem
        super().__init__(f"{path}: {problem}")


class UnsupportedInstructionError(HexapodError, ValueError):
    """A CasADi function uses an instruction the lane-parallel code generator
    (:mod:`hexapod.compiled_lanes`) does not translate.

    Attributes:
        function: Name of the function.
        instruction: CasADi's name of the instruction (``"ATAN2"``...).
    """

    def __init__(self, function: str, instruction: str) -> None:
        self.function = function
        self.instruction = instruction
        super().__init__(f"{function}: instruction {instruction} has no lane translation")


class IdentificationError(HexapodError, ValueError):
    """Dynamic identification impossible on the data given (too few samples, an
    excitation that leaves a base parameter undetermined, non-finite data); the message
    says which."""
