"""The camera's exposure time (``[clock] exposure_ms``): a frame is exposed over the
``T`` before its capture instant, the sensor gets the true poses at the midpoints of the
exposure's slices (where the plant was then), the frame's timestamp is the middle of the
exposure, and a scenario without rendered images is refused."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from benchmarks.exceptions import ScenarioError
from benchmarks.sim import run_trials
from benchmarks.study.scenario import parse_scenario
from controllers.base import ObservationBatch
from tests.benchmarks.sim.clock_world import RECORDER, Recorder, clock_world
from tests.benchmarks.sim.clock_world import frame as _frame

IMAGE = {"kind": "image", "blur_px": 0.8, "noise_std": 2.0}


def _scenario(clock: dict[str, Any], **extra: Any) -> Any:
    table: dict[str, Any] = {"name": "exposure", "seed": 3, "trials": 2,
                             "controllers": ["leg-edge"], "sensor": IMAGE,
                             "task": {"max_steps": 5, "fixed_duration": True},
                             "clock": clock}
    table.update(extra)
    return parse_scenario(table)


@pytest.mark.parametrize("exposure", [10.0, [0.0, 10.0]])
def test_exposure_needs_rendered_images(exposure: Any) -> None:
    with pytest.raises(ScenarioError) as info:
        parse_scenario({"name": "x", "controllers": ["leg-edge"],
                        "clock": {"exposure_ms": exposure}}, "blur.toml")
    assert info.value.key == "clock.exposure_ms" and "blur.toml" in str(info.value)


@pytest.mark.parametrize(("clock", "key"), [({"exposure_ms": -1.0}, "clock.exposure_ms"),
                                            ({"exposure_ms": 5.0, "exposure_samples": 0},
                                             "clock.exposure_samples")])
def test_bad_exposure_keys_are_refused(clock: dict[str, Any], key: str) -> None:
    with pytest.raises(ScenarioError) as info:
        _scenario(clock)
    assert info.value.key == key


def test_the_exposed_poses_are_where_the_plant_was() -> None:
    """A 100 Hz camera exposing 8 ms in 4 slices, 13 ms late: at 40 ms the newest frame
    delivered is the one captured at 20 ms (at 33 ms), exposed over [12, 20] ms: its four
    poses are the plant's at 13, 15, 17 and 19 ms (moving with the first period's
    command), its timestamp 16 ms."""
    sc = _scenario({"frame_rate_hz": 100.0, "latency_ms": 13.0, "exposure_ms": 8.0,
                    "exposure_samples": 4})
    w = clock_world(sc)
    seen: list[tuple[np.ndarray, np.ndarray]] = []

    def keep(rows: np.ndarray, Rr: np.ndarray, tr: np.ndarray) -> ObservationBatch:
        seen.append((Rr, tr))
        return _frame(len(rows))

    w.clock.measure(0, w.rows, keep)
    w.advance()
    w.clock.measure(1, w.rows, keep)
    w.advance()
    out = w.clock.measure(2, w.rows, keep)
    np.testing.assert_allclose(out.image_t, [0.016, 0.016], atol=1e-12)
    R_s, t_s = seen[-1]
    assert R_s.shape == (2, 4, 3, 3) and t_s.shape == (2, 4, 3)
    for j, when in enumerate((0.013, 0.015, 0.017, 0.019)):
        part = w.moved_from_start(when)
        np.testing.assert_allclose(t_s[:, j], part.t, atol=1e-12)
        np.testing.assert_allclose(R_s[:, j], part.R, atol=1e-12)
    assert np.linalg.norm(t_s[:, 0] - t_s[:, 3]) > 1e-5  # the robot moved during it


def test_a_blurred_study_runs_and_its_images_are_half_an_exposure_old() -> None:
    """Rendered images exposed 10 ms at every control instant: every observation's
    image is 5 ms old (the middle of its exposure), the trial runs to its end."""
    Recorder.seen = []
    sc = _scenario({"exposure_ms": 10.0},
                   controllers=[RECORDER])
    (res,) = run_trials(sc, 0, [0])
    assert res.row["failure"] is None or "not converged" in res.row["failure"]
    t, image_t = np.array(Recorder.seen, dtype=float).T
    np.testing.assert_allclose(t - image_t, 0.005, atol=1e-12)
    assert len(t) == 5
