"""An emulated PI GCS hexapod controller (C-887 family), on loopback TCP or a pty.

:class:`GcsController` is the controller's state machine: it answers the subset of
GCS of :mod:`hexapod.backends.gcs_protocol` like the real controller (queries answered,
set commands silent, errors stored for ``ERR?``), with its own kinematic model of the
TRUE robot (a :class:`~hexapod.geometry.HexapodGeometry`, which may differ from the
nominal one a client uses):

- the platform pose is six coordinates about the pivot point
  (:mod:`hexapod.backends.gcs_pose`); ``MOV`` moves them in a straight line (every
  coordinate reaches its target at the same time) at the system velocity ``VLS``:
  the pivot point at ``VLS`` mm/s and the rotation (the norm of the change of U, V, W)
  at ``VLS`` deg/s, whichever takes longer, and never faster than the true robot's leg
  speed limit allows (the largest leg change over the leg speed limit);
- a target is reachable when every leg of the TRUE robot's inverse kinematics is inside
  its TRUE stroke (``VMO?``); an unreachable ``MOV`` is refused with error 7 and nothing
  moves;
- ``HLT`` and ``STP`` stop the platform where it is and store error 10.

:class:`GcsEmulator` serves it with the generic server of
:mod:`hexapod.backends.emulator_server` (seeded faults included); the console script is
``hexapod-emulator --gcs --tcp 127.0.0.1:PORT`` (or ``--gcs --pty``).
"""

from __future__ import annotations

import logging
import math
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from hexapod.backends import gcs_protocol as gp
from hexapod.backends.emulator_server import EmulatorServer, FaultConfig
from hexapod.backends.gcs_pose import ROTATION_ORDERS, PoseConvention, from_wire, to_wire
from hexapod.backends.gcs_protocol import CommandSyntaxError, GcsError
from hexapod.exceptions import BackendError, ShapeError
from hexapod.fk import forward_kinematics
from hexapod.geometry import HexapodGeometry
from hexapod.kinematics import inverse_kinematics

logger = logging.getLogger(__name__)

__all__ = ["LIMIT_TOL", "GcsConfig", "GcsController", "GcsEmulator"]

#: Tolerance of the stroke check on a target [m] (far above the 1e-9 mm of a command).
LIMIT_TOL = 1e-8


@dataclass(frozen=True)
class GcsConfig:
    """What the emulated GCS hexapod is.

    Attributes:
        geometry: The TRUE robot: its kinematics, stroke and leg speed limit.
        lengths: Initial leg lengths (6,) [m] (the zero position if None).
        coords: Initial coordinates (x, y, z [m], u, v, w [rad]) instead of ``lengths``.
        pivot: The pivot point in the platform frame (3,) [m].
        rotation_order: ``"moving-xyz"`` or ``"fixed-xyz"`` (:mod:`~hexapod.backends.gcs_pose`).
        zero_height: Height of the platform frame at the zero position [m]
            (the geometry's home height if None).
        velocity: Initial system velocity (``VLS``) [m/s] (and the same number of
            rad/s x 180/pi / 1000 for rotations: ``VLS`` is mm/s and deg/s).
        max_velocity: Largest ``VLS`` accepted [m/s].
        identity: The ``*IDN?`` answer.
        dynamics: The platform is moved by the robot with mass and drives
            (:mod:`hexapod.backends.emulator_dynamics`): the straight-line motion becomes
            the legs' position setpoints, and ``POS?`` answers the true pose.
        physics_dt: Physics step of ``dynamics`` [s].
    """

    geometry: HexapodGeometry
    lengths: tuple[float, ...] | None = None
    coords: tuple[float, ...] | None = None
    pivot: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotation_order: str = "moving-xyz"
    zero_height: float | None = None
    velocity: float = 0.01
    max_velocity: float = 0.5
    identity: str = "hexapod-vs, GCS hexapod emulator, 0, 0.1.0"
    dynamics: bool = False
    physics_dt: float = 1e-3
    convention: PoseConvention = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.rotation_order not in ROTATION_ORDERS:
            raise BackendError(f"rotation order must be one of {ROTATION_ORDERS}, got "
                               f"{self.rotation_order!r}")
        if not (math.isfinite(self.max_velocity) and self.max_velocity > 0):
            raise BackendError(f"max_velocity must be positive, got {self.max_velocity} m/s")
        if not (math.isfinite(self.velocity) and 0 < self.velocity <= self.max_velocity):
            raise BackendError(f"velocity must be in (0, {self.max_velocity}] m/s, got "
                               f"{self.velocity}")
        pivot = np.asarray(self.pivot, dtype=float)
        if pivot.shape != (3,) or not np.all(np.isfinite(pivot)):
            raise ShapeError("pivot", "3 finite coordinates [m]", self.pivot)
        object.__setattr__(self, "pivot", tuple(pivot.tolist()))
        if self.lengths is not None:
            q = np.asarray(self.lengths, dtype=float)
            lo, hi = self.geometry.stroke
            if q.shape != (6,) or not np.all(np.isfinite(q)):
                raise ShapeError("lengths", "6 finite leg lengths [m]", self.lengths)
            if np.any(q < lo - LIMIT_TOL) or np.any(q > hi + LIMIT_TOL):
                raise BackendError(f"initial lengths {np.round(q * 1e3, 3).tolist()} mm "
                                   f"outside the stroke [{lo * 1e3:.3f}, {hi * 1e3:.3f}] mm")
            object.__setattr__(self, "lengths", tuple(q.tolist()))
        object.__setattr__(self, "convention", PoseConvention.for_geometry(
            self.geometry, pivot, self.rotation_order, self.zero_height))
        if self.coords is not None:
            c = np.asarray(self.coords, dtype=float)
            if self.lengths is not None:
                raise BackendError("give the initial lengths or the initial coords, not both")
            if c.shape != (6,) or not np.all(np.isfinite(c)):
                raise ShapeError("coords", "6 finite coordinates (x, y, z [m], u, v, w [rad])",
                                 self.coords)
            q = inverse_kinematics(self.geometry, *self.convention.pose(c))
            lo, hi = self.geometry.stroke
            if np.any(q < lo - LIMIT_TOL) or np.any(q > hi + LIMIT_TOL):
                raise BackendError(f"initial pose {np.round(c, 6).tolist()} out of limits: "
                                   f"legs {np.round(q * 1e3, 3).tolist()} mm, stroke "
                                   f"[{lo * 1e3:.3f}, {hi * 1e3:.3f}] mm")
            object.__setattr__(self, "coords", tuple(c.tolist()))

    def initial_coords(self) -> np.ndarray:
        """The coordinates (x, y, z [m], u, v, w [rad]) the controller starts at."""
        if self.coords is not None:
            return np.array(self.coords)
        if self.lengths is None:
            return np.zeros(6)
        sol = forward_kinematics(self.geometry, np.array(self.lengths))
        return self.convention.coords(sol.rotation, sol.translation)


class GcsController:
    """The emulated controller: pose, motion, limits, pivot point and error register.

    Every method takes the current time ``now`` [s] of a monotonic clock; the pose is
    advanced exactly (in closed form) to that time before a command acts.

    Args:
        config: What the hexapod is.
        now: The current time [s].
    """

    terminator: ClassVar[bytes] = gp.TERMINATOR
    max_line: ClassVar[int] = gp.MAX_LINE

    def __init__(self, config: GcsConfig, now: float) -> None:
        self.config = config
        self.geometry = config.geometry
        self.convention = config.convention
        c0 = config.initial_coords()
        self._coords = c0.copy()
        self._start = c0.copy()
        self._target = c0.copy()
        self._t0 = now
        self._duration = 0.0
        #: System velocity (``VLS``) [m/s].
        self.velocity = config.velocity
        #: The stored error number (``ERR?`` returns and clears it).
        self.error = int(GcsError.NO_ERROR)
        #: Added to the reported X [m] (fault injection: a glitching reading).
        self.glitch = 0.0
        self.commands = 0
        self.last_command = ""
        #: The last commands received (newest last), for inspection.
        self.history: deque[str] = deque(maxlen=256)
        self._t = now
        self._axes = None
        if config.dynamics:
            from hexapod.backends.emulator_dynamics import DynamicAxes

            self._axes = DynamicAxes(self.geometry, self.lengths_of(c0), config.physics_dt)

    # ---------------------------------------------------------------- motion
    def advance(self, now: float) -> None:
        """Move the platform up to ``now`` [s] (straight line in the six coordinates;
        with ``dynamics`` the legs of the robot with mass follow that line)."""
        if self._axes is not None:
            start, h = self._t, self._axes.h
            steps = self._axes.steps_for(now - start)
            k = 0
            while k < steps and self._on_line(start + (k + 1) * h):
                commanded = self._commanded(start + (k + 1) * h)
                self._axes.step(self.lengths_of(commanded), self.geometry.max_speed)
                k += 1
            if k < steps:  # past the line's end: its target held (nothing to do at rest)
                self._axes.hold(self.lengths_of(self._target), self.geometry.max_speed,
                                steps - k)
        self._t = max(self._t, now)
        self._coords = self._commanded(now)
        if self._duration > 0 and now >= self._t0 + self._duration:
            self._duration = 0.0

    def _on_line(self, now: float) -> bool:
        """The platform is commanded along its line at ``now`` [s] (not yet at its end)."""
        return self._duration > 0 and now < self._t0 + self._duration

    def _commanded(self, now: float) -> np.ndarray:
        """The commanded coordinates at ``now`` [s] on the straight line."""
        if self._duration <= 0 or now >= self._t0 + self._duration:
            return self._target.copy()
        s = max(0.0, (now - self._t0) / self._duration)
        return self._start + s * (self._target - self._start)  # type: ignore[no-any-return]

    @property
    def coords(self) -> np.ndarray:
        """The current coordinates (x, y, z [m], u, v, w [rad]) (at the last advance):
        the commanded ones, or with ``dynamics`` those of the robot's true pose."""
        if self._axes is not None:
            return self.convention.coords(*self._axes.pose())  # type: ignore[no-any-return]
        return self._coords.copy()

    @property
    def moving(self) -> bool:
        """The platform is on its way to a target (at the last advance); with
        ``dynamics``, until its legs have arrived (within 1 um) and stopped."""
        if self._axes is not None and self._duration <= 0:
            arrived = np.all(np.abs(self._axes.lengths - self.lengths_of(self._target))
                             <= 1e-6)
            return not (arrived and self._axes.settled)
        return self._duration > 0

    def lengths_of(self, coords: np.ndarray) -> np.ndarray:
        """The TRUE leg lengths of coordinates [m]."""
        return inverse_kinematics(self.geometry, *self.convention.pose(coords))

    def reachable(self, coords: np.ndarray) -> bool:
        """Every TRUE leg inside the TRUE stroke at these coordinates (and V within +-90 deg)."""
        if not np.all(np.isfinite(coords)) or abs(coords[4]) >= 0.5 * np.pi:
            return False
        q = self.lengths_of(coords)
        lo, hi = self.geometry.stroke
        return bool(np.all(q >= lo - LIMIT_TOL) and np.all(q <= hi + LIMIT_TOL))

    def _plan(self, target: np.ndarray, now: float) -> None:
        start = self._coords.copy()
        d = target - start
        lin = float(np.linalg.norm(d[:3])) / self.velocity
        rot = float(np.linalg.norm(np.rad2deg(d[3:]))) / (self.velocity * 1e3)
        legs = float(np.max(np.abs(self.lengths_of(target) - self.lengths_of(start))))
        self._start, self._target, self._t0 = start, target.copy(), now
        self._duration = max(lin, rot, legs / self.geometry.max_speed)

    def _stop(self) -> None:
        self._target = self._coords.copy()
        self._start = self._coords.copy()
        self._duration = 0.0

    # ---------------------------------------------------------------- served device
    def frame(self, reply: str) -> bytes:
        """The bytes of an answer (its lines joined by ``" \\n"``); b"" for no answer."""
        return gp.frame_answer(reply.split("\n")) if reply else b""

    def next_event(self) -> float | None:
        """No timer: the pose is computed in closed form when asked."""
        return None

    def overlong_line(self) -> str:
        """A line longer than :attr:`max_line`: error 3, no answer."""
        self.error = int(GcsError.COMMAND_TOO_LONG)
        return ""

    def handle_line(self, line: bytes, now: float) -> str:
        """Act on one received line; return its answer ('' for none: set commands and
        errors, which are stored for ``ERR?``)."""
        self.advance(now)
        self.commands += 1
        if len(line) > self.max_line:
            return self.overlong_line()
        try:
            text = line.decode("ascii").rstrip("\r\n")
        except UnicodeDecodeError:
            self.last_command = "<not ascii>"
            self.error = int(GcsError.PARAM_SYNTAX)
            return ""
        if not text.strip():
            return ""
        self.last_command = text
        self.history.append(text)
        name, args = gp.split_command(text)
        handler = self._handlers.get(name)
        if handler is None:
            self.error = int(GcsError.UNKNOWN_COMMAND)
            return ""
        try:
            return handler(self, args, now)
        except CommandSyntaxError as exc:
            self.error = int(exc.code)
            return ""

    # ---------------------------------------------------------------- commands
    @staticmethod
    def _no_args(args: list[str]) -> None:
        if args:
            raise CommandSyntaxError(GcsError.PARAM_SYNTAX, "takes no argument")

    def _idn(self, args: list[str], now: float) -> str:
        self._no_args(args)
        return self.config.identity

    def _err(self, args: list[str], now: float) -> str:
        self._no_args(args)
        code, self.error = self.error, int(GcsError.NO_ERROR)
        return str(code)

    def _axis_lines(self, values: dict[str, float], axes: list[str]) -> str:
        return "\n".join(f"{a}={gp.format_answer_number(values[a])}" for a in axes)

    def inject_glitch(self, offset: float) -> None:
        """From now on report the platform ``offset`` [m] further along X than it is."""
        self.glitch = float(offset)

    def _pos(self, args: list[str], now: float) -> str:
        axes = gp.parse_axis_list(args)
        shown = to_wire(self.coords)
        shown["X"] += self.glitch * 1e3
        return self._axis_lines(shown, axes)

    def _ont(self, args: list[str], now: float) -> str:
        axes = gp.parse_axis_list(args)
        return "\n".join(f"{a}={0 if self.moving else 1}" for a in axes)

    def _target_of(self, args: list[str]) -> np.ndarray:
        wire = to_wire(self._target)
        wire.update(gp.parse_axis_values(args))
        return from_wire(wire)

    def _mov(self, args: list[str], now: float) -> str:
        target = self._target_of(args)
        if not self.reachable(target):
            self.error = int(GcsError.POS_OUT_OF_LIMITS)
            return ""
        self._plan(target, now)
        return ""

    def _vmo(self, args: list[str], now: float) -> str:
        return "1" if self.reachable(self._target_of(args)) else "0"

    def _vls(self, args: list[str], now: float) -> str:
        if len(args) != 1:
            raise CommandSyntaxError(GcsError.PARAM_SYNTAX, "VLS takes one velocity")
        try:
            v = gp.parse_number(args[0]) * 1e-3
        except ValueError:
            raise CommandSyntaxError(GcsError.PARAM_SYNTAX, args[0]) from None
        if not 0 < v <= self.config.max_velocity * (1 + 1e-12):
            raise CommandSyntaxError(GcsError.PARAM_OUT_OF_RANGE, args[0])
        self.velocity = min(v, self.config.max_velocity)
        if self.moving:  # the rest of the way at the new velocity
            self._plan(self._target, now)
        return ""

    def _vls_query(self, args: list[str], now: float) -> str:
        self._no_args(args)
        return gp.format_answer_number(self.velocity * 1e3)

    def _hlt(self, args: list[str], now: float) -> str:
        gp.parse_axis_list(args)  # HLT [axes]: a hexapod stops as a whole
        self._stop()
        self.error = int(GcsError.STOP)
        logger.info("HLT: platform halted at %s (error 10 set)",
                    np.round(self._coords, 6).tolist())
        return ""

    def _stp(self, args: list[str], now: float) -> str:
        self._no_args(args)
        self._stop()
        self.error = int(GcsError.STOP)
        return ""

    def _spi(self, args: list[str], now: float) -> str:
        values = gp.parse_axis_values(args, gp.PIVOT_AXES)
        if self.moving or np.any(np.abs(self._coords[3:]) > 1e-9):  # below 1 micro-degree
            raise CommandSyntaxError(GcsError.SET_PIVOT_NOT_POSSIBLE, "U, V, W not all 0")
        pivot = self.convention.pivot.copy()
        for i, axis in enumerate(gp.PIVOT_AXES):
            if axis in values:
                pivot[i] = values[axis] * 1e-3
        # with U = V = W = 0 the platform does not move: X, Y, Z follow the pivot point
        R, t = self.convention.pose(self._coords)
        self.convention = self.convention.with_pivot(pivot)
        self._coords = self._start = self._target = self.convention.coords(R, t)
        return ""

    def _spi_query(self, args: list[str], now: float) -> str:
        axes = gp.parse_axis_list(args, gp.PIVOT_AXES)
        p = self.convention.pivot * 1e3
        return self._axis_lines(dict(zip(gp.PIVOT_AXES, p.tolist(), strict=True)), axes)

    _handlers: ClassVar[dict[str, Callable[[GcsController, list[str], float], str]]] = {
        "*IDN?": _idn,
        "ERR?": _err,
        "POS?": _pos,
        "ONT?": _ont,
        "MOV": _mov,
        "VMO?": _vmo,
        "VLS": _vls,
        "VLS?": _vls_query,
        "HLT": _hlt,
        "STP": _stp,
        "SPI": _spi,
        "SPI?": _spi_query,
    }


class GcsEmulator(EmulatorServer[GcsController]):
    """An emulated GCS hexapod controller served on loopback TCP (or a pseudo-terminal).

    Args:
        config: The hexapod (its TRUE geometry, start, pivot, velocities).
        faults: Faults to inject (none if None).
        transport: ``"tcp"`` (default, as a C-887 on the network) or ``"pty"``.
        host: TCP address (loopback only unless ``allow_remote``).
        port: TCP port (0: any free port, see :attr:`url`).
        allow_remote: Allow a non-loopback ``host``.
        line_rate: Emulated line rate [baud] (0: instantaneous).

    Example:
        >>> with GcsEmulator(GcsConfig(deltalab())) as emu:
        ...     robot = GcsHexapod(emu.url, deltalab())
    """

    def __init__(self, config: GcsConfig, faults: FaultConfig | None = None, *,
                 transport: str = "tcp", host: str = "127.0.0.1", port: int = 0,
                 allow_remote: bool = False, line_rate: float = 0.0) -> None:
        self.config = config
        super().__init__(GcsController(config, time.monotonic()), faults,
                         transport=transport, host=host, port=port,
                         allow_remote=allow_remote, line_rate=line_rate)

    def client_url(self) -> str:
        """What ``--backend gcs:URL`` takes (printed and logged): ``tcp://HOST:PORT``, or
        ``serial:/dev/pts/N`` on a pseudo-terminal."""
        return ("tcp://" if self.transport == "tcp" else "serial:") + self.device

    def coords(self) -> np.ndarray:
        """The controller's coordinates now (x, y, z [m], u, v, w [rad])."""
        with self._lock:
            self.board.advance(time.monotonic())
            return self.board.coords

    def pose(self) -> tuple[np.ndarray, np.ndarray]:
        """The TRUE platform pose now (rotation, translation [m])."""
        with self._lock:
            self.board.advance(time.monotonic())
            return self.board.convention.pose(self.board.coords)

    def true_lengths(self) -> np.ndarray:
        """The TRUE leg lengths now (6,) [m]."""
        with self._lock:
            self.board.advance(time.monotonic())
            return self.board.lengths_of(self.board.coords)

    def moving(self) -> bool:
        """The platform is moving now."""
        with self._lock:
            self.board.advance(time.monotonic())
            return self.board.moving

    def history(self) -> list[str]:
        """The last commands received (oldest first)."""
        with self._lock:
            return list(self.board.history)

