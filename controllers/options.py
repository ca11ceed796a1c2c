"""Controllers that remember the options they were built with.

A batched law steps each trial with its own instance of the law (the rows its compiled
core cannot finish); those instances are built from the options of the batch's own
instance, never copied from it (a copy would carry whatever state it holds).
"""

from __future__ import annotations

from collections.abc import Iterable
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

    def clones_reset(self: T, contexts: Iterable[Any]) -> list[T]:
        """One :meth:`clone` per context, reset with it (the trials of a batch)."""
        out = []
        for ctx in contexts:
            inst = self.clone()
            inst.reset(ctx)  # type: ignore[attr-defined]
            out.append(inst)
        return out
