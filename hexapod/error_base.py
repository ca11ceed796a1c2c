"""The base of the project's error classes: how an error crosses a process boundary.

A study runs its trials in worker processes (a process pool, Dask), which send an error
raised there back pickled. Python's default pickle of an exception calls
``cls(*exc.args)``, the formatted message, which an ``__init__`` of other parameters (the
file, the key, the leg) refuses: the pool breaks instead of reporting the error.
:class:`PicklableError` rebuilds the error from its message and attributes instead.
"""

from __future__ import annotations

__all__ = ["PicklableError"]


def _rebuilt(cls: type[BaseException], args: tuple[object, ...],
             state: dict[str, object]) -> BaseException:
    """An exception of ``cls`` with its ``args`` and attributes, without calling its
    ``__init__`` (whose parameters are not its message: the pickle of a worker's error)."""
    exc = cls.__new__(cls, *args)
    BaseException.__init__(exc, *args)
    exc.__dict__.update(state)
    return exc


class PicklableError(Exception):
    """Base of the project's error bases: an error raised in a worker process (a process
    pool, Dask) crosses back whole, its message and attributes, whatever its
    ``__init__`` takes (the default pickle calls ``cls(*args)`` with the formatted
    message, which such an ``__init__`` refuses, breaking the pool)."""

    def __reduce__(self) -> tuple[object, ...]:
        return (_rebuilt, (type(self), self.args, dict(self.__dict__)))
