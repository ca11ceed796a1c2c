"""The camera sub-package imports one way: each module imports only modules of lower
layers (no circle), and no camera model imports the file readers."""

from __future__ import annotations

import ast
from pathlib import Path

import vision.cameras

ROOT = Path(vision.cameras.__file__).parent

#: Layer of each module of vision.cameras (a module imports only lower layers).
LAYERS = {
    "checks": 0, "fields": 0,
    "lens": 1, "projection": 1,
    "distortion": 2, "distortion_full": 2, "radial": 2,
    "base": 3,
    "perspective": 4, "unified": 4,
    "radial_camera": 5,
    "fisheye": 6, "double_sphere": 6, "eucm": 6,
    "presets": 7,
    "files": 7, "files.project": 7, "files.opencv": 7, "files.ros": 7, "files.kalibr": 7,
    "factory": 8,
    "": 9,
}
MODELS = ("base", "perspective", "unified", "radial_camera", "fisheye", "double_sphere", "eucm",
          "presets")


def _module(path: Path) -> str:
    rel = path.relative_to(ROOT).with_suffix("")
    parts = [p for p in rel.parts if p != "__init__"]
    return ".".join(parts)


def _imports(path: Path) -> set[str]:
    """The vision.cameras modules a file imports (``""`` for the package itself)."""
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        names: list[str] = []
        if isinstance(node, ast.ImportFrom) and node.module:
            # ``from vision.cameras import projection`` imports the submodule only.
            subs = [f"{node.module}.{a.name}" for a in node.names]
            names = [s for s in subs if s.removeprefix("vision.cameras.") in LAYERS
                     and s.startswith("vision.cameras.")] or [node.module]
        elif isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        for name in names:
            if name == "vision.cameras" or name.startswith("vision.cameras."):
                sub = name.removeprefix("vision.cameras").lstrip(".")
                while sub and sub not in LAYERS:
                    sub = sub.rpartition(".")[0]
                out.add(sub)
    return out


def test_every_camera_module_has_a_layer() -> None:
    modules = {_module(p) for p in ROOT.rglob("*.py")}
    assert modules == set(LAYERS), modules ^ set(LAYERS)


def test_camera_modules_import_one_way() -> None:
    bad = []
    for path in ROOT.rglob("*.py"):
        me = _module(path)
        for dep in _imports(path):
            if dep != me and not LAYERS[dep] < LAYERS[me]:
                bad.append(f"{me} (layer {LAYERS[me]}) imports {dep} (layer {LAYERS[dep]})")
    assert not bad, bad


def test_no_model_imports_the_file_readers() -> None:
    for name in MODELS:
        deps = _imports(ROOT / f"{name}.py")
        assert not any(d == "files" or d.startswith("files.") or d == "factory" for d in deps), (
            name, deps)
