"""The pictures of ``docs/`` are the project's outputs: each carries its marker, so the
commands the README gives to draw them again replace them (they refused, the committed
pictures being taken for a user's files)."""

from __future__ import annotations

from pathlib import Path

from hexapod.outputs import check_replace, written_by_project

DOCS = Path(__file__).resolve().parents[1] / "docs"


def test_every_picture_of_the_docs_carries_the_project_s_marker() -> None:
    pictures = sorted(DOCS.glob("*.png"))
    assert pictures
    unmarked = [p.name for p in pictures if not written_by_project(p)]
    assert not unmarked, f"draw them with the project's command, or mark them: {unmarked}"
    for p in pictures:
        check_replace(p, False, kind="PNG")  # what perf detect --pictures docs meets
