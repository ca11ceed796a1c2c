"""Backends by name: built-ins, entry-point plugins and ``module:attr`` specs.

A ``--backend`` spec is ``NAME[:ARGS]`` or ``module:attr[:ARGS]``:

- ``NAME`` is a registered backend (``hexapod-bench list`` shows them): the
  built-ins ``sim``, ``emulator``, ``serial`` (``serial:URL``), ``gcs``
  (``gcs:tcp://HOST:PORT``, a PI GCS hexapod controller) and ``gcs-emulator``, and every
  entry point of the group ``hexapod.backends``::

      [project.entry-points."hexapod.backends"]
      my-robot = "my_package.robot:MyRobot"

- ``module:attr`` names a backend class (or an opener function) directly,
  without packaging: ``--backend my_package.robot:MyRobot:192.168.0.7``.

``ARGS`` is the rest of the spec, passed as one string to the backend (an
address, a port, ``key=value`` pairs: the backend decides).

What a spec names is either a :class:`~hexapod.backends.base.Backend` subclass,
opened with its classmethod :meth:`~hexapod.backends.base.Backend.open`, or a
function with the same signature ``(args, geometry, start) -> Backend``.
"""

from __future__ import annotations

import importlib
import importlib.metadata as metadata
import logging
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from hexapod.backends.base import Backend, started
from hexapod.config import suggest
from hexapod.exceptions import (
    BackendError,
    BackendPluginError,
    UnknownBackendError,
    UnsafeNameError,
)
from hexapod.geometry import HexapodGeometry
from hexapod.outputs import check_name

log = logging.getLogger(__name__)

ENTRY_POINT_GROUP = "hexapod.backends"

#: ``(args, geometry, start) -> Backend``: what a spec resolves to.
BackendOpener = Callable[[str, HexapodGeometry, np.ndarray | None], Backend]


@dataclass(frozen=True)
class BackendInfo:
    """A registered backend and where it comes from.

    Attributes:
        name: Registry name.
        package: Distribution that provides it.
        version: Version of that distribution.
        description: First line of its docstring.
    """

    name: str
    package: str
    version: str
    description: str


def _no_arguments(name: str) -> Callable[[str], object]:
    """The ``validate`` of a backend that takes no arguments."""
    def validate(args: str) -> None:
        if args:
            raise BackendPluginError(name, "hexapod-vs", f"takes no arguments, got {args!r}")
    return validate


def _open_emulator(args: str, geometry: HexapodGeometry, start: np.ndarray | None) -> Backend:
    """A firmware emulator on a pseudo-terminal, driven through the serial backend."""
    from hexapod.backends.serial_emulated import open_emulated_robot

    _no_arguments("emulator")(args)
    robot = open_emulated_robot(geometry, start)
    return started(robot, start)


def _open_sim(args: str, geometry: HexapodGeometry, start: np.ndarray | None) -> Backend:
    """An ideal simulated robot (leg lengths integrate the clamped commands)."""
    from hexapod.backends.sim import SimulatedRobot

    _no_arguments("sim")(args)
    return SimulatedRobot(geometry, start)


def serial_url(args: str) -> tuple[str, int]:
    """The port URL and baud rate of ``serial:URL[?baud=N]`` (115200 by default; other
    query options of a pyserial URL, ``socket://HOST:PORT?logging=debug``, stay in it).

    Raises:
        BackendPluginError: No URL, or a baud rate that is not a positive integer.
    """
    from hexapod.backends import protocol

    url, sep, query = args.partition("?")
    if not url:
        raise BackendPluginError("serial", "hexapod-vs", "needs a URL: serial:/dev/ttyUSB0 or "
                                 "serial:socket://HOST:PORT")
    baud, kept = protocol.BAUDRATE, []
    for item in query.split("&") if sep else []:
        key, _, value = item.partition("=")
        if key != "baud":
            kept.append(item)
        elif not value.isdigit() or int(value) <= 0:
            raise BackendPluginError("serial", "hexapod-vs", f"baud: expected a positive "
                                     f"integer (e.g. ?baud=57600), got {value!r}")
        else:
            baud = int(value)
    return (f"{url}?{'&'.join(kept)}" if kept else url), baud


def _open_serial(args: str, geometry: HexapodGeometry, start: np.ndarray | None) -> Backend:
    """A robot controller board speaking the project's serial protocol
    (``serial:URL[?baud=N]``)."""
    from hexapod.backends.serial import SerialRobot

    url, baud = serial_url(args)
    robot = SerialRobot(url, baudrate=baud)
    return started(robot, start)


def _open_gcs(args: str, geometry: HexapodGeometry, start: np.ndarray | None) -> Backend:
    """A hexapod behind a PI GCS controller (gcs:tcp://HOST:PORT or gcs:serial:URL)."""
    from hexapod.backends.gcs import GcsHexapod

    return GcsHexapod.open(args, geometry, start)


def _open_gcs_emulator(args: str, geometry: HexapodGeometry,
                       start: np.ndarray | None) -> Backend:
    """An emulated PI GCS hexapod on loopback TCP, driven through the gcs backend."""
    from hexapod.backends.gcs_emulated import open_from_spec

    robot: Backend = open_from_spec(args, geometry, start)
    return robot


class BackendRegistry:
    """Backends by name (built-ins, then the ``hexapod.backends`` entry points, lazily)."""

    def __init__(self) -> None:
        self._openers: dict[str, BackendOpener] = {}
        self._info: dict[str, BackendInfo] = {}
        self._needs_args: dict[str, str] = {}
        self._validate: dict[str, Callable[[str], object]] = {}
        self._simulated: set[str] = set()
        self.errors: list[BackendPluginError] = []
        self._plugins_loaded = False

    def register(self, name: str, target: type[Backend] | BackendOpener,
                 package: str = "hexapod-vs", version: str | None = None,
                 needs_args: str | None = None, simulated: bool | None = None,
                 validate: Callable[[str], object] | None = None) -> None:
        """Register a backend class or opener function under ``name``.

        Args:
            name: Registry name.
            target: A :class:`Backend` subclass or an opener ``(args, geometry, start)``.
            package: Distribution that provides it.
            version: Its version (looked up when None).
            needs_args: What ARGS it needs (a spec without them is refused early).
            simulated: The robot is simulated (an emulator, a model), not hardware
                (:meth:`is_simulated`); None: the target's ``simulated`` attribute, else
                False (a plugin is real hardware unless it says otherwise).
            validate: Checks a spec's ARGS without opening anything (raising the error
                the opener would): :meth:`check` runs it, so that a bad option is refused
                before a session's record is written or a robot connected.

        Raises:
            BackendPluginError: ``name`` breaks :func:`hexapod.outputs.check_name`, or
                ``target`` is no backend.
        """
        try:
            check_name(name, "backend name")
        except UnsafeNameError as exc:
            raise BackendPluginError(str(name), package, exc.problem) from None
        opener = _opener(name, target, package)
        if needs_args:
            self._needs_args[name] = needs_args
        if validate is not None:
            self._validate[name] = validate
        if simulated is None:
            simulated = bool(getattr(target, "simulated", False))
        if simulated:
            self._simulated.add(name)
        else:
            self._simulated.discard(name)
        doc = (getattr(target, "__doc__", None) or "").strip().splitlines()
        self._openers[name] = opener
        self._info[name] = BackendInfo(name, package, version or _version(package),
                                       doc[0] if doc else "")

    def load_plugins(self) -> None:
        """Load the entry points of the ``hexapod.backends`` group (once)."""
        if self._plugins_loaded:
            return
        self._plugins_loaded = True
        for ep in metadata.entry_points(group=ENTRY_POINT_GROUP):
            dist = ep.dist.name if ep.dist is not None else "unknown"
            try:
                target = ep.load()
                self.register(ep.name, target, dist,
                              ep.dist.version if ep.dist is not None else "unknown")
            except Exception as exc:  # a broken plugin must not break the others
                err = exc if isinstance(exc, BackendPluginError) else BackendPluginError(
                    ep.name, dist, f"{type(exc).__name__}: {exc}")
                log.warning("%s", err)
                self.errors.append(err)

    def info(self) -> list[BackendInfo]:
        """Every registered backend with its package and version, by name."""
        self.load_plugins()
        return [self._info[n] for n in sorted(self._info)]

    def names(self) -> list[str]:
        """Registered names."""
        self.load_plugins()
        return sorted(self._openers)

    def resolve(self, spec: str) -> tuple[str, BackendOpener, str]:
        """Split a spec into (name, opener, args).

        Raises:
            UnknownBackendError: Neither a registered name nor ``module:attr``.
            BackendPluginError: ``module:attr`` that cannot be imported or is not a backend.
        """
        self.load_plugins()
        if not isinstance(spec, str) or not spec.strip():
            raise UnknownBackendError(str(spec), list(self._openers))
        head, _, rest = spec.partition(":")
        if head in self._openers:
            return head, self._openers[head], rest
        if "." in head or rest:
            attr, _, args = rest.partition(":")
            if not attr:
                raise UnknownBackendError(spec, list(self._openers),
                                          suggest(head, self._openers))
            try:
                obj: Any = importlib.import_module(head)
                for part in attr.split("."):
                    obj = getattr(obj, part)
            except ModuleNotFoundError as exc:
                close = suggest(head, self._openers)
                named_class = all(part.isidentifier() for part in attr.split("."))
                if exc.name == head and "." not in head and (close or not named_class):
                    # a registered name misspelt ('seial:/dev/ttyUSB0'), not a module
                    raise UnknownBackendError(spec, list(self._openers), close) from None
                hint = (f" (is the folder of {head.replace('.', '/')}.py on PYTHONPATH? "
                        "the module of module:attr must be importable from where the "
                        "command runs)" if exc.name == head else "")
                raise BackendPluginError(f"{head}:{attr}", "command line",
                                         f"{type(exc).__name__}: {exc}{hint}") from None
            except (ImportError, AttributeError) as exc:
                raise BackendPluginError(f"{head}:{attr}", "command line",
                                         f"{type(exc).__name__}: {exc}") from None
            return f"{head}:{attr}", _opener(f"{head}:{attr}", obj, "command line"), args
        raise UnknownBackendError(spec, list(self._openers), suggest(head, self._openers))

    def check(self, spec: str) -> str:
        """Validate a spec before any work (resolves it); returns its name.

        Raises:
            UnknownBackendError, BackendPluginError: A bad spec, or a backend that needs
                arguments given none (``serial`` without its URL).
            BackendError: Its arguments refused by the backend's ``validate``
                (:meth:`register`).
        """
        name, _, args = self.resolve(spec)
        if name in self._needs_args and not args:
            raise BackendPluginError(name, self._info[name].package,
                                     f"needs arguments: {self._needs_args[name]}")
        if name in self._validate:
            self._validate[name](args)
        return name

    def is_simulated(self, spec: str) -> bool:
        """Whether the robot of a spec is simulated (``sim``, ``emulator``,
        ``gcs-emulator``, a plugin registered with ``simulated=True`` or whose class has
        ``simulated = True``) rather than real hardware (``serial:``, ``gcs:``, any other
        plugin). A link to an emulator through ``serial:``/``gcs:`` counts as hardware:
        nothing on the line tells them apart.

        Raises:
            UnknownBackendError, BackendPluginError: A bad spec.
        """
        name, opener, _ = self.resolve(spec)
        if name in self._openers:
            return name in self._simulated
        target = getattr(opener, "__self__", opener)  # a class's bound ``open``
        return bool(getattr(target, "simulated", False))

    def open(self, spec: str, geometry: HexapodGeometry,
             start: np.ndarray | None = None) -> Backend:
        """Open the backend of a spec.

        Args:
            spec: ``NAME[:ARGS]`` or ``module:attr[:ARGS]``.
            geometry: The nominal robot (stroke, speed limit, kinematics).
            start: Leg lengths [m] to start from: a simulated robot starts there, a real
                one moves there (None: where it is).

        Raises:
            UnknownBackendError, BackendPluginError: A bad spec or plugin.
            BackendError: The backend's own failure (connection, robot).
        """
        name = self.check(spec)
        _, opener, args = self.resolve(spec)
        try:
            robot = opener(args, geometry, start)
        except BackendError:
            raise
        except Exception as exc:  # a plugin's own failure (a bad ARGS, an abstract class,
            # its SDK): named as the plugin's, not a traceback of an internal error
            raise BackendPluginError(name, "open", f"{type(exc).__name__}: {exc}") from exc
        if not isinstance(robot, Backend):
            for attr in ("reset", "step", "measured_lengths", "halt", "close"):
                if not callable(getattr(robot, attr, None)):
                    raise BackendPluginError(name, "opener",
                                             f"returned {type(robot).__name__} without "
                                             f"{attr}()")
        return robot


def _opener(name: str, target: Any, package: str) -> BackendOpener:
    if isinstance(target, type):
        if not issubclass(target, Backend):
            raise BackendPluginError(name, package, f"{target.__name__} is not a subclass of "
                                     "hexapod.backends.base.Backend")
        return target.open
    if not callable(target):
        raise BackendPluginError(name, package, f"{target!r} is not callable")
    return target  # type: ignore[no-any-return]


def _version(package: str) -> str:
    try:
        return metadata.version(package)
    except metadata.PackageNotFoundError:
        return "unknown"


#: The process-wide backend registry.
backends = BackendRegistry()
backends.register("sim", _open_sim, simulated=True, validate=_no_arguments("sim"))
backends.register("emulator", _open_emulator, simulated=True,
                  validate=_no_arguments("emulator"))
backends.register("serial", _open_serial,
                  needs_args="serial:URL, e.g. serial:/dev/ttyUSB0 or serial:socket://HOST:PORT",
                  validate=serial_url)
def _gcs_options(args: str) -> object:
    from hexapod.backends.gcs_config import GcsOptions

    return GcsOptions.parse(args)


def _gcs_emulator_options(args: str) -> object:
    from hexapod.backends.gcs_emulated import parse_spec

    return parse_spec(args)


backends.register("gcs", _open_gcs,
                  needs_args="gcs:tcp://HOST:PORT or gcs:serial:URL (a PI GCS hexapod "
                             "controller), e.g. gcs:tcp://192.168.0.10:50000",
                  validate=_gcs_options)
backends.register("gcs-emulator", _open_gcs_emulator, simulated=True,
                  validate=_gcs_emulator_options)


def open_backend(spec: str, geometry: HexapodGeometry,
                 start: np.ndarray | None = None) -> Backend:
    """Open a backend from a ``--backend`` spec (:meth:`BackendRegistry.open`)."""
    return backends.open(spec, geometry, start)
