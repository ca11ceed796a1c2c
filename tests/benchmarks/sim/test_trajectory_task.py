"""Trajectory tasks in the study engine: a perfect model tracks exactly (every law, every
shape), feedback alone lags by speed / gain as a first-order law must, a calibration error
shows in the tracking metrics, both engines give the same rows, the scenario keys are
checked."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from benchmarks.exceptions import ScenarioError
from benchmarks.sim import run_trials
from benchmarks.sim.reference import Targets
from benchmarks.sim.tracking import Tracker
from benchmarks.study.scenario import parse_scenario
from tests.benchmarks.sim.test_engine import _compare, _rows


def _scenario(task: dict[str, Any], **extra: Any) -> Any:
    table = {"name": "track", "seed": 3, "trials": 2,
             "controllers": ["leg-edge", "leg-direction", "model-based", "joint-space"],
             "controller_options": {"gain": 5.0},
             "task": {"kind": "trajectory", "speed_mm_s": 40.0, "acceleration_mm_s2": 200.0,
                      "radius_mm": 15.0, "max_steps": 330, "margin_mm": 20.0,
                      "max_translation_mm": 30.0, "angular_speed_deg_s": 5.0,
                      "angular_acceleration_deg_s2": 30.0, **task}}
    if task.get("kind", "trajectory") != "trajectory":  # (it refuses a trajectory's keys)
        table["task"] = {"margin_mm": 20.0, "max_translation_mm": 30.0, **task}
    table.update(extra)
    return parse_scenario(table)


@pytest.mark.slow
@pytest.mark.parametrize(("shape", "profile"), [("circle", "quintic"),
                                                ("lemniscate", "trapezoidal"),
                                                ("line", "trapezoidal")])
def test_a_perfect_model_tracks_exactly(shape: str, profile: str) -> None:
    """No calibration error, no noise, the kinematic world: every law follows the
    reference to the forward kinematics' tolerance (below 1e-6 mm and 1e-6 deg), within
    the strokes and the speed limit, and the row says how long the reference moved."""
    sc = _scenario({"shape": shape, "profile": profile})
    for c in range(len(sc.controllers)):
        for res in run_trials(sc, c, [0, 1]):
            row = res.row
            assert row["failure"] is None, row
            assert row["trajectory_duration_s"] > 1.0
            assert row["trajectory_duration_s"] < sc.dt * sc.task.max_steps
            assert row["tracking_max_position_mm"] < 1e-6, row
            assert row["tracking_max_orientation_deg"] < 1e-6, row
            assert row["settling_time_s"] == 0.0
            assert row["stroke_violations"] == 0


def test_feedback_alone_lags_by_speed_over_gain() -> None:
    """Without the feed-forward, the joint-space law (gain 5/s) on a pure translation at
    30 mm/s lags by v / lambda = 6 mm in the cruise (the discrete first-order law's ramp
    error is exactly v / lambda in the legs), and settles after the reference stops."""
    sc = _scenario({"shape": "line", "profile": "trapezoidal", "max_angle_deg": 0.0,
                    "feed_forward": False, "acceleration_mm_s2": 400.0,
                    "speed_mm_s": 30.0},
                   controllers=["joint-space"])
    rows = [r.row for r in run_trials(sc, 0, [0, 1])]
    for row in rows:
        assert row["tracking_max_position_mm"] == pytest.approx(30.0 / 5.0, rel=0.02)
        assert row["settling_time_s"] is not None and row["settling_time_s"] > 0.5
        assert row["tracking_max_orientation_deg"] < 0.01  # second order in the lag


def test_a_calibration_error_shows_in_the_tracking_error() -> None:
    sc = _scenario({"shape": "circle"},
                   calibration_error={"base_points_mm": 1.0, "platform_points_mm": 1.0})
    rows = [r.row for r in run_trials(sc, 3, [0, 1])]  # joint-space
    assert all(0.05 < r["tracking_rms_position_mm"] < 10.0 for r in rows)


@pytest.mark.slow
def test_both_engines_give_the_same_tracking_rows() -> None:
    sc = _scenario({"shape": "lemniscate", "max_steps": 120},
                   calibration_error={"base_points_mm": 1.0, "camera_pose_mm": 2.0},
                   noise={"model": "rotation", "amplitude_deg": 0.01})
    batched, per_trial = _rows(sc, "batched", 2), _rows(sc, "per-trial", 2)
    assert "tracking_rms_position_mm" in batched[0]
    _compare(per_trial, batched)


def test_point_to_point_rows_have_no_tracking_fields() -> None:
    sc = _scenario({"kind": "random-pairs", "max_steps": 20}, controllers=["joint-space"])
    row = run_trials(sc, 0, [0])[0].row
    assert "tracking_rms_position_mm" not in row and "settling_time_s" not in row


def test_tracker_settling_time() -> None:
    """A hand-made error history: out of tolerance until 0.3 s after the reference's end
    (the book's last period out of tolerance is the tracker's settling)."""
    sc = _scenario({"shape": "circle", "max_steps": 400})
    setups = _setups(sc, 1)
    tr = Tracker(sc, Targets(sc, setups).duration)
    end = tr.duration[0]
    idx = np.array([0])
    last = -1
    for step in range(sc.task.max_steps + 1):
        t = step * sc.dt
        dp = np.array([2e-4 if t < end + 0.3 else 0.0])
        tr.add(step, idx, dp, np.zeros(1))
        last = step if dp[0] >= 1e-4 else last
    row = tr.row(0, last)
    moving = np.arange(sc.task.max_steps + 1) * sc.dt <= end + 1e-12
    assert row["tracking_rms_position_mm"] == pytest.approx(0.2)
    assert row["tracking_max_position_mm"] == pytest.approx(0.2)
    assert tr.count[0] == moving.sum()
    assert row["settling_time_s"] == pytest.approx(0.3, abs=sc.dt)


@pytest.mark.parametrize("n", [1, 7, 200])
def test_tracker_sums_the_drive_forces_as_np_sum(n: int) -> None:
    """The squared drive forces summed leg by leg (no reduction along a row) are np.sum's
    to the last bit, rows given as a slice or as indices."""
    sc = _scenario({"shape": "circle", "max_steps": 40})
    rng = np.random.default_rng(n)
    forces = rng.normal(scale=300.0, size=(n, 6)) * rng.choice([1e-3, 1.0, 1e3], size=(n, 6))
    tr = Tracker(sc, np.ones(n))
    tr.drive_forces = lambda rows: forces[rows]
    expected = np.zeros(n)
    for step, rows in enumerate([slice(None), np.arange(n)[::2], slice(None)]):
        tr.add(step, rows, np.zeros(n)[rows], np.zeros(n)[rows])
        expected[rows] += np.sum(forces[rows] ** 2, axis=1)
    assert tr.sum_f2.tobytes() == expected.tobytes()
    assert tr.count_f.tolist() == [18 if k % 2 == 0 else 12 for k in range(n)]


def _setups(sc: Any, n: int) -> list[Any]:
    from benchmarks.sim.world import load_camera, load_geometry, make_trials

    g = load_geometry(sc)
    return make_trials(sc, list(range(n)), g, load_camera(sc, g))  # type: ignore[return-value]


@pytest.mark.parametrize(("task", "key"), [
    ({"kind": "trajectory", "shape": "spiral"}, "task.shape"),
    ({"kind": "trajectory", "profile": "cubic"}, "task.profile"),
    ({"kind": "trajectory", "speed_mm_s": 0.0}, "task.speed_mm_s"),
    ({"kind": "trajectory", "laps": 0}, "task.laps"),
    ({"kind": "random-pairs", "speed_mm_s": [10.0, 20.0]}, "task.speed_mm_s"),
    # a fixed task's lengths in another task: random pairs ran, the lengths ignored
    ({"start_mm": [375.0] * 6, "goal_mm": [375.0] * 6}, "task.start_mm"),
    ({"kind": "trajectory", "goal_mm": [375.0] * 6}, "task.goal_mm"),
    # forced to true without a word
    ({"kind": "trajectory", "fixed_duration": False}, "task.fixed_duration"),
])
def test_bad_trajectory_keys_are_refused(task: dict[str, Any], key: str) -> None:
    with pytest.raises(ScenarioError) as info:
        parse_scenario({"name": "x", "controllers": ["leg-edge"], "task": task})
    assert info.value.key == key


def test_a_trajectory_task_sweeps_its_speed() -> None:
    sc = parse_scenario({"name": "x", "controllers": ["leg-edge"],
                         "task": {"kind": "trajectory", "speed_mm_s": [10.0, 20.0]}})
    points = sc.expand()
    assert [p.task.speed_mm_s for p in points] == [10.0, 20.0]
    assert all(p.task.fixed_duration for p in points)
