"""Sphinx configuration of the API reference (``make docs``).

The build imports the real packages (nothing is mocked): run it with the
project's virtual environment, where numpy, pinocchio, casadi... are installed.
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
# The packages are importable from the editable install; the checkout comes first
# so that a build from a fresh clone documents the files it contains.
sys.path.insert(0, str(ROOT))

project = "hexapod-vs"
author = "hexapod-vs contributors"
copyright = "hexapod-vs contributors"

import hexapod  # noqa: E402 (after the path set-up)

release = hexapod.__version__

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
]

# Google-style docstrings only.
napoleon_google_docstring = True
napoleon_numpy_docstring = False
napoleon_use_rtype = False

autodoc_default_options = {
    "member-order": "bysource",
}
# Type hints stay in the signatures: "description" builds cleanly too, but it
# adds a type-only "Parameters" entry for every dataclass field and every
# argument a docstring does not list, which buries the documented ones.
autodoc_typehints = "signature"

nitpicky = False

html_theme = "alabaster"
html_title = f"hexapod-vs {release}"
html_static_path: list[str] = []

exclude_patterns = ["_build"]
