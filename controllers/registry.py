"""The controller registry: built-ins, entry-point plugins and ``module:attr`` specs.

Register a third-party controller through the entry-point group
``hexapod.controllers`` of its distribution::

    [project.entry-points."hexapod.controllers"]
    my-law = "my_package.my_module:MyController"

The object an entry point names is a *factory*: a callable taking keyword
options and returning a :class:`~controllers.base.Controller` (a subclass is
one). On the command line, ``module:attr`` names a factory directly.
"""

from __future__ import annotations

import importlib
import importlib.metadata as metadata
import inspect
import logging
from collections.abc import Callable
from contextvars import ContextVar
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from controllers.exceptions import OptionError, PluginLoadError, UnknownControllerError
from controllers.options import OptionTable, first_sentence, option_table
from hexapod.config import suggest
from hexapod.exceptions import UnsafeNameError
from hexapod.outputs import check_name

if TYPE_CHECKING:
    from controllers.base import Controller

log = logging.getLogger(__name__)

ENTRY_POINT_GROUP = "hexapod.controllers"

ControllerFactory = Callable[..., "Controller"]

#: Calls of :meth:`Registry.create` under way in this thread (a wrapper's factory builds
#: its law by name: 2).
_CREATING: ContextVar[int] = ContextVar("_CREATING", default=0)


@dataclass(frozen=True)
class ControllerInfo:
    """A registered controller and where it comes from.

    Attributes:
        name: Registry name.
        package: Distribution that provides it.
        version: Version of that distribution.
        description: First sentence of the factory's docstring.
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
        #: Names registered by ``module:attr``, not imported yet: ``(spec, package)``.
        self._lazy: dict[str, tuple[str, str]] = {}
        self.errors: list[PluginLoadError] = []
        self._plugins_loaded = False

    def register(self, name: str, factory: ControllerFactory, package: str = "hexapod-vs",
                 version: str | None = None) -> None:
        """Register a controller factory under ``name``.

        Raises:
            PluginLoadError: ``name`` breaks :func:`hexapod.outputs.check_name` (it
                becomes part of file names: the recorded trials).
        """
        _check_name(name, package)
        if version is None:
            version = _distribution_version(package)
        self._factories[name] = factory
        self._info[name] = ControllerInfo(name, package, version, describe(factory))

    def register_lazy(self, name: str, spec: str, package: str = "hexapod-vs") -> None:
        """Register the factory ``spec`` (``"module:attr"``) under ``name`` without
        importing its module: it is imported when ``name`` is first used
        (:meth:`factory`, :meth:`create`, :meth:`options`, :meth:`info`).

        Raises:
            PluginLoadError: ``name`` breaks :func:`hexapod.outputs.check_name`, or
                ``spec`` is not ``module:attr``.
        """
        _check_name(name, package)
        module, _, attr = spec.partition(":")
        if not module or not attr:
            raise PluginLoadError(name, package, f"{spec!r} is not 'module:attr'")
        self._lazy[name] = (spec, package)

    def _resolve(self, name: str) -> ControllerFactory:
        """The factory of a name registered by :meth:`register_lazy`, imported now and
        registered (kept in the lazy table: a caller that restores the registry's tables
        gets it imported again, from the module cache).

        Raises:
            PluginLoadError: Its module does not import, or has no such attribute, or
                the attribute is not callable (names the controller and the spec).
        """
        spec, package = self._lazy[name]
        obj = _import_spec(spec, name, package)
        self.register(name, obj, package)
        return obj

    def load_plugins(self, force: bool = False) -> None:
        """Load the entry points of the ``hexapod.controllers`` group."""
        if self._plugins_loaded and not force:
            return
        self._plugins_loaded = True
        for ep in metadata.entry_points(group=ENTRY_POINT_GROUP):
            dist = ep.dist.name if ep.dist is not None else "unknown"
            version = ep.dist.version if ep.dist is not None else "unknown"
            registered = (self._info[ep.name].package if ep.name in self._info
                          else self._lazy.get(ep.name, ("", None))[1])
            if registered == dist:
                continue
            if registered:  # another package's name: the plugin does not replace it
                err = PluginLoadError(ep.name, dist, f"the name is taken by {registered}'s "
                                      f"controller, which stays: give the entry point "
                                      f"{ep.value} another name")
                log.warning("%s", err)
                self.errors.append(err)
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
        return sorted(self._factories.keys() | self._lazy.keys())

    def info(self) -> list[ControllerInfo]:
        """Every registered controller with its package and version (imports the
        modules of the built-ins not used yet: their descriptions are their docstrings)."""
        self.load_plugins()
        for name in self._lazy.keys() - self._factories.keys():
            self._resolve(name)
        return [self._info[n] for n in sorted(self._info)]

    def factory(self, name: str) -> ControllerFactory:
        """The factory of ``name`` or of a ``module:attr`` spec."""
        self.load_plugins()
        if name in self._factories:
            return self._factories[name]
        if name in self._lazy:
            return self._resolve(name)
        if ":" in name:
            obj = _import_spec(name, name, "command line")
            package, version = _module_distribution(name.partition(":")[0])
            own = getattr(obj, "name", None)
            if (isinstance(own, str) and own != name
                    and own in (self._factories.keys() | self._lazy.keys())
                    and self.factory(own) is not obj):  # (the built-in by its path: fine)
                log.warning("%s: its class's name %r is another controller's: messages and "
                            "records of its own checks will say %r; give it a name of its "
                            "own", name, own, own)
            self.register(name, obj, package, version)
            return obj
        known = sorted(self._factories.keys() | self._lazy.keys())
        raise UnknownControllerError(name, known, suggest(name, known))

    def create(self, name: str, **options: Any) -> Controller:
        """Instantiate a controller by name with its options.

        Raises:
            UnknownControllerError: No controller of that name.
            OptionError: An option the controller's table (:meth:`options`) does not
                declare and its factory refuses (naming the controller, the option, its
                options and the close one); a factory that hands further options on (an
                open table), and a law a wrapper builds, raise their own error.
            PluginLoadError: The factory is not a controller class or returned no
                controller.
        """
        from controllers.base import Controller  # base imports this module

        factory = self.factory(name)
        if (isinstance(factory, type) and not issubclass(factory, Controller)
                and not all(callable(getattr(factory, a, None)) for a in ("reset", "step"))):
            raise PluginLoadError(name, self._info[name].package,
                                  f"{factory.__qualname__} is not a controller class (a "
                                  "controllers.base.Controller, or a class with reset() and "
                                  "step()), nor a function that makes one")
        depth = _CREATING.set(_CREATING.get() + 1)
        try:
            ctrl = factory(**options)
        except TypeError as exc:
            # a wrapper's law built inside the wrapper's factory (latency-compensated):
            # its error stays the wrapper's to report (scenario checks name the wrapper)
            unknown = None if _CREATING.get() > 1 else self._refused_option(name, options, exc)
            if unknown is None:
                raise
            raise unknown from None
        finally:
            _CREATING.reset(depth)
        if not isinstance(ctrl, Controller):
            for attr in ("reset", "step"):
                if not callable(getattr(ctrl, attr, None)):
                    raise PluginLoadError(name, self._info[name].package,
                                          f"the factory returned an object without {attr}()")
        return ctrl

    def _refused_option(self, name: str, options: dict[str, Any], exc: TypeError
                        ) -> OptionError | None:
        """The :class:`OptionError` of an option the factory of ``name`` refused with
        ``exc`` (Python's "unexpected keyword argument") and its table does not declare;
        None when ``exc`` is another error or the table is open (only on failure: the
        table is read from docstrings, too slow for every :meth:`create`)."""
        text = str(exc)
        refused = [o for o in options if f"unexpected keyword argument '{o}'" in text]
        if not refused:
            return None
        try:
            table = self.options(name)
        except Exception:  # a table that cannot be read: the factory's own error
            return None
        if table.open or table.declares(refused[0]):
            return None
        hint = suggest(refused[0], table.names)
        return OptionError(name, refused[0], "no such option; its options: "
                           f"{', '.join(table.names) or 'none'}"
                           + (f" (did you mean '{hint}'?)" if hint else ""))

    def options(self, name: str) -> OptionTable:
        """The options ``name`` declares (:func:`controllers.options.option_table`): what
        the scenario checks accept and ``hexapod-bench list --options`` prints."""
        return option_table(self.factory(name))

    def source(self, name: str) -> ControllerInfo:
        """Package and version of a registered controller."""
        self.factory(name)
        return self._info[name]


def _check_name(name: str, package: str) -> None:
    try:
        check_name(name, "controller name")
    except UnsafeNameError as exc:
        raise PluginLoadError(str(name), package, exc.problem) from None


def _import_spec(spec: str, name: str, source: str) -> ControllerFactory:
    """The callable a ``module:attr`` spec names (``attr`` may be dotted).

    Raises:
        PluginLoadError: The module does not import, has no such attribute, or the
            attribute is not callable (names the controller ``name``, ``source`` and
            the spec).
    """
    module, _, attr = spec.partition(":")
    try:
        obj: Any = importlib.import_module(module)
        for part in attr.split("."):
            obj = getattr(obj, part)
    except Exception as exc:  # whatever the plugin's module raises while it imports (a
        # typo, an abstract class built at import, a SyntaxError): one line
        raise PluginLoadError(name, source, f"{spec}: {type(exc).__name__}: {exc}"
                              ) from exc
    if not callable(obj):
        raise PluginLoadError(name, source, f"{spec} is not callable")
    return obj  # type: ignore[no-any-return]


def describe(factory: Any) -> str:
    """The first sentence of a factory's docstring, whole (its first paragraph may span
    several lines)."""
    doc = inspect.cleandoc(getattr(factory, "__doc__", None) or "")
    paragraph = " ".join(doc.split("\n\n")[0].split())
    return first_sentence(paragraph)


def _module_distribution(module: str) -> tuple[str, str]:
    """The installed distribution that provides ``module`` and its version (its import
    name and "unknown" when no installed distribution provides it: a file on the path)."""
    top = module.split(".")[0]
    for dist in metadata.packages_distributions().get(top, []):
        try:
            return dist, metadata.version(dist)
        except metadata.PackageNotFoundError:
            continue
    return top, _distribution_version(top)


def _distribution_version(package: str) -> str:
    try:
        return metadata.version(package)
    except metadata.PackageNotFoundError:
        return "unknown"


#: The process-wide registry (built-ins are added by :mod:`controllers`).
registry = Registry()
