"""The key listing of docs/scenarios.md is a scenario a user can copy: it parses, loads
and gives the controllers its table names (the comments' alternatives aside)."""

from __future__ import annotations

import re
from pathlib import Path

from benchmarks.study.scenario import load_scenario

DOC = Path(__file__).resolve().parents[3] / "docs" / "scenarios.md"


def test_the_key_listing_is_a_scenario(tmp_path: Path) -> None:
    text = DOC.read_text()
    listing = re.search(r"```toml\n(.*?)```", text[text.index("## Keys"):], flags=re.S)
    assert listing is not None
    path = tmp_path / "keys.toml"
    path.write_text(listing.group(1))
    sc = load_scenario(path)
    assert [c.label for c in sc.controllers] == ["leg-direction", "leg-edge", "edge-fast"]
    assert sc.expand(), "a scenario with at least one sweep point"
