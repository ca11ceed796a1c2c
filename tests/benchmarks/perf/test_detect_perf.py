"""The detection benchmark's bookkeeping: found edges are counted among the visible ones."""

from __future__ import annotations

import io
import re
from contextlib import redirect_stdout

import cv2
import numpy as np
import pytest

from benchmarks.perf.detect import EdgeCounts, main
from hexapod.exceptions import OutputError


def test_a_detected_partly_hidden_edge_is_not_counted_as_found() -> None:
    truth = np.ones((6, 2), bool)
    truth[2, 1] = False                      # hidden for the truth...
    fraction = np.ones((6, 2))
    fraction[2, 1] = 0.6                     # ...but 60 % of it in view
    fraction[4, 0] = 0.1
    truth[4, 0] = False                      # nothing of it to see
    detected = np.ones((6, 2), bool)         # the detector reports all twelve
    detected[0, 0] = False                   # and misses one visible edge
    c = EdgeCounts()
    c.add(truth, fraction, detected)
    assert (c.truth, c.found, c.missed, c.partly_hidden, c.invented) == (10, 9, 1, 1, 1)


@pytest.mark.slow
def test_benchmark_table_never_finds_more_than_the_truth() -> None:
    buf = io.StringIO()
    with redirect_stdout(buf):
        assert main(["--frames", "60", "--repeats", "1"]) == 0
    rows = [line for line in buf.getvalue().splitlines() if line.startswith("| omni")
            or line.startswith("| front")]
    assert len(rows) == 2
    for line in rows:
        cells = [c.strip() for c in line.strip("|").split("|")]
        found, visible = map(int, re.fullmatch(r"(\d+)/(\d+)", cells[11]).groups())
        missed = int(cells[12])
        assert found <= visible and found + missed == visible, line


@pytest.mark.slow
def test_distortion_rows_beside_the_ideal_ones(tmp_path) -> None:
    """``--distortion``: each camera twice, ideal then distorted (the ``lens`` column, the
    last but one), then the front camera through the other lens models; the same poses
    (same number of visible edges for the omnidirectional camera, which sees every
    edge), detections as good as through the ideal lens (median error within 1.5 times),
    the time over the ideal lens's (the last column, 1.00x for the ideal lens) and the
    pictures of the distorted frames."""
    buf = io.StringIO()
    with redirect_stdout(buf):
        assert main(["--frames", "8", "--repeats", "1", "--distortion",
                     "--pictures", str(tmp_path)]) == 0
    rows = [[c.strip() for c in line.strip("|").split("|")]
            for line in buf.getvalue().splitlines()
            if line.startswith("| omni") or line.startswith("| front")]
    assert [(r[0], r[-2]) for r in rows] == [
        ("omni", "ideal"), ("omni", "distorted"), ("front", "ideal"), ("front", "distorted"),
        ("front", "opencv-full"), ("front", "fisheye"), ("front", "double-sphere"),
        ("front", "eucm")]
    assert rows[0][11] == rows[1][11] == "96/96"
    assert rows[0][-1] == rows[2][-1] == "1.00x"
    for ideal, lens in [rows[0:2], *([rows[2], r] for r in rows[3:])]:
        assert float(lens[8]) < 1.5 * float(ideal[8]), (ideal, lens)
        found, visible = map(int, re.fullmatch(r"(\d+)/(\d+)", lens[11]).groups())
        assert found + int(lens[12]) == visible and int(lens[14]) == 0
        ratio = float(lens[-1].rstrip("x"))
        assert abs(ratio - float(lens[3]) / float(ideal[3])) < 0.01 * ratio + 0.01
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == ["detect-front-distorted.png", "detect-front-double-sphere.png",
                     "detect-front-eucm.png", "detect-front-fisheye.png",
                     "detect-front-opencv-full.png", "detect-front.png",
                     "detect-omni-distorted.png", "detect-omni.png"]
    # the pictures are marked as the project's and still decode; a picture of the user's
    # under one of those names is refused before any work
    from hexapod.outputs import written_by_project

    assert all(written_by_project(tmp_path / n) for n in names)
    assert cv2.imread(str(tmp_path / "detect-omni.png")) is not None
    (tmp_path / "detect-front.png").write_bytes(b"\x89PNG\r\n\x1a\n a photo")
    with redirect_stdout(io.StringIO()), pytest.raises(OutputError, match="already exists"):
        main(["--frames", "1", "--repeats", "1", "--pictures", str(tmp_path)])
    assert (tmp_path / "detect-front.png").read_bytes() == b"\x89PNG\r\n\x1a\n a photo"


def test_interleaved_rounds_give_ratios_to_the_ideal_lens() -> None:
    """``--rounds``: a second table, one row per camera, the ideal rows at 1.00x and each
    ratio the row's time over its camera's ideal-lens time."""
    buf = io.StringIO()
    with redirect_stdout(buf):
        assert main(["--frames", "2", "--repeats", "1", "--rounds", "2"]) == 0
    text = buf.getvalue().split("# interleaved")[1]
    rows = [[c.strip() for c in line.strip("|").split("|")] for line in text.splitlines()
            if line.startswith("| omni") or line.startswith("| front")]
    assert [(r[0], r[1]) for r in rows] == [("omni", "ideal"), ("front", "ideal")]
    for r in rows:
        assert r[3] == r[5] == "1.00x" and float(r[2]) > 0 and float(r[4]) >= float(r[2])
