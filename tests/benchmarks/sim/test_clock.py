"""The camera's clock: a camera at the control rate without latency is the clock-less
engine bit for bit; frames are as old as the latency and the frame period say; the pose
of a frame between two control instants is where the robot was then; both engines give
the same rows; latency compensation is exact when the model is exact."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from benchmarks.exceptions import ScenarioError
from benchmarks.sim import run_trials
from benchmarks.sim.clock import CameraClock
from benchmarks.sim.world import load_camera, load_geometry, make_trials
from benchmarks.study.scenario import parse_scenario
from controllers.base import ObservationBatch
from tests.benchmarks.sim.clock_world import RECORDER, Recorder, clock_world
from tests.benchmarks.sim.clock_world import frame as _frame
from tests.benchmarks.sim.test_engine import _compare, _rows

CIRCLE = {"kind": "trajectory", "shape": "circle", "speed_mm_s": 40.0,
          "acceleration_mm_s2": 200.0, "radius_mm": 15.0, "max_steps": 260,
          "margin_mm": 20.0, "max_translation_mm": 30.0}
POINT = {"max_steps": 100, "fixed_duration": True}


def _scenario(clock: dict[str, Any], task: dict[str, Any] | None = None,
              controllers: list[Any] | None = None, **extra: Any) -> Any:
    table: dict[str, Any] = {"name": "clock", "seed": 3, "trials": 3,
                             "controllers": controllers or ["leg-edge", "joint-space"],
                             "controller_options": {"gain": 5.0}, "task": task or POINT,
                             "clock": clock}
    table.update(extra)
    return parse_scenario(table)


def _strip(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return [{k: v for k, v in r.items() if k not in ("series",)} for r in rows]


@pytest.mark.slow
def test_a_camera_at_the_control_rate_is_the_engine_without_clock() -> None:
    extra = {"noise": {"model": "rotation", "amplitude_deg": 0.01},
             "calibration_error": {"base_points_mm": 0.5}}
    plain = _scenario({}, **extra)
    clocked = _scenario({"frame_rate_hz": 50.0}, **extra)  # dt = 20 ms
    for engine in ("batched", "per-trial"):
        a, b = _strip(_rows(plain, engine, 3)), _strip(_rows(clocked, engine, 3))
        assert a == b  # bit for bit


@pytest.mark.slow
def test_both_engines_give_the_same_rows_with_a_clock() -> None:
    sc = _scenario({"frame_rate_hz": 30.0, "latency_frames": 2.0, "jitter_ms": 2.0},
                   controllers=["leg-edge", "joint-space",
                                {"name": "latency-compensated", "law": "leg-direction"}],
                   noise={"model": "rotation", "amplitude_deg": 0.01},
                   calibration_error={"base_points_mm": 0.5, "camera_pose_mm": 1.0})
    _compare(_rows(sc, "per-trial", 3), _rows(sc, "batched", 3))


@pytest.mark.parametrize(("clock", "lo", "hi"), [
    # 30 Hz frames against 50 Hz control: the age cycles through the frame period
    ({"frame_rate_hz": 30.0, "latency_frames": 2.0}, 2 / 30, 3 / 30),
    # 1 kHz frames, 25 ms late: a frame lands on every control instant, always 25 ms old
    ({"frame_rate_hz": 1000.0, "latency_ms": 25.0}, 0.025, 0.025),
    ({"frame_rate_hz": 100.0, "latency_frames": 1.0, "jitter_ms": 2.0}, 0.01 - 0.0045,
     0.02 + 0.0045 + 0.0045),
])
@pytest.mark.parametrize("engine", ["batched", "per-trial"])
def test_images_are_as_old_as_the_clock_says(clock: dict[str, Any], lo: float, hi: float,
                                             engine: str) -> None:
    Recorder.seen = []
    sc = _scenario(clock, controllers=[RECORDER])
    run_trials(sc, 0, [0], engine=engine)
    t, image_t = np.array(Recorder.seen, dtype=float).T
    age = t - image_t
    assert len(age) == 100 and np.all(age >= lo - 1e-9) and np.all(age <= hi + 1e-9)
    assert age.max() - age.min() >= 0.5 * (hi - lo)  # the age sweeps its range
    assert np.all(np.diff(image_t) >= 0)  # frames in order


def test_the_pose_of_a_frame_between_instants_is_where_the_plant_was() -> None:
    """A frame captured 7 ms after a control instant sees the pose the kinematic plant
    reaches by moving 7 ms with that period's command; a frame on an instant sees that
    instant's pose, and one captured before the start the start pose."""
    sc = _scenario({"frame_rate_hz": 50.0, "latency_ms": 13.0})
    w = clock_world(sc)
    seen: list[np.ndarray] = []

    def keep(rows: np.ndarray, Rr: np.ndarray, tr: np.ndarray) -> ObservationBatch:
        seen.append(tr)
        return _frame(len(rows))

    w.clock.measure(0, w.rows, keep)  # at 0: the frame of -20 ms (delivered at -7 ms)
    np.testing.assert_array_equal(seen[-1], w.start[2])
    w.advance()
    after = w.t.copy()
    w.clock.measure(1, w.rows, keep)  # at 20 ms: the frame of 0 ms (delivered at 13 ms)
    np.testing.assert_array_equal(seen[-1], w.start[2])
    R_c, t_c = w.clock._poses_at(w.rows, np.array([0.007, 0.007]), 1)
    part = w.moved_from_start(0.007)
    np.testing.assert_allclose(t_c, part.t, atol=1e-12)
    np.testing.assert_allclose(R_c, part.R, atol=1e-12)
    assert np.linalg.norm(t_c - after) > 1e-4  # not the instant's pose
    R_e, t_e = w.clock._poses_at(w.rows, np.array([0.02, 0.02]), 1)
    np.testing.assert_array_equal(t_e, after)
    np.testing.assert_array_equal(R_e, w.R)


def test_jitter_has_its_standard_deviation() -> None:
    sc = _scenario({"frame_rate_hz": 100.0, "jitter_ms": 1.0}, task={"max_steps": 5000})
    g = load_geometry(sc)
    setups = make_trials(sc, [0], g, load_camera(sc, g))
    z = np.zeros((1, 6))
    clock = CameraClock(sc, setups, z, np.eye(3)[None], np.zeros((1, 3)), g.base_points,
                        g.platform_points)
    jitter = clock.capture[0] - np.round(clock.capture[0] / 0.01) * 0.01
    assert len(jitter) > 10000
    assert np.std(jitter) == pytest.approx(1e-3, rel=0.05)
    assert np.abs(jitter).max() <= 0.45 * 0.01


@pytest.mark.slow
@pytest.mark.parametrize("task", [POINT, CIRCLE])
@pytest.mark.parametrize("law", ["leg-edge", "leg-direction"])
def test_latency_compensation_is_exact_with_an_exact_model(task: dict[str, Any],
                                                           law: str) -> None:
    """No calibration error, no noise, the kinematic world: with a 30 Hz camera one frame
    late, or 100 Hz three frames late with 1 ms jitter, the compensated law moves the
    robot as the law does with images taken at the control instants (final errors and
    tracking errors equal to 1e-9 mm); without compensation the latency shows."""
    spec = [{"name": "latency-compensated", "law": law}, law]
    ref = [r.row for r in run_trials(_scenario({}, task, spec), 1, [0, 1])]
    for clock in ({"frame_rate_hz": 30.0, "latency_frames": 1.0},
                  {"frame_rate_hz": 100.0, "latency_frames": 3.0, "jitter_ms": 1.0}):
        sc = _scenario(clock, task, spec)
        comp = [r.row for r in run_trials(sc, 0, [0, 1])]
        late = [r.row for r in run_trials(sc, 1, [0, 1])]
        keys = ["final_position_error_mm", "final_orientation_error_deg"]
        if "tracking_max_position_mm" in ref[0]:
            keys += ["tracking_max_position_mm", "tracking_rms_position_mm"]
        for a, b, c in zip(ref, comp, late, strict=True):
            for key in keys:
                assert abs(a[key] - b[key]) < 1e-9, (key, a[key], b[key])
            assert abs(a["final_position_error_mm"] - c["final_position_error_mm"]) > 1e-3 or (
                abs(a.get("tracking_max_position_mm", 0) - c.get("tracking_max_position_mm", 0))
                > 0.1)


@pytest.mark.parametrize(("clock", "key"), [
    ({"frame_rate_hz": -1.0}, "clock.frame_rate_hz"),
    ({"latency_frames": 1e6}, "clock.latency_frames"),
    ({"jiter_ms": 1.0}, "clock.jiter_ms"),
])
def test_bad_clock_keys_are_refused(clock: dict[str, Any], key: str) -> None:
    with pytest.raises(ScenarioError) as info:
        _scenario(clock)
    assert info.value.key == key


def test_clock_keys_sweep() -> None:
    sc = _scenario({"frame_rate_hz": [30.0, 100.0], "latency_frames": [0.0, 1.0]})
    points = sc.expand()
    assert [(p.clock.frame_rate_hz, p.clock.latency_frames) for p in points] == [
        (30.0, 0.0), (30.0, 1.0), (100.0, 0.0), (100.0, 1.0)]
