"""hexapod.outputs: the name rule, paths kept inside their directory, files replaced only
when the project wrote them or the user asked."""

from __future__ import annotations

import os
import re
from pathlib import Path

import cv2
import numpy as np
import pytest

from hexapod.exceptions import OutputError, UnsafeNameError
from hexapod.outputs import (
    check_name,
    check_output_dir,
    check_replace,
    file_kind,
    inside,
    mark_png,
    write_output,
    written_by_project,
)


@pytest.mark.parametrize("name", ["quick", "leg-edge", "tests.benchmarks.plugins:Joints",
                                  "edge_fast+2", "a.b", "_x", "7dof"])
def test_ordinary_names_pass(name: str) -> None:
    assert check_name(name, "scenario name") == name


@pytest.mark.parametrize(("name", "problem"), [
    ("../../escape", "path separator '/'"),
    ("a/b", "path separator '/'"),
    ("a\\b", "path separator '\\\\'"),
    ("..", "contains '..'"),
    ("a..b", "contains '..'"),
    ("nul\x00byte", "NUL character"),
    ("tab\there", "control character '\\t'"),
    ("new\nline", "control character '\\n'"),
    ("bell\x07", "control character '\\x07'"),
    ("del\x7f", "control character '\\x7f'"),
    ("with space", "contains ' '"),
    ("étude", "contains 'é'"),
    (".hidden", "starts with '.'"),
    ("-rf", "starts with '-'"),
    ("", "empty"),
    ("x" * 101, "101 characters"),
])
def test_unsafe_names_are_refused_with_the_reason(name: str, problem: str) -> None:
    with pytest.raises(UnsafeNameError) as info:
        check_name(name, "scenario name")
    assert problem in str(info.value)
    assert str(info.value).startswith(f"scenario name {name!r}: ")
    assert "letters, digits" in info.value.problem


def test_a_non_string_name_is_refused() -> None:
    with pytest.raises(UnsafeNameError, match="expected a string"):
        check_name(3, "controller label")


def test_inside_keeps_paths_in_their_directory(tmp_path: Path) -> None:
    assert inside(tmp_path, "a.png") == tmp_path / "a.png"
    assert inside(tmp_path / "trials", "x__p0__y__00000.npz").parent == tmp_path / "trials"
    for part in ("../escape.png", "/etc/passwd", "a/../../b"):
        with pytest.raises(OutputError, match="outside"):
            inside(tmp_path, part)
    (tmp_path / "link").symlink_to(tmp_path.parent)
    with pytest.raises(OutputError, match="symbolic link"):
        inside(tmp_path, "link", "x.png")


def test_check_replace_protects_files_the_project_did_not_write(tmp_path: Path) -> None:
    mine = tmp_path / "notes.html"
    mine.write_text("<html>my notes</html>")
    with pytest.raises(OutputError) as info:
        check_replace(mine)
    assert "already exists (a .html file of 21 bytes, not written by hexapod-vs)" in str(
        info.value)
    assert "--overwrite" in str(info.value)
    check_replace(mine, overwrite=True)  # asked explicitly
    ours = tmp_path / "page.html"
    ours.write_text('<!DOCTYPE html><html><head><meta name="generator" content="hexapod-vs">')
    check_replace(ours)  # the project's: replaced silently
    check_replace(tmp_path / "new.html")  # absent
    with pytest.raises(OutputError, match="is a directory"):
        check_replace(tmp_path)
    assert mine.read_text() == "<html>my notes</html>"


def test_a_project_file_of_another_kind_is_not_replaced_unasked(tmp_path: Path) -> None:
    """A ``--json`` (or ``--parquet``, ...) given the project's report or tuned options
    is refused: replacing a file the project wrote is fine only with one of its kind."""
    report = tmp_path / "report.md"  # as the report writes it: the mark on line 3
    report.write_text("# Benchmark report\n\n<!-- written by hexapod-vs: hexapod-bench "
                      "report -->\n\nbody\n")
    tuned = write_output(tmp_path / "tuned.toml", "[controller_options]\ngain = 2.0\n")
    plot = write_output(tmp_path / "plot.png", mark_png(cv2.imencode(
        ".png", np.zeros((4, 4), np.uint8))[1].tobytes()))
    assert [file_kind(f) for f in (report, tuned, plot)] == ["Markdown", "TOML", "PNG"]
    for target in (report, tuned, plot):
        before = target.read_bytes()
        with pytest.raises(OutputError, match=r"already exists \(hexapod-vs's \w+, and this "
                                              r"writes a JSON file\)"):
            write_output(target, {"comparisons": []})
        assert target.read_bytes() == before
        with pytest.raises(OutputError, match="--overwrite"):
            check_replace(target, kind="JSON")
        check_replace(target, overwrite=True, kind="JSON")  # asked: allowed
    again = write_output(tmp_path / "c.json", {"comparisons": [1]})
    write_output(again, {"comparisons": [2]})  # its own kind: replaced
    assert '"comparisons": [\n  2' in again.read_text()
    write_output(report, "# Benchmark report\n")  # Markdown over Markdown: replaced
    assert file_kind(b"{}", ".md") == "JSON" and file_kind(b"x", ".jsonl") == "JSON lines"
    assert file_kind(tmp_path / "absent.json") is None


def test_marked_png_is_recognised_and_still_decodes(tmp_path: Path) -> None:
    img = np.zeros((8, 12, 3), np.uint8)
    img[2:5, 3:9] = (10, 200, 30)
    ok, data = cv2.imencode(".png", img)
    assert ok
    plain, marked = tmp_path / "plain.png", tmp_path / "marked.png"
    plain.write_bytes(data.tobytes())
    marked.write_bytes(mark_png(data.tobytes()))
    assert not written_by_project(plain)
    assert written_by_project(marked)
    np.testing.assert_array_equal(cv2.imread(str(marked)), img)  # the CRC is right
    with pytest.raises(ValueError, match="not a PNG"):
        mark_png(b"GIF89a")


def test_check_output_dir_lists_what_is_there(tmp_path: Path) -> None:
    d = tmp_path / "d"
    check_output_dir(d, lambda e: False, "run directory")  # absent: fine
    d.mkdir()
    check_output_dir(d, lambda e: False, "run directory")  # empty: fine
    for k in range(10):
        (d / f"f{k}.txt").write_text("x")
    (d / "sub").mkdir()
    with pytest.raises(OutputError) as info:
        check_output_dir(d, lambda e: e.name == "f0.txt", "run directory")
    text = str(info.value)
    assert "is not empty and is not a run directory: it holds f1.txt, f2.txt" in text
    assert "(and 2 more)" in text and "--overwrite" in text
    check_output_dir(d, lambda e: False, "run directory", overwrite=True)
    f = tmp_path / "file"
    f.write_text("")
    with pytest.raises(OutputError, match="is a file, not a directory"):
        check_output_dir(f, lambda e: True, "run directory")
    assert sorted(os.listdir(d))[:2] == ["f0.txt", "f1.txt"]


def test_parquet_files_are_recognised_by_their_schema_metadata(tmp_path: Path) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    from hexapod.outputs import PARQUET_METADATA

    table = pa.table({"trial": [0, 1], "error_mm": [0.1, 0.2]})
    theirs, ours = tmp_path / "theirs.parquet", tmp_path / "ours.parquet"
    pq.write_table(table, theirs)
    pq.write_table(table.replace_schema_metadata(PARQUET_METADATA), ours)
    assert not written_by_project(theirs)
    assert written_by_project(ours)
    check_replace(ours)
    with pytest.raises(OutputError, match="not written by hexapod-vs"):
        check_replace(theirs)


def test_write_output_marks_every_kind_and_refuses_a_users_file(tmp_path: Path) -> None:
    import json

    import pyarrow as pa
    import pyarrow.parquet as pq
    from PIL import Image

    ok, png = cv2.imencode(".png", np.zeros((4, 4, 3), np.uint8))
    ok2, jpg = cv2.imencode(".jpg", np.zeros((8, 8, 3), np.uint8))
    assert ok and ok2
    table = pa.table({"x": [1.0, 2.0]})
    contents: dict[str, object] = {"a.json": {"k": 1}, "b.json": [1, 2], "c.png": png.tobytes(),
                                   "d.jpg": jpg.tobytes(), "e.md": "| a |\n", "f.toml": "x = 1\n",
                                   "g.html": "<p>x</p>", "h.parquet": table}
    for name, content in contents.items():
        path = tmp_path / "sub" / name
        path.parent.mkdir(exist_ok=True)
        path.write_bytes(b"mine")
        with pytest.raises(OutputError, match=f"{name}: already exists .* --overwrite"):
            write_output(path, content)
        assert path.read_bytes() == b"mine"
        assert write_output(path, content, overwrite=True) == path
        assert written_by_project(path), name
        write_output(path, content)  # its own file: replaced without asking
    assert json.loads((tmp_path / "sub/a.json").read_text()) == {"generator": "hexapod-vs",
                                                                  "k": 1}
    assert json.loads((tmp_path / "sub/b.json").read_text())["items"] == [1, 2]
    with Image.open(tmp_path / "sub/c.png") as im:
        assert im.text["Software"] == "hexapod-vs"  # type: ignore[attr-defined]
    with Image.open(tmp_path / "sub/d.jpg") as im:
        assert im.info["comment"] == b"written by hexapod-vs" and im.size == (8, 8)
    assert (tmp_path / "sub/e.md").read_text() == "<!-- written by hexapod-vs -->\n| a |\n"
    assert pq.read_table(tmp_path / "sub/h.parquet").column("x").to_pylist() == [1.0, 2.0]
    assert not list((tmp_path / "sub").glob(".*.part")), "no temporary file left"
    with pytest.raises(ValueError, match="PNG or JPEG"):
        write_output(tmp_path / "x.bin", b"GIF89a")


def test_a_json_output_holds_no_nan_or_infinity(tmp_path: Path) -> None:
    """json.dumps writes NaN and Infinity, which are not JSON (an identification's
    condition number was written 'Infinity'): non-finite values are null."""
    import json

    from hexapod.outputs import write_output

    path = write_output(tmp_path / "x.json", {"a": float("nan"), "b": [1.0, float("inf")],
                                              "c": {"d": np.float64(-np.inf), "e": 2.5}})
    text = path.read_text()
    doc = json.loads(text, parse_constant=lambda c: pytest.fail(f"not JSON: {c}"))
    assert (doc["a"], doc["b"], doc["c"]) == (None, [1.0, None], {"d": None, "e": 2.5})


def test_replace_whole_leaves_the_earlier_file_when_the_write_fails(tmp_path: Path) -> None:
    """run.json written in place was cut at 8192 bytes by a full disk, and the study could
    not be resumed: written beside and renamed, a failed write leaves the earlier file
    (here the failure is a non-encodable text, raised while writing the part file)."""
    from hexapod.outputs import replace_whole

    path = tmp_path / "run.json"
    replace_whole(path, '{"a": 1}')
    with pytest.raises(UnicodeEncodeError):
        replace_whole(path, '{"a": "\ud800"}')  # a lone surrogate: not UTF-8
    assert path.read_text() == '{"a": 1}' and sorted(p.name for p in tmp_path.iterdir()) == \
        ["run.json"]


def test_the_mark_counts_where_the_project_puts_it_not_where_a_file_quotes_it(
        tmp_path: Path) -> None:
    """A user's notes that mention 'written by hexapod-vs' in their text, or a JSON that
    embeds a compare output, were taken for the project's and replaced; the mark counts
    as a comment of the first lines, JSON's first key, the PNG text chunk."""
    cases = {
        "ours.md": ("# Benchmark report\n\n<!-- written by hexapod-vs: report -->\n", True),
        "ours.toml": ("# written by hexapod-vs (calibrate)\nscale = 1.0\n", True),
        "ours.json": ('{\n "generator": "hexapod-vs",\n "comparisons": []\n}\n', True),
        "notes.md": ("# Notes\n\nThe table was written by hexapod-vs, not me.\n", False),
        "late.md": ("a\nb\nc\nd\ne\nf\n<!-- written by hexapod-vs -->\n", False),
        "embeds.json": ('{"mine": [1], "pasted": {"generator": "hexapod-vs"}}\n', False),
    }
    for name, (text, ours) in cases.items():
        (tmp_path / name).write_text(text)
        assert written_by_project(tmp_path / name) is ours, name


def test_a_write_that_fails_names_the_file(tmp_path: Path) -> None:
    """An OSError while writing (a full disk, a missing folder) was printed as
    'OSError: [Errno 28] ...' without the file: it names it now."""
    from hexapod.outputs import replace_whole

    path = tmp_path / "missing" / "report.md"
    with pytest.raises(OutputError, match="could not be written") as info:
        replace_whole(path, "x")
    assert str(path) in str(info.value) and not path.parent.exists()


def test_write_output_refuses_unwritable_paths_and_content_as_output_errors(
        tmp_path: Path) -> None:
    """A folder of the path that is a file gave FileExistsError, a numpy array in a dict
    a TypeError naming no file: both are OutputErrors naming the file, nothing written."""
    user = tmp_path / "user.json"
    user.write_text("{}")
    inner = user / "sub" / "inner.json"
    with pytest.raises(OutputError, match=f"^{re.escape(str(inner))}: its folder cannot be "
                       f"made: {re.escape(str(user))} is a file, not a folder; nothing was "
                       "written$"):
        write_output(inner, {"a": 1})
    path = tmp_path / "out" / "x.json"
    with pytest.raises(OutputError, match=rf"^{re.escape(str(path))}: cannot be written as "
                       r"JSON: the value at "
                       r"'a.b\[1\]' has type ndarray \(convert it"):
        write_output(path, {"a": {"b": [1, np.arange(3)]}})
    with pytest.raises(OutputError, match=r"the key \(1, 2\) in 'a' has type tuple"):
        write_output(path, {"a": {(1, 2): 3}})
    assert user.read_text() == "{}" and sorted(p.name for p in tmp_path.iterdir()) == \
        ["user.json"], "nothing written, no folder made"


def test_a_runs_own_files_are_not_called_the_users(tmp_path: Path) -> None:
    """compare --json given a run's run.json was refused as 'not written by hexapod-vs'
    (those files carry no mark, yet the project wrote them)."""
    (tmp_path / "results.jsonl").write_text("{}\n")
    (tmp_path / "run.json").write_text("{}\n")
    for name in ("run.json", "results.jsonl"):
        with pytest.raises(OutputError, match=f"the {name} of the run in") as info:
            check_replace(tmp_path / name)
        assert "not written by" not in str(info.value)
