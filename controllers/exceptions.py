"""Exceptions of the :mod:`controllers` package."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

from hexapod.error_base import PicklableError


class ControllerError(PicklableError):
    """Base class of every error raised by :mod:`controllers`."""


class UnknownControllerError(ControllerError, KeyError):
    """No controller is registered under this name.

    Attributes:
        name: The requested name.
        available: Registered names.
        suggestion: The closest registered name, if any.
    """

    def __init__(self, name: str, available: list[str], suggestion: str | None) -> None:
        self.name = name
        self.available = available
        self.suggestion = suggestion
        msg = f"unknown controller '{name}'; available: {', '.join(sorted(available))}"
        if suggestion:
            msg += f" (did you mean '{suggestion}'?)"
        super().__init__(msg)

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0])


class PluginLoadError(ControllerError):
    """A controller plugin could not be imported or is not a controller factory.

    Attributes:
        name: Entry-point name or ``module:attr`` spec.
        source: Where it came from (distribution name or "command line").
        reason: The underlying error, as text.
    """

    def __init__(self, name: str, source: str, reason: str) -> None:
        self.name = name
        self.source = source
        self.reason = reason
        super().__init__(f"controller plugin '{name}' from {source} failed to load: {reason}")


class NamedInputError(ControllerError, ValueError):
    """A named input of a controller (a context field, an option) is missing or bad: the
    message is ``"<controller>: <what> '<name>': <problem>"``.

    Attributes:
        controller: The controller name.
        problem: What is wrong.
    """

    #: What the input is, in the message.
    what = "input"

    def __init__(self, controller: str, name: str, problem: str) -> None:
        self.controller = controller
        self.problem = problem
        super().__init__(f"{controller}: {self.what} '{name}': {problem}")


class ContextError(NamedInputError):
    """A controller context lacks what the controller needs, or holds bad values
    (:class:`NamedInputError`; ``field``: the missing or invalid field)."""

    what = "context field"

    def __init__(self, controller: str, field: str, problem: str) -> None:
        self.field = field
        super().__init__(controller, field, problem)


class OptionError(NamedInputError):
    """An option given to a controller is unknown or out of range
    (:class:`NamedInputError`; ``option``: the option)."""

    what = "option"

    def __init__(self, controller: str, option: str, problem: str) -> None:
        self.option = option
        super().__init__(controller, option, problem)


class CommandError(ControllerError, ValueError):
    """A controller returned a command of the wrong shape or kind.

    Attributes:
        controller: The controller name.
        problem: What is wrong (the shapes or kinds, given and expected).
    """

    def __init__(self, controller: str, problem: str) -> None:
        self.controller = controller
        self.problem = problem
        super().__init__(f"controller '{controller}' {problem}")


@contextmanager
def named_as(controller: str) -> Iterator[None]:
    """Raise a held law's :class:`ContextError` or :class:`OptionError` as the holder's,
    ``controller`` (a predictive controller builds, resets and retargets the law it
    holds: a bad goal or option is the predictive controller's to name; ``leg-edge-mpc``
    with ``gain=0`` said "leg-edge-qp: option 'gain'", a law the user never named)."""
    try:
        yield
    except ContextError as exc:
        if exc.controller == controller:
            raise
        raise ContextError(controller, exc.field, exc.problem) from None
    except OptionError as exc:
        if exc.controller == controller:
            raise
        raise OptionError(controller, exc.option, exc.problem) from None
