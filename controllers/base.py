"""The controller plugin interface: observations, context, commands, registry.

A controller sees only what a real robot and camera give (an
:class:`Observation`) and what the user knows or calibrated (a
:class:`ControllerContext`); it never sees the simulator's true state.

Register a third-party controller through the entry-point group
``hexapod.controllers`` of its distribution::

    [project.entry-points."hexapod.controllers"]
    my-law = "my_package.my_module:MyController"

The object an entry point names is a *factory*: a callable taking keyword
options and returning a :class:`Controller` (a :class:`Controller` subclass is
one). On the command line, ``module:attr`` names a factory directly.
"""

from __future__ import annotations

import importlib
import importlib.metadata as metadata
import logging
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from controllers.exceptions import PluginLoadError, UnknownControllerError
from hexapod.actuation import Actuation
from hexapod.config import suggest
from hexapod.exceptions import UnsafeNameError
from hexapod.geometry import HexapodGeometry
from hexapod.outputs import check_name

log = logging.getLogger(__name__)

ENTRY_POINT_GROUP = "hexapod.controllers"

#: Feature names a controller may declare in ``Controller.features``.
FEATURES = ("lengths", "normals", "lines", "directions")


@dataclass
class Observation:
    """What the robot and the camera measured at one instant.

    All vectors are in the camera frame. Hidden features are NaN and flagged
    False in the masks.

    Attributes:
        t: Time [s].
        lengths: (6,) measured leg lengths (encoders, offsets included) [m].
        normals: (6, 2, 3) unit edge normals (interpretation planes), computed with
            the estimated intrinsics; None when the sensor gives none.
        lines: (6, 2, 3) unit image lines in normalised pixel coordinates
            (perspective camera only), else None.
        directions: (6, 3) unit leg directions, else None.
        edge_visible: (6, 2) bool, which edges were observed.
        direction_visible: (6,) bool, which directions were observed.
        quality: Optional per-edge quality (e.g. fit residual), (6, 2).
        image_t: Capture time of the image the features come from [s] (None: taken at
            ``t``); older than ``t`` by the camera's latency and frame period
            (:mod:`benchmarks.sim.clock`).
        q_dot: (6,) measured leg velocities [m/s], or None when the robot gives none
            (a kinematic world does not; force laws need them).
    """

    t: float
    lengths: np.ndarray
    normals: np.ndarray | None = None
    lines: np.ndarray | None = None
    directions: np.ndarray | None = None
    edge_visible: np.ndarray = field(default_factory=lambda: np.ones((6, 2), dtype=bool))
    direction_visible: np.ndarray = field(default_factory=lambda: np.ones(6, dtype=bool))
    quality: np.ndarray | None = None
    image_t: float | None = None
    q_dot: np.ndarray | None = None


@dataclass
class Goal:
    """The desired configuration, as features and (for the baselines) as a pose.

    Attributes:
        normals: (6, 2, 3) desired edge normals (from the image at the goal).
        lines: (6, 2, 3) desired image lines (perspective camera).
        directions: (6, 3) desired leg directions.
        lengths: (6,) desired leg lengths in the nominal model [m].
        rotation: (3, 3) desired platform orientation in the nominal base frame.
        translation: (3,) desired platform position in the nominal base frame [m].
        edge_visible: (6, 2) which desired edges were observed.
    """

    normals: np.ndarray | None = None
    lines: np.ndarray | None = None
    directions: np.ndarray | None = None
    lengths: np.ndarray | None = None
    rotation: np.ndarray | None = None
    translation: np.ndarray | None = None
    edge_visible: np.ndarray | None = None


@dataclass
class ControllerContext:
    """What the user knows or calibrated (estimates, never the truth).

    Attributes:
        base_points: (6, 3) estimated base points ``A_i`` in the camera frame [m].
        geometry: Nominal geometry (base frame), with strokes and speed limit.
        camera: The estimated camera (intrinsics and ``camera_from_base``), or None.
        dt: Control period [s].
        goal: The desired features / pose.
        stroke_margin: Distance kept from the stroke limits by limit-aware laws [m].
        reference: A trajectory task's reference (a
            :class:`hexapod.trajectory.PoseTrajectory` in the base frame: pose, twist and
            acceleration at any time), or None for a fixed goal
            (:mod:`controllers.tracking`).
    """

    base_points: np.ndarray
    geometry: HexapodGeometry
    camera: Any
    dt: float
    goal: Goal
    stroke_margin: float = 0.002
    reference: Any = None

    @property
    def stroke(self) -> tuple[float, float]:
        """(q_min, q_max) [m]."""
        return self.geometry.stroke

    @property
    def max_speed(self) -> float:
        """Leg speed limit [m/s]."""
        return self.geometry.max_speed


@dataclass
class Command:
    """A controller's output for one step, with its diagnostics.

    What it commands is :attr:`actuation`: leg velocities (the default; ``velocities``)
    or leg forces (``forces``, with ``velocities`` zeros); build a force command with
    :meth:`of_forces`. :attr:`values` is the command of its kind.

    Attributes:
        velocities: (6,) leg velocity command [m/s]; zeros when the controller refuses
            or commands forces.
        twist: (6,) platform twist ``(v, w)`` in the camera frame, if the law computes one.
        error: The stacked task error.
        error_norm: Its Euclidean norm.
        rank: Rank of the (stacked) interaction matrix.
        condition: Its condition number.
        features_used: Number of scalar feature rows used.
        active_constraints: Names of the active constraints (QP laws).
        reason: Why the command is zero (None when the command is valid).
        notes: Other diagnostics (e.g. "using 10 of 12 edges").
        actuation: What the command sets (:class:`~hexapod.actuation.Actuation`).
        forces: (6,) leg force command [N] of a force command (zeros when refused),
            else None.
    """

    velocities: np.ndarray
    twist: np.ndarray | None = None
    error: np.ndarray = field(default_factory=lambda: np.zeros(0))
    error_norm: float = 0.0
    rank: int = 0
    condition: float = float("nan")
    features_used: int = 0
    active_constraints: list[str] = field(default_factory=list)
    reason: str | None = None
    notes: list[str] = field(default_factory=list)
    actuation: Actuation = Actuation.VELOCITY
    forces: np.ndarray | None = None

    @property
    def ok(self) -> bool:
        """True when the controller produced a movement command."""
        return self.reason is None

    @property
    def values(self) -> np.ndarray:
        """(6,) the command of its kind, velocities [m/s] or forces [N]."""
        if self.actuation is Actuation.FORCE:
            return np.zeros(6) if self.forces is None else self.forces
        return self.velocities

    @staticmethod
    def of_forces(forces: np.ndarray, **diagnostics: Any) -> Command:
        """A leg-force command [N] (``velocities`` zeros), with its diagnostics."""
        return Command(np.zeros(6), actuation=Actuation.FORCE,
                       forces=np.asarray(forces, dtype=float), **diagnostics)

    @staticmethod
    def refuse(reason: str, error: np.ndarray | None = None,
               actuation: Actuation = Actuation.VELOCITY) -> Command:
        """A zero command with its reason (never NaN)."""
        err = np.zeros(0) if error is None else np.nan_to_num(error)
        return Command(np.zeros(6), reason=reason, error=err,
                       error_norm=float(np.linalg.norm(err)), actuation=actuation,
                       forces=np.zeros(6) if actuation is Actuation.FORCE else None)


@dataclass
class ObservationBatch:
    """Observations of several trials at one period: :class:`Observation` fields with a
    leading trial axis (n, ...), for :meth:`Controller.step_batch`.

    Attributes:
        trials: (n,) indices of the trials, into the contexts given to ``reset_batch``.
        t: (n,) times [s].
        lengths: (n, 6) measured leg lengths [m].
        normals: (n, 6, 2, 3) or None.
        lines: (n, 6, 2, 3) or None.
        directions: (n, 6, 3) or None.
        edge_visible: (n, 6, 2) bool.
        direction_visible: (n, 6) bool.
        image_t: (n,) capture times of the images [s], or None (taken at ``t``).
        q_dot: (n, 6) measured leg velocities [m/s], or None.
    """

    trials: np.ndarray
    t: np.ndarray
    lengths: np.ndarray
    normals: np.ndarray | None
    lines: np.ndarray | None
    directions: np.ndarray | None
    edge_visible: np.ndarray
    direction_visible: np.ndarray
    image_t: np.ndarray | None = None
    q_dot: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.trials)

    def item(self, k: int) -> Observation:
        """The observation of row ``k`` (views of the batch arrays)."""
        return Observation(
            t=float(self.t[k]), lengths=self.lengths[k],
            normals=None if self.normals is None else self.normals[k],
            lines=None if self.lines is None else self.lines[k],
            directions=None if self.directions is None else self.directions[k],
            edge_visible=self.edge_visible[k], direction_visible=self.direction_visible[k],
            image_t=None if self.image_t is None else float(self.image_t[k]),
            q_dot=None if self.q_dot is None else self.q_dot[k])


@dataclass
class CommandBatch:
    """The commands of :meth:`Controller.step_batch`, one row per observation row.

    Attributes:
        velocities: (n, 6) leg velocities [m/s] (zeros where refused or for forces;
            never NaN).
        error_norm: (n,) norm of each task error.
        reasons: (n,) why a command is zero (None where it is valid).
        actuation: What every row commands (one kind per batch).
        forces: (n, 6) leg forces [N] of a force batch (zeros where refused), else None.
    """

    velocities: np.ndarray
    error_norm: np.ndarray
    reasons: list[str | None]
    actuation: Actuation = Actuation.VELOCITY
    forces: np.ndarray | None = None

    @property
    def values(self) -> np.ndarray:
        """(n, 6) the commands of their kind, velocities [m/s] or forces [N]."""
        if self.actuation is Actuation.FORCE:
            return np.zeros_like(self.velocities) if self.forces is None else self.forces
        return self.velocities

    @property
    def ok(self) -> np.ndarray:
        """(n,) True where the controller produced a movement command."""
        return np.array([r is None for r in self.reasons], dtype=bool)

    @staticmethod
    def zeros(n: int, actuation: Actuation = Actuation.VELOCITY) -> CommandBatch:
        """``n`` rows of zero commands, zero norms and no reasons, to be filled."""
        forces = np.zeros((n, 6)) if actuation is Actuation.FORCE else None
        return CommandBatch(np.zeros((n, 6)), np.zeros(n), [None] * n, actuation, forces)

    def put(self, k: int, command: Command) -> None:
        """Set row ``k`` to a per-trial :class:`Command` (of the batch's actuation).

        Raises:
            ActuationError: The command is of another kind than the batch.
        """
        if command.actuation is not self.actuation:
            from hexapod.actuation import check_actuation

            check_actuation(command.actuation, (self.actuation,),
                            f"a batch of {self.actuation.quantity}", "row " + str(k))
        self.velocities[k] = command.velocities
        if self.forces is not None:
            self.forces[k] = command.values
        self.error_norm[k] = command.error_norm
        self.reasons[k] = command.reason

    @staticmethod
    def from_commands(commands: list[Command]) -> CommandBatch:
        """Stack per-trial :class:`Command` objects (all of one actuation)."""
        kind = commands[0].actuation if commands else Actuation.VELOCITY
        out = CommandBatch.zeros(len(commands), kind)
        for k, c in enumerate(commands):
            out.put(k, c)
        return out


class Controller(ABC):
    """A controller: ``reset(context)`` once, then ``step(observation)`` every period.

    Subclasses set ``name`` and ``features`` (subset of :data:`FEATURES`), say what
    they command in ``actuation`` (leg velocities unless set to
    :attr:`~hexapod.actuation.Actuation.FORCE`) and implement :meth:`reset` and
    :meth:`step`. A class is its own factory: its
    constructor takes the options as keyword arguments.

    A controller may also step many trials at once (the study engine calls it when
    it can): ``reset_batch(contexts)`` prepares one trial per context and
    ``step_batch(observations)`` (an :class:`ObservationBatch`) returns a
    :class:`CommandBatch`. Both are optional; without them the engine builds one
    controller per trial and calls ``step`` in a loop (``docs/plugins.md``).
    """

    #: Registry name.
    name: str = "controller"
    #: Observation fields the controller needs.
    features: frozenset[str] = frozenset({"lengths"})
    #: What the commands set: leg velocities [m/s] (default) or leg forces [N].
    actuation: Actuation = Actuation.VELOCITY

    @abstractmethod
    def reset(self, context: ControllerContext) -> None:
        """Prepare for a new run with the estimated parameters and the goal."""

    @abstractmethod
    def step(self, observation: Observation) -> Command:
        """Compute the command for one observation (never raises for bad measurements)."""


ControllerFactory = Callable[..., Controller]


@dataclass(frozen=True)
class ControllerInfo:
    """A registered controller and where it comes from.

    Attributes:
        name: Registry name.
        package: Distribution that provides it.
        version: Version of that distribution.
        description: First line of the factory's docstring.
    """

    name: str
    package: str
    version: str
    description: str


class Registry:
    """Controllers by name: built-ins, entry-point plugins and ``module:attr`` specs.

    Entry points of the group ``hexapod.controllers`` are loaded lazily, once; a
    plugin that fails to import is recorded in :attr:`errors` and the others
    remain usable.
    """

    def __init__(self) -> None:
        self._factories: dict[str, ControllerFactory] = {}
        self._info: dict[str, ControllerInfo] = {}
        self.errors: list[PluginLoadError] = []
        self._plugins_loaded = False

    def register(self, name: str, factory: ControllerFactory, package: str = "hexapod-vs",
                 version: str | None = None) -> None:
        """Register a controller factory under ``name``.

        Raises:
            PluginLoadError: ``name`` breaks :func:`hexapod.outputs.check_name` (it
                becomes part of file names: the recorded trials).
        """
        try:
            check_name(name, "controller name")
        except UnsafeNameError as exc:
            raise PluginLoadError(str(name), package, exc.problem) from None
        if version is None:
            version = _distribution_version(package)
        doc = (getattr(factory, "__doc__", None) or "").strip().splitlines()
        self._factories[name] = factory
        self._info[name] = ControllerInfo(name, package, version, doc[0] if doc else "")

    def load_plugins(self, force: bool = False) -> None:
        """Load the entry points of the ``hexapod.controllers`` group."""
        if self._plugins_loaded and not force:
            return
        self._plugins_loaded = True
        for ep in metadata.entry_points(group=ENTRY_POINT_GROUP):
            dist = ep.dist.name if ep.dist is not None else "unknown"
            version = ep.dist.version if ep.dist is not None else "unknown"
            if ep.name in self._factories and self._info[ep.name].package == dist:
                continue
            try:
                factory = ep.load()
            except Exception as exc:  # a broken plugin must not break the others
                err = PluginLoadError(ep.name, dist, f"{type(exc).__name__}: {exc}")
                log.warning("%s", err)
                self.errors.append(err)
                continue
            if not callable(factory):
                err = PluginLoadError(ep.name, dist, f"{ep.value} is not callable")
                self.errors.append(err)
                continue
            try:
                self.register(ep.name, factory, dist, version)
            except PluginLoadError as err:
                log.warning("%s", err)
                self.errors.append(err)

    def names(self) -> list[str]:
        """Registered names (plugins included), sorted."""
        self.load_plugins()
        return sorted(self._factories)

    def info(self) -> list[ControllerInfo]:
        """Every registered controller with its package and version."""
        self.load_plugins()
        return [self._info[n] for n in sorted(self._info)]

    def factory(self, name: str) -> ControllerFactory:
        """The factory of ``name`` or of a ``module:attr`` spec."""
        self.load_plugins()
        if name in self._factories:
            return self._factories[name]
        if ":" in name:
            module, _, attr = name.partition(":")
            try:
                obj: Any = importlib.import_module(module)
                for part in attr.split("."):
                    obj = getattr(obj, part)
            except (ImportError, AttributeError) as exc:
                raise PluginLoadError(name, "command line", f"{type(exc).__name__}: {exc}"
                                      ) from None
            if not callable(obj):
                raise PluginLoadError(name, "command line", "not callable")
            package = module.split(".")[0]
            self.register(name, obj, package, _distribution_version(package))
            return obj
        raise UnknownControllerError(name, list(self._factories), suggest(name,
                                                                         self._factories))

    def create(self, name: str, **options: Any) -> Controller:
        """Instantiate a controller by name with its options."""
        factory = self.factory(name)
        ctrl = factory(**options)
        if not isinstance(ctrl, Controller):
            for attr in ("reset", "step"):
                if not callable(getattr(ctrl, attr, None)):
                    raise PluginLoadError(name, self._info[name].package,
                                          f"the factory returned an object without {attr}()")
        return ctrl

    def source(self, name: str) -> ControllerInfo:
        """Package and version of a registered controller."""
        self.factory(name)
        return self._info[name]


def _distribution_version(package: str) -> str:
    try:
        return metadata.version(package)
    except metadata.PackageNotFoundError:
        return "unknown"


#: The process-wide registry (built-ins are added by :mod:`controllers`).
registry = Registry()


def observation_problem(obs: Observation, features: frozenset[str]) -> str | None:
    """Return why an observation cannot be used (None if it can).

    Checks that the needed fields exist with the right shapes, and that every
    value flagged visible is finite.
    """
    q = np.asarray(obs.lengths, dtype=float)
    if q.shape != (6,):
        return f"lengths: expected 6 values, got shape {q.shape}"
    bad = np.flatnonzero(~np.isfinite(q))
    if len(bad):
        return f"lengths: leg {int(bad[0])} is {q[bad[0]]} (not finite)"
    if not np.isfinite(obs.t):
        return f"time is {obs.t} (not finite)"
    for name, shape, mask in (("normals", (6, 2, 3), obs.edge_visible),
                              ("lines", (6, 2, 3), obs.edge_visible),
                              ("directions", (6, 3), obs.direction_visible)):
        if name not in features:
            continue
        value = getattr(obs, name)
        if value is None:
            return f"{name}: not measured by this sensor"
        arr = np.asarray(value, dtype=float)
        if arr.shape != shape:
            return f"{name}: expected shape {shape}, got {arr.shape}"
        m = np.asarray(mask, dtype=bool)
        finite = np.all(np.isfinite(arr), axis=-1)
        bad_idx = np.argwhere(m & ~finite)
        if len(bad_idx):
            return f"{name}: visible feature {tuple(int(x) for x in bad_idx[0])} is not finite"
    return None


def usable_observation_problem(obs: Observation, features: frozenset[str]) -> str | None:
    """:func:`observation_problem`, with a malformed observation (wrong types) reported as
    a reason too: what every controller's ``step`` checks before computing."""
    try:
        return observation_problem(obs, features)
    except (TypeError, ValueError) as exc:
        return f"malformed observation: {exc}"
