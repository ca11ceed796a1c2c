"""The batched engine gives the rows of the per-trial path, on every built-in scenario that
it runs (geometric sensor), whatever the controller: built-in ones step as arrays, a plugin
without ``step_batch`` goes through a per-trial loop in the same study."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from benchmarks.sim import run_trials
from benchmarks.study.calibration import calibration_hook
from benchmarks.study.scenario import ControllerSpec, builtin_scenarios, load_scenario
from controllers.batch import batch_controller
from controllers.law_rows import ACCEPTED, LawRows
from tests.benchmarks.plugins import ProportionalJoints

#: Fields that legitimately differ between the two paths (the controller's timing).
VOLATILE = {"step_time_us"}
GEOMETRIC = [name for name in builtin_scenarios()
             if load_scenario(name).sensor == "geometric"]
PLUGIN = "tests.benchmarks.plugins:ProportionalJoints"


def _diagonal(sc: Any) -> list[Any]:
    """The points of a scenario's sweep along its diagonal: the k-th value of every swept
    key together (a shorter key's last value repeated), so that every value of every key
    runs (all the points of a one-key sweep; 8 of calibration-map's 8 x 8)."""
    axes = sc.sweep_axes
    n = max((len(v) for v in axes.values()), default=1)
    want = [{k: v[min(i, len(v) - 1)] for k, v in axes.items()} for i in range(n)]
    points = [p for p in sc.expand() if not axes or p.sweep in want]
    assert len(points) == n
    return points


def _rows(sc: Any, engine: str, trials: int, diagonal: bool = False) -> list[dict[str, Any]]:
    out = []
    for p, point in enumerate(_diagonal(sc) if diagonal else sc.expand()):
        for c in range(len(point.controllers)):
            for res in run_trials(point, c, list(range(trials)), record_trials=1,
                                  calibrate=calibration_hook(point), engine=engine):
                row = {k: v for k, v in res.row.items() if k not in VOLATILE}
                row["point"] = p
                out.append(row)
                if res.series is not None:
                    row["series"] = res.series
    return out


def _compare(a: list[dict[str, Any]], b: list[dict[str, Any]]) -> None:
    assert len(a) == len(b)
    for x, y in zip(a, b, strict=True):
        sx, sy = x.pop("series", None), y.pop("series", None)
        assert x.keys() == y.keys(), (x, y)
        for key in x:
            if isinstance(x[key], float) and isinstance(y[key], float):
                assert abs(x[key] - y[key]) <= 1e-9 * max(1.0, abs(x[key])), (key, x, y)
            else:
                assert x[key] == y[key], (key, x, y)
        assert (sx is None) == (sy is None)
        if sx is not None:
            for key in sx:
                np.testing.assert_allclose(np.asarray(sx[key], float),
                                           np.asarray(sy[key], float), rtol=0, atol=1e-12,
                                           err_msg=key)


@pytest.mark.slow
@pytest.mark.parametrize("name", GEOMETRIC)
def test_batched_rows_equal_the_per_trial_rows(name: str) -> None:
    """Every built-in scenario with the geometric sensor (2 trials per controller at every
    value of each swept key, 60 periods): the same rows, final errors to 1e-9 mm, the
    same convergence and steps, the same recorded series."""
    sc = load_scenario(name).with_overrides(trials=2, max_steps=60)
    _compare(_rows(sc, "per-trial", 2, diagonal=True), _rows(sc, "batched", 2, diagonal=True))


@pytest.mark.slow
def test_a_plugin_without_step_batch_runs_in_the_same_study() -> None:
    sc = load_scenario("quick").with_overrides(trials=3, max_steps=200)
    sc = replace(sc, controllers=(ControllerSpec(PLUGIN, PLUGIN, {"gain": 4.0}),
                                  ControllerSpec("leg-edge", "leg-edge", {"gain": 4.0})))
    assert isinstance(batch_controller(PLUGIN, {}), ProportionalJoints)
    assert "step_batch" not in vars(ProportionalJoints)  # stepped by the base's adapter
    batched, per_trial = _rows(sc, "batched", 3), _rows(sc, "per-trial", 3)
    _compare(per_trial, batched)
    plugin_rows = [r for r in batched if r["controller"] == PLUGIN]
    assert len(plugin_rows) == 3 and all(r["failure"] is None or "not conv" in r["failure"]
                                         for r in plugin_rows)


@pytest.mark.parametrize("name", ["quick", "tahri2009-convergence"])
def test_batched_rows_equal_the_per_trial_rows_in_the_dynamic_world(name: str) -> None:
    """The dynamic world (mass, drives, encoders; quick with 20 % mass and inertia errors,
    every trial its own robot; tahri2009 with one shared robot): the same rows, drive
    figures and recorded series (leg forces included) on both paths."""
    sc = load_scenario(name).with_overrides(trials=2, max_steps=60)
    sc = replace(sc, world="dynamic", controllers=sc.controllers[:2])
    if name == "quick":
        sc = replace(sc, calibration_error=replace(sc.calibration_error, mass_percent=20.0,
                                                   inertia_percent=20.0))
    per_trial, batched = _rows(sc, "per-trial", 2), _rows(sc, "batched", 2)
    assert all("leg_forces" in r["series"] for r in batched if "series" in r)
    assert all(r["max_leg_force_n"] > 0 and r["drive_tracking_rms_mm_s"] > 0 for r in batched)
    _compare(per_trial, batched)


@pytest.mark.slow
@pytest.mark.parametrize("interaction", ["desired", "mean"])
def test_batched_rows_equal_the_per_trial_rows_with_the_desired_or_mean_interaction(
        interaction: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """The DESIRED and MEAN cores in the batch's lean loop: the per-trial rows."""
    sc = load_scenario("quick").with_overrides(trials=3, max_steps=100)
    options = {"interaction": interaction, "adaptive_gain": [5.0, 1.0, 30.0]}
    sc = replace(sc, controllers=tuple(ControllerSpec(n, n, dict(options))
                                       for n in ("leg-direction", "leg-edge", "leg-edge-qp")))
    per_trial = _rows(sc, "per-trial", 3)
    fast_rows: list[int] = []
    real = LawRows.step

    def counting(self: LawRows, *args: Any) -> tuple[np.ndarray, np.ndarray]:
        code, Y = real(self, *args)
        if len(code) > 1:
            fast_rows.append(int(np.count_nonzero(code == ACCEPTED)))
        return code, Y

    monkeypatch.setattr(LawRows, "step", counting)
    batched = _rows(sc, "batched", 3)
    assert sum(fast_rows) > 100  # the lean core stepped the common case
    _compare(per_trial, batched)
