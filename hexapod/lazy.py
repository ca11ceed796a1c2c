"""Names of a package imported on first use (PEP 562): a package re-exports classes of
heavy modules (CasADi's MPC, Pinocchio's model, OSQP) without importing them until one is
used.

In a package's ``__init__.py``::

    __getattr__ = lazy_names(__name__, {"HexapodViewer": "hexapod.visualize.viewer"},
                             globals())
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from importlib import import_module
from importlib.util import find_spec
from typing import Any


def lazy_names(package: str, modules: Mapping[str, str], namespace: dict[str, Any]
               ) -> Callable[[str], Any]:
    """A module ``__getattr__`` for ``package``: a name of ``modules`` (name -> module)
    is imported from its module on first access and kept in ``namespace`` (the package's
    globals); any other name is the package's submodule of that name, imported now (as if
    the package had imported every submodule).

    Raises (from the returned function):
        AttributeError: The name is neither a lazy name nor a submodule.
    """

    def attribute(name: str) -> Any:
        module = modules.get(name)
        if module is not None:
            value = getattr(import_module(module), name)
        elif not name.startswith("_") and find_spec(f"{package}.{name}") is not None:
            value = import_module(f"{package}.{name}")
        else:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        namespace[name] = value
        return value

    return attribute
