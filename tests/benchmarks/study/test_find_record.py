"""``viz DIR --trial K``: which recorded trial, and what to add when several match."""

from __future__ import annotations

from pathlib import Path

import pytest

from benchmarks.exceptions import BenchmarkError
from benchmarks.study.viz_command import find_record


def _records(tmp_path: Path, stems: list[str]) -> Path:
    (tmp_path / "trials").mkdir()
    for stem in stems:
        (tmp_path / "trials" / f"{stem}.npz").write_bytes(b"")
    (tmp_path / "run.json").write_text("{}")
    return tmp_path


def test_an_ambiguous_choice_names_only_what_still_tells_them_apart(tmp_path: Path) -> None:
    """A swept run: --controller given, the records differ by sweep point: the message
    asked for '--controller, --scenario or --point' although --controller was given."""
    out = _records(tmp_path, ["track__p0__leg-edge__00000", "track__p1__leg-edge__00000",
                              "track__p0__joint-space__00000"])
    with pytest.raises(BenchmarkError) as info:
        find_record(out, 0, controller="leg-edge")
    assert str(info.value).endswith("choose with --point"), str(info.value)
    with pytest.raises(BenchmarkError) as info:
        find_record(out, 0)
    assert str(info.value).endswith("choose with --point and --controller"), str(info.value)
    assert find_record(out, 0, controller="leg-edge", point=1).stem == \
        "track__p1__leg-edge__00000"


def test_an_unknown_point_or_controller_is_named_as_such(tmp_path: Path) -> None:
    """--point 4 of a run with point 0 only said trial 0 was not recorded (listing it);
    --controller nosuch advised --record."""
    out = _records(tmp_path, ["quick__p0__leg-edge__00000", "quick__p0__joint-space__00000"])
    with pytest.raises(BenchmarkError, match=r"--point 4: nothing recorded under it; "
                                             r"recorded: 0$"):
        find_record(out, 0, controller="leg-edge", point=4)
    with pytest.raises(BenchmarkError, match=r"--controller nosuch: nothing recorded under "
                                             r"it; recorded: joint-space, leg-edge$"):
        find_record(out, 5, controller="nosuch")
