"""The paired comparison of a saturation strategy with its law's clip
(:mod:`benchmarks.perf.saturation_pairs`) on hand-made rows."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from benchmarks.perf.saturation_pairs import comparisons, main


def _rows(shift: float) -> list[dict]:
    """20 trials at 0 kg (no saturation) and 70 kg (saturated), computed-torque and its
    ``+scale`` variant, the variant ``shift`` mm worse at 70 kg; trial 3 of the variant
    at 70 kg failed on an end stop."""
    rng = np.random.default_rng(0)
    rows = []
    for mass, sat in ((0.0, 0.0), (70.0, 0.3)):
        base = rng.uniform(1.0, 2.0, 20)
        for name, extra in (("computed-torque", 0.0), ("computed-torque+scale", shift)):
            for k in range(20):
                failed = name.endswith("+scale") and mass == 70.0 and k == 3
                rows.append({"controller": name, "payload_mass_kg": mass, "trial": k,
                             "tracking_rms_position_mm": float(base[k] + (
                                 extra if mass == 70.0 else 0.0) + 1e-3 * k),
                             "saturation_time_s": sat,
                             "failure": "leg 3 hit its end stop" if failed else None})
    return rows


def test_a_worse_strategy_is_found_where_it_saturates() -> None:
    lines = comparisons(_rows(0.5))
    assert len(lines) == 1  # 0 kg: nothing saturated, not compared
    line = lines[0]
    assert line.startswith("70 kg computed-torque+scale - computed-torque: +0.5 mm")
    assert ", 19 trials," in line  # the failed trial left out
    assert "Holm p" in line
    p = float(line.rsplit("p ", 1)[1])
    assert p < 1e-3


def test_no_difference_is_not_significant() -> None:
    (line,) = comparisons(_rows(0.0))
    assert "+0 mm" in line
    assert line.endswith("Holm p 1")


def test_main_reads_a_results_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "results.jsonl"
    path.write_text("".join(json.dumps(r) + "\n" for r in _rows(0.5)))
    assert main([str(path)]) == 0
    assert "computed-torque+scale" in capsys.readouterr().out
    assert main([]) == 2
    assert main(["--help"]) == 0 and "Run: ``python -m" in capsys.readouterr().out


def test_too_few_pairs_are_named_not_tested() -> None:
    rows = [r for r in _rows(0.5) if r["trial"] < 5]  # 5 pairs at 70 kg, one failed: 4
    assert comparisons(rows) == ["70 kg computed-torque+scale - computed-torque: 4 paired "
                                 "trials ran to their end, fewer than 6: not tested"]
