"""The tracking table's drive forces in the dynamic world: the peak force, the RMS force
and the time at a force limit of every row agree with the values recomputed from the
recorded trial's forces (one physics step per control period, so the recorded samples
are every force the drives produced), the table's cells are the medians and the worst
of the rows, and the forces figure draws the recorded forces."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from benchmarks.cli import main as cli_main
from benchmarks.study.results import read_results
from benchmarks.study.tracking_figures import forces_figure
from benchmarks.study.tracking_report import (
    FORCE_HEADER,
    HEADER,
    tracking_header,
    tracking_rows,
)
from hexapod.geometry import deltalab

LIMIT = 12.0  # [N]: low enough that a fast line saturates some drives, not all the time
DT = 0.01


def _scenario(tmp_path: Path) -> Path:
    g = deltalab()
    g = g.replace(drives=g.drives.replace(force_limit=np.full(6, LIMIT)))
    g.to_toml(tmp_path / "weak.toml")
    path = tmp_path / "forces.toml"
    path.write_text(f"""name = "forces"
seed = 3
trials = 2
controllers = ["joint-space", "computed-torque"]
[robot]
geometry = "weak.toml"
world = "dynamic"
dt = {DT}
physics_dt = {DT}
[task]
kind = "trajectory"
shape = "line"
profile = "trapezoidal"
speed_mm_s = 60.0
acceleration_mm_s2 = 2000.0
max_steps = 200
margin_mm = 20.0
max_translation_mm = 30.0
""")
    return path


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[dict]]:
    tmp = tmp_path_factory.mktemp("forces")
    out = tmp / "out"
    assert cli_main(["run", str(_scenario(tmp)), "--out", str(out), "--no-progress",
                     "--record", "1"]) == 0
    return out, read_results(out)


def _recorded(out: Path, controller: str) -> dict[str, np.ndarray]:
    (f,) = (out / "trials").glob(f"forces__p0__{controller}__00000.npz")
    with np.load(f) as rec:
        return {k: rec[k] for k in rec.files}


@pytest.mark.slow
@pytest.mark.parametrize("controller", ["joint-space", "computed-torque"])
def test_row_forces_agree_with_the_recorded_trial(run: tuple[Path, list[dict]],
                                                  controller: str) -> None:
    """Peak = largest |f| of the record, RMS = sqrt(mean f^2) over its periods and legs,
    time at the limit = dt x periods where some |f| reached the limit (velocity drives
    and force drives)."""
    out, rows = run
    rec = _recorded(out, controller)
    (row,) = [r for r in rows if r["controller"] == controller and r["trial"] == 0]
    f = rec["leg_forces"]
    assert f.shape == (len(rec["t"]), 6) and f.shape[0] > 100
    np.testing.assert_array_equal(rec["force_limit"], np.full(6, LIMIT))
    assert row["max_leg_force_n"] == pytest.approx(np.abs(f).max(), rel=1e-12)
    assert row["rms_leg_force_n"] == pytest.approx(np.sqrt(np.mean(f**2)), rel=1e-12)
    at_limit = np.any(np.abs(f) >= LIMIT * (1 - 1e-12), axis=1)
    # the sample of period k is the force the drives ended period k-1 with
    assert row["saturation_time_s"] == pytest.approx(DT * at_limit[1:].sum(), abs=1e-12)
    assert row["saturation_time_s"] > 0  # the case is one that reaches the limit


@pytest.mark.slow
def test_the_study_reaches_and_misses_the_limit(run: tuple[Path, list[dict]]) -> None:
    """Not a degenerate case: some trial saturates for part of its motion only."""
    _, rows = run
    sat = [r["saturation_time_s"] for r in rows]
    assert any(0 < s < 0.5 * r["trajectory_duration_s"] for s, r in zip(sat, rows, strict=True))
    assert all(r["max_leg_force_n"] <= LIMIT * (1 + 1e-12) for r in rows)


@pytest.mark.slow
def test_table_cells_are_the_groups_medians_and_worst(run: tuple[Path, list[dict]]) -> None:
    out, rows = run
    assert tracking_header(rows) == HEADER + FORCE_HEADER
    table = tracking_rows(rows)
    assert len(table) == 2
    for cells in table:
        rs = [r for r in rows if r["controller"] == cells[1]]
        peak = [r["max_leg_force_n"] for r in rs]
        sat = [r["saturation_time_s"] for r in rs]
        expected = [np.median(peak), max(peak), np.median([r["rms_leg_force_n"] for r in rs]),
                    np.median(sat), max(sat)]
        # the medians with their intervals (three decimals), the worst alone
        got = [float(c.split(" [")[0]) for c in cells[len(HEADER):]]
        np.testing.assert_allclose(got, expected, rtol=5e-3, atol=5e-4)
        assert all("[" in cells[len(HEADER) + k] for k in (0, 2, 3))
    report = (out / "report.md").read_text()
    assert "peak N (median)" in report and "forces_p0_forces.png" in report
    assert (out / "forces_p0_forces.png").stat().st_size > 1000


@pytest.mark.slow
def test_the_forces_figure_draws_the_recorded_forces(run: tuple[Path, list[dict]]) -> None:
    out, _ = run
    fig = forces_figure(out, "forces", 0)
    assert len(fig.axes) == 2
    for ax in fig.axes:
        controller = ax.get_title().split(":")[0]
        rec = _recorded(out, controller)
        legs = [ln for ln in ax.get_lines() if ln.get_label().startswith("leg ")]
        assert len(legs) == 6
        for i, ln in enumerate(legs):
            np.testing.assert_array_equal(ln.get_xdata(), rec["t"])
            np.testing.assert_array_equal(ln.get_ydata(), rec["leg_forces"][:, i])
        limits = sorted(float(ln.get_ydata()[0]) for ln in ax.get_lines()
                        if ln.get_linestyle() == "--")
        assert limits == [-LIMIT, LIMIT]


def test_kinematic_rows_have_no_force_columns() -> None:
    rows = [{"controller": "leg-edge", "point": 0, "tracking_rms_position_mm": 0.1,
             "tracking_max_position_mm": 0.2, "tracking_rms_orientation_deg": 0.01,
             "settling_time_s": 0.0}]
    assert tracking_header(rows) == HEADER
    assert len(tracking_rows(rows)[0]) == len(HEADER)
