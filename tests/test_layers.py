"""The packages import one way, ``hexapod`` <- ``vision`` <- ``controllers`` <-
``benchmarks`` (docs/architecture.md): no module of a package names a package above it
in any import statement, at module level, inside a function or under
``TYPE_CHECKING`` (a deferred import is still a dependency)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
ORDER = ("hexapod", "vision", "controllers", "benchmarks")


def imported(path: Path) -> list[tuple[int, str]]:
    """Every absolute module name an import statement of ``path`` names, with its line."""
    out: list[tuple[int, str]] = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            out.append((node.lineno, node.module))
    return out


def upward(package: str) -> list[str]:
    """``file:line module`` of every import of ``package`` that names a package above it."""
    above = set(ORDER[ORDER.index(package) + 1:])
    return [f"{path.relative_to(ROOT)}:{line} imports {name}"
            for path in sorted((ROOT / package).rglob("*.py"))
            for line, name in imported(path) if name.split(".")[0] in above]


@pytest.mark.parametrize("package", ORDER[:-1])
def test_no_package_imports_one_above_it(package: str) -> None:
    assert (ROOT / package / "__init__.py").is_file()
    assert upward(package) == []


def test_the_check_sees_an_upward_import(tmp_path: Path) -> None:
    """The scan finds the import forms it must refuse (a deferred one included)."""
    src = tmp_path / "m.py"
    src.write_text("import os\nfrom typing import TYPE_CHECKING\n"
                   "if TYPE_CHECKING:\n    from benchmarks.sim import loop\n"
                   "def f():\n    import controllers.base as b\n    from . import x\n")
    names = [name for _, name in imported(src)]
    assert names == ["os", "typing", "benchmarks.sim", "controllers.base"]
