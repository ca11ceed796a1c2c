"""The README's library example (stepping a controller by hand) runs as written and
reaches its goal."""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"


def test_the_readme_s_library_example_runs_and_converges() -> None:
    text = README.read_text()
    block = text.split("<!-- library-example -->\n```python\n", 1)[1].split("```", 1)[0]
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(block, "README.md (library example)", "exec"), {"__name__": "readme"})
    assert out.getvalue().strip() == "position error 0.0000 mm after 200 periods"
