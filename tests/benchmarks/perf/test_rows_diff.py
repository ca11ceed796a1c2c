"""``benchmarks.perf.rows_diff diff``: two runs' folders compared row by row (written here
as a run writes them: ``NAME/results.jsonl`` and ``NAME/trials/*.npz``), what only one
run has named, the controllers whose rows or series differ named. A trial's series are
the arrays of its ``.npz`` (its controller's name among them, as a run writes it)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from benchmarks.perf.rows_diff import diff


def _run(root: Path, name: str, rows: list[tuple[str, int, float]],
         series: dict[tuple[str, int], np.ndarray] | None = None) -> None:
    """A scenario's folder: one row per (controller, trial, final error [mm]), a trial's
    recorded series where ``series`` gives one."""
    folder = root / name
    (folder / "trials").mkdir(parents=True)
    with open(folder / "results.jsonl", "w") as f:
        for controller, trial, error in rows:
            f.write(json.dumps({"scenario": name, "point": 0, "controller": controller,
                                "trial": trial, "final_position_error_mm": error,
                                "step_time_us": 10.0 + trial}) + "\n")
    for (controller, trial), values in (series or {}).items():
        np.savez(folder / "trials" / f"{name}__p0__{controller}__{trial:05d}.npz",
                 controller=np.array(controller), t=np.arange(len(values)) * 0.02,
                 error_norm=values)


def test_equal_runs_are_bitwise_and_timings_are_left_out(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    curve = np.array([3.0, 1.0, 0.5])
    for side in ("a", "b"):
        _run(tmp_path / side, "quick", [("leg-edge", 0, 0.25), ("joint-space", 0, 0.5)],
             {("leg-edge", 0): curve})
    # (the step times differ between the runs' rows in real runs: a timing, not a result)
    assert diff(str(tmp_path / "a"), str(tmp_path / "b")) == 0
    assert capsys.readouterr().out == "quick: 2 rows, 3 series: bitwise\n"


def test_what_differs_is_named_by_controller_and_what_one_run_has_alone(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Scenario ``mpc``: ``leg-edge-mpc``'s row differs by 2e-5 mm (relative to max(1,
    |x|)) and ``leg-edge``'s series by 0.25; ``tracking``: the common rows equal, the new
    run's added controller (two trials) named and counted; ``added``: a scenario only the
    new run has, named and not compared."""
    a, b = tmp_path / "a", tmp_path / "b"
    _run(a, "mpc", [("leg-edge", 0, 0.5), ("leg-edge-mpc", 0, 2.0)],
         {("leg-edge", 0): np.array([1.0, 0.5])})
    _run(b, "mpc", [("leg-edge", 0, 0.5), ("leg-edge-mpc", 0, 2.00004)],
         {("leg-edge", 0): np.array([1.0, 0.25])})
    _run(a, "tracking", [("computed-torque", 0, 1.0)])
    _run(b, "tracking", [("computed-torque", 0, 1.0), ("force-mpc", 0, 0.1),
                         ("force-mpc", 1, 0.2)])
    _run(b, "added", [("leg-edge", 0, 0.1)])
    assert diff(str(a), str(b)) == 2
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == f"added: only in {b} (not compared)"
    assert lines[1] == ("mpc: 2 rows, 3 series: max relative difference of a row field 2e-05, "
                        "of a series 0.25 (controllers leg-edge, leg-edge-mpc)")
    assert lines[2] == (f"tracking: 1 rows, 0 series: bitwise; 2 rows only in {b}: "
                        "force-mpc (2)")
    assert len(lines) == 3


def test_a_series_the_second_run_lost_differs_and_a_new_one_does_not(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A series recorded by the first run only makes its controller differ; one recorded
    by the second run only (a new recording, as a new row field) is not compared."""
    a, b = tmp_path / "a", tmp_path / "b"
    for side in (a, b):
        _run(side, "quick", [("leg-edge", 0, 0.25)], {("leg-edge", 0): np.array([1.0])})
    trial = "trials/quick__p0__leg-edge__00000.npz"
    np.savez(b / "quick" / trial, controller=np.array("leg-edge"), t=np.zeros(1),
             error_norm=np.array([1.0]), forces=np.zeros(1))  # a new series
    assert diff(str(a), str(b)) == 0
    np.savez(b / "quick" / trial, controller=np.array("leg-edge"), t=np.zeros(1))
    assert diff(str(a), str(b)) == 1
    out = capsys.readouterr().out.splitlines()
    assert out[0] == "quick: 1 rows, 3 series: bitwise"
    assert out[1].startswith("quick: 1 rows, 3 series: max relative difference of a row "
                             "field 0, of a series 0 (controllers leg-edge); other "
                             "differences: [(")
    assert "'error_norm', 'not in'" in out[1]
