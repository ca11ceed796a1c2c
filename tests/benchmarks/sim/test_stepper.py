"""A scenario point's trials are drawn once for all its controllers
(:func:`benchmarks.sim.stepper.point_trials`), each run with its own copies."""

from __future__ import annotations

from dataclasses import fields
from typing import Any

import numpy as np
import pytest

from benchmarks.sim import stepper
from benchmarks.sim.world import TrialSetup, load_camera, load_geometry, make_trials
from benchmarks.study.scenario import load_scenario

#: Fields of a row that are timings (they differ between runs).
VOLATILE = {"step_time_us"}


def _counting(monkeypatch: pytest.MonkeyPatch) -> list[list[int]]:
    """Record the trials of every :func:`make_trials` call of the stepper."""
    calls: list[list[int]] = []

    def counted(sc: Any, trials: list[int], *args: Any) -> Any:
        calls.append(list(trials))
        return make_trials(sc, trials, *args)

    monkeypatch.setattr(stepper, "make_trials", counted)
    return calls


def _arrays(s: TrialSetup) -> list[np.ndarray]:
    """Every writable array of a setup and of its world, found by their fields (a field
    added later is covered without naming it here)."""
    found = [getattr(obj, f.name) for obj in (s, s.world) for f in fields(obj)]
    arrays = [a for a in found if isinstance(a, np.ndarray) and a.flags.writeable]
    assert len(arrays) >= 7, "the setup's writable arrays were not found"
    return arrays


def test_a_trial_written_into_by_one_run_does_not_leak_into_the_next(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The second call draws nothing and gets the drawn setups' values, whatever the
    first call's consumer wrote into its arrays and its calibration summary."""
    calls = _counting(monkeypatch)
    sc = load_scenario("quick").with_overrides(trials=3)
    first = stepper.point_trials(sc, [0, 1, 2])
    for s in first:
        assert isinstance(s, TrialSetup)
        for a in _arrays(s):
            a[...] = np.nan
        s.calibration["median_error_mm"] = -1.0
    second = stepper.point_trials(sc, [0, 1, 2])
    assert calls == [[0, 1, 2]]
    nominal = load_geometry(sc)
    fresh = make_trials(sc, [0, 1, 2], nominal, load_camera(sc, nominal))
    for s, f in zip(second, fresh, strict=True):
        assert isinstance(s, TrialSetup) and isinstance(f, TrialSetup)
        for a, b in zip(_arrays(s), _arrays(f), strict=True):
            assert np.array_equal(a, b)
        assert s.calibration == f.calibration == {}
    stepper.point_trials(sc.with_overrides(seed=2), [0, 1, 2])  # another point: drawn
    assert calls == [[0, 1, 2], [0, 1, 2]]


@pytest.mark.slow
def test_a_points_trials_are_drawn_once_for_all_its_controllers(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Every controller of a point after the first takes the drawn trials, and its rows
    are those of trials drawn for it alone."""
    sc = load_scenario("quick").with_overrides(trials=2, max_steps=40)
    trials = [0, 1]

    def rows(fresh: bool) -> list[dict[str, Any]]:
        out = []
        for c in range(len(sc.controllers)):
            if fresh:
                stepper.forget_trials()
            out += [{k: v for k, v in r.row.items() if k not in VOLATILE}
                    for r in stepper.run_trials(sc, c, trials)]
        return out

    alone = rows(fresh=True)
    calls = _counting(monkeypatch)
    stepper.forget_trials()
    assert rows(fresh=False) == alone
    assert calls == [trials]
    assert len(sc.controllers) == 5


def test_a_points_targets_are_sampled_once_for_all_its_controllers() -> None:
    """The second controller's book measures against the targets sampled for the first
    (the same object), equal to targets sampled afresh; another point samples its own."""
    from benchmarks.sim.reference import Targets

    point = load_scenario("paccot2008-tracking").with_overrides(trials=2).expand()[0]
    group = stepper.point_trials(point, [0, 1])
    first = stepper.point_targets(point, group)
    again = stepper.point_trials(point, [0, 1])
    assert stepper.point_targets(point, again) is first
    fresh = Targets(point, group)
    rows = np.arange(2)
    for step in (0, 17, point.task.max_steps):
        for a, b in zip(first(step, rows), fresh(step, rows), strict=True):
            assert np.array_equal(a, b)
    assert first.duration is not None and np.array_equal(first.duration, fresh.duration)
    other = point.with_overrides(seed=2)
    assert stepper.point_targets(other, stepper.point_trials(other, [0, 1])) is not first
    stepper.forget_trials()


def test_the_run_takes_the_preflights_draws_of_an_equal_point(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The trajectory pre-flight's draws of a point are the run's when the run's point is
    equal and nothing calibrates: no second draw, the same values as a fresh draw, each
    trial taken once; another point, or a calibration, draws its own."""
    from benchmarks.study.trajectory_check import sampled_setups

    stepper.forget_trials()
    calls = _counting(monkeypatch)
    sc = load_scenario("paccot2008-tracking").with_overrides(trials=3)
    checked, run = sc.expand()[0], sc.expand()[0]  # equal points, not the same object
    assert checked is not run
    assert len(sampled_setups(checked, 3)) == 3
    assert calls == [[0, 1, 2]]
    taken = stepper.point_trials(run, [0, 1, 2])
    assert calls == [[0, 1, 2]]  # taken, not drawn again
    assert all(not m for _, m in stepper._preflight)  # each trial taken once
    nominal = load_geometry(run)
    fresh = make_trials(run, [0, 1, 2], nominal, load_camera(run, nominal))
    for s, f in zip(taken, fresh, strict=True):
        assert isinstance(s, TrialSetup) and isinstance(f, TrialSetup)
        for a, b in zip(_arrays(s), _arrays(f), strict=True):
            assert np.array_equal(a, b)
    stepper.forget_trials()
    sampled_setups(checked, 3)
    stepper.point_trials(run.with_overrides(seed=2), [0, 1, 2])  # another point: drawn
    stepper.point_trials(run, [0, 1, 2], calibrate=lambda world, rng: (np.zeros((6, 3)), {}))
    assert calls == [[0, 1, 2]] * 4  # the calibrated run draws its own
    stepper.forget_trials()
    assert not stepper._preflight
