"""Exceptions of the :mod:`controllers` package."""

from __future__ import annotations


class ControllerError(Exception):
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


class ContextError(ControllerError, ValueError):
    """A controller context lacks what the controller needs, or holds bad values.

    Attributes:
        controller: The controller name.
        field: The missing or invalid field.
        problem: What is wrong.
    """

    def __init__(self, controller: str, field: str, problem: str) -> None:
        self.controller = controller
        self.field = field
        self.problem = problem
        super().__init__(f"{controller}: context field '{field}': {problem}")


class OptionError(ControllerError, ValueError):
    """An option given to a controller is unknown or out of range.

    Attributes:
        controller: The controller name.
        option: The option.
        problem: What is wrong.
    """

    def __init__(self, controller: str, option: str, problem: str) -> None:
        self.controller = controller
        self.option = option
        self.problem = problem
        super().__init__(f"{controller}: option '{option}': {problem}")


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
