"""Tables fit an 80-column terminal: every number printed at width 200 appears in full at
width 80 (column groups, or one block per row when even that does not fit); no cell is
cut to ``0.…``."""

from __future__ import annotations

import io
import re
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from rich.console import Console

from benchmarks.study.commands import _print_summary
from benchmarks.study.fit_table import column_groups, print_table, table_width
from tests.benchmarks.study.helpers_rows import make_rows, two_controllers, write_run

NUMBER = re.compile(r"[-+]?\d+(?:\.\d+)?(?:e[-+]?\d+)?")


def _numbers(text: str) -> Counter[str]:
    return Counter(NUMBER.findall(text))


def _console(width: int) -> tuple[Console, io.StringIO]:
    buf = io.StringIO()
    return Console(width=width, file=buf, color_system=None), buf


def _swept_run(tmp_path: Path) -> Path:
    rng = np.random.default_rng(4)
    rows = []
    for p, noise in enumerate((0.01, 0.05, 0.1)):
        sweep = {"noise_amplitude_deg": noise, "calib_base_points_mm": 1.0 + p}
        for c in ("leg-direction", "leg-edge", "model-based-with-long-label"):
            err = rng.lognormal(-3, 0.5, 20)
            rows += make_rows(c, err, err < 0.06, rng.integers(80, 140, 20),
                              scenario="andreff2005-noise-realistic", point=p, sweep=sweep)
    return write_run(tmp_path / "run", rows)


def _assert_same_numbers(wide: str, narrow: str) -> None:
    missing = _numbers(wide) - _numbers(narrow)
    assert not missing, f"numbers of the wide table missing at 80 columns: {missing}"
    assert "…" not in narrow
    assert max(len(line) for line in narrow.splitlines()) <= 80


def test_results_table_fits_80_columns(tmp_path: Path) -> None:
    out = _swept_run(tmp_path)
    texts = {}
    for width in (200, 80):
        con, buf = _console(width)
        _print_summary(out, con)
        texts[width] = buf.getvalue()
    _assert_same_numbers(texts[200], texts[80])
    assert "(1/" in texts[80]  # wrapped in column groups
    assert "(1/" not in texts[200]  # one table where it fits


def test_comparison_table_fits_80_columns(tmp_path: Path,
                                          monkeypatch: pytest.MonkeyPatch) -> None:
    from benchmarks.study import commands, load
    from benchmarks.study.analysis_cli import print_comparisons
    from benchmarks.study.compare import compare_controllers

    comps = compare_controllers(load(write_run(tmp_path / "r", two_controllers(60,
                                                                              worse_by=1.2))))
    texts = {}
    for width in (200, 80):
        con, buf = _console(width)
        monkeypatch.setattr(commands, "console", lambda con=con: con)
        print_comparisons(comps, "Paired comparisons")
        texts[width] = buf.getvalue()
    _assert_same_numbers(texts[200], texts[80])


def test_narrow_layout_when_the_keys_alone_do_not_fit() -> None:
    header = ["sweep", "controller", "pos med mm"]
    rows = [["noise_amplitude_deg=0.05, calib_base_points_mm=1", "leg-edge", "0.0123"],
            ["noise_amplitude_deg=0.1, calib_base_points_mm=2", "leg-edge", "0.0456"]]
    con, buf = _console(40)
    print_table(con, "Results", header, rows, keys=(0, 1))
    text = buf.getvalue()
    assert "    pos med mm: 0.0123" in text and "    pos med mm: 0.0456" in text
    assert "…" not in text


def test_column_groups_repeat_the_keys_and_fit() -> None:
    widths = [20, 15, 12, 12, 12, 12, 12]
    groups = column_groups(widths, [0, 1], 80)
    assert groups is not None and len(groups) > 1
    assert all(g[:2] == [0, 1] for g in groups)
    assert sorted(i for g in groups for i in g[2:]) == [2, 3, 4, 5, 6]
    assert all(table_width([widths[i] for i in g]) <= 80 for g in groups)
    assert column_groups([50, 30, 12], [0, 1], 80) is None
