"""Controllers that remember the options they were built with.

A controller steps each trial of a batch with its own instance where it computes no
rows as arrays (:class:`controllers.base.Controller`); those instances are built from the
options of the batch's own instance, never copied from it (a copy would carry whatever
state it holds).
"""

from __future__ import annotations

from typing import Any, TypeVar

T = TypeVar("T", bound="RemembersOptions")


class RemembersOptions:
    """Records the constructor's arguments; :meth:`clone` builds an un-reset twin."""

    _options: tuple[tuple[Any, ...], dict[str, Any]]

    def __new__(cls, *args: Any, **kwargs: Any) -> Any:
        obj = super().__new__(cls)
        obj._options = (args, dict(kwargs))
        return obj

    @property
    def options(self) -> dict[str, Any]:
        """The keyword options given to the constructor (positional ones not included)."""
        return dict(self._options[1])

    def clone(self: T) -> T:
        """A new instance with the same options, not reset."""
        args, kwargs = self._options
        return type(self)(*args, **kwargs)
