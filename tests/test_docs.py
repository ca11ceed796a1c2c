"""The API reference (docs/api) builds without a warning and documents the plugin API.

Runs the same command as ``make docs`` (Sphinx with ``-W``) into a temporary
directory with this interpreter, so the real modules are imported. Sphinx is a
``dev`` dependency: without it the test fails rather than skips.
"""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SOURCE = ROOT / "docs" / "api"

#: Names the built reference must contain (plugin interfaces, robot, vision).
EXPECTED = (
    "ControllerContext",
    "Observation",
    "Backend",
    "clamp_velocities",
    "forward_kinematics",
    "HexapodGeometry",
    "PerspectiveCamera",
    "fit_normal",
    "CalibrationError",
)


@pytest.mark.slow
def test_api_reference_builds_without_warnings(tmp_path: Path) -> None:
    assert importlib.util.find_spec("sphinx") is not None, (
        "Sphinx is not installed in this environment: it is a 'dev' extra "
        "(pip install -e '.[dev]', or make venv)"
    )
    out = tmp_path / "html"
    cmd = [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-b", "html"]
    cmd += [str(SOURCE), str(out)]
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=600)
    if proc.returncode != 0:
        print(proc.stdout)
        print(proc.stderr, file=sys.stderr)
    assert proc.returncode == 0, f"sphinx-build failed ({proc.returncode}):\n{proc.stderr}"

    pages = {p.name: p.read_text(encoding="utf-8") for p in out.glob("*.html")}
    assert "index.html" in pages
    text = "\n".join(pages.values())
    missing = [name for name in EXPECTED if name not in text]
    assert not missing, f"not in the generated HTML: {missing}"
    # The plugin interface page documents the classes themselves, not only mentions them.
    assert 'id="controllers.base.ControllerContext"' in pages["controllers.html"]
    assert 'id="hexapod.backends.base.Backend"' in pages["backends.html"]
    assert 'id="hexapod.fk.forward_kinematics"' in pages["fk.html"]
    assert 'id="vision.cameras.PerspectiveCamera"' in pages["cameras.html"]
