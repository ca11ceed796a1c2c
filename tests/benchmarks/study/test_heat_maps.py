"""The convergence map of a study with two sweep axes: drawn for numbers and for a
setting given as text (the goal information), each cell its point's figures."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from benchmarks.study.plots import sweep_tick
from benchmarks.study.report import write_report
from tests.benchmarks.study.helpers_rows import make_rows, write_run


def _rows(first: list[Any], second: list[Any]) -> list[dict[str, Any]]:
    rng = np.random.default_rng(2)
    rows: list[dict[str, Any]] = []
    point = 0
    for a in first:
        for b in second:
            for ctrl in ("leg-edge", "model-based"):
                err = rng.lognormal(-2, 0.4, 6)
                rows += make_rows(ctrl, err, np.arange(6) > point % 3, rng.integers(60, 90, 6),
                                  point=point, sweep={"task_goal": a, "noise_amplitude_deg": b})
            point += 1
    return rows


@pytest.mark.parametrize("first", [["mixed", "taught", "cartesian"], [0.5, 1.0, 2.0]])
def test_two_axes_give_a_convergence_map(tmp_path: Path, first: list[Any]) -> None:
    out = write_run(tmp_path / "run", _rows(first, [0.0, 0.05]))
    text = write_report(out).read_text()
    assert "![convergence map](synthetic_map.png)" in text
    png = out / "synthetic_map.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000


def test_a_tick_is_a_number_in_g_format_or_the_value_s_text() -> None:
    assert [sweep_tick(v) for v in (0.05, 2, 1e-7, "taught", True)] == [
        "0.05", "2", "1e-07", "taught", "True"]
