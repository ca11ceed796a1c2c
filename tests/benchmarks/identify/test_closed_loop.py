"""The closed loop's files and its paired comparison."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from benchmarks.exceptions import ScenarioError
from benchmarks.identify.closed_loop import compare, prepare
from benchmarks.study.scenario import load_scenario


def test_prepare_writes_the_truth_and_three_scenarios_that_load(tmp_path: Path) -> None:
    paths = prepare(tmp_path)
    assert [p.name for p in paths] == ["deltalab-heavy.toml", "inertia-error-exact.toml",
                                       "inertia-error-identified.toml",
                                       "inertia-error-wrong.toml"]
    exact = load_scenario(str(tmp_path / "inertia-error-exact.toml"))
    assert exact.model_data.inertia.platform_mass == pytest.approx(2.0 / 0.7)
    assert exact.calibration_error.model_mass_error_percent == -30.0
    assert load_scenario(str(tmp_path / "inertia-error-wrong.toml")).model_data is None
    # the identified scenario needs the identification's output first
    with pytest.raises(ScenarioError, match=r"identified\.toml"):
        load_scenario(str(tmp_path / "inertia-error-identified.toml"))


def test_compare_pairs_the_trials(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    base = 0.1 + 0.01 * rng.random(30)
    for name, values in (("exact", base), ("identified", base + 0.002),
                         ("wrong", base + 5.0)):
        d = tmp_path / name
        d.mkdir()
        rows = [{"controller": "computed-torque", "trial": k,
                 "tracking_rms_position_mm": float(v)} for k, v in enumerate(values)]
        rows.append({"controller": "leg-edge", "trial": 0, "tracking_rms_position_mm": 9.0})
        (d / "results.jsonl").write_text("\n".join(json.dumps(r) for r in rows))
    out = compare(tmp_path / "exact", tmp_path / "identified", tmp_path / "wrong")
    assert out["trials"] == 30
    assert out["median_identified_mm"] == pytest.approx(np.median(base) + 0.002)
    assert out["identified_vs_exact"]["worse_in"] == 30
    assert out["identified_vs_exact"]["wilcoxon_p"] < 1e-6
    assert out["wrong_vs_identified"]["median_difference_mm"] == pytest.approx(4.998)
