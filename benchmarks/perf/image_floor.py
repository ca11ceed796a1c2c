"""Where the final error of a vision law servoing from rendered images comes from.

``python -m benchmarks.perf.image_floor`` (options: ``--scenario``, ``--controller``,
``--trials``, ``--variants``): runs the scenario (default ``andreff2006-images``, the
seed-002 task from rendered images) for one controller (default ``leg-edge``) under
variants that remove or change one factor at a time, and prints one row per variant:

- the scenario as it is (``shipped``);
- desired features averaged over K goal frames (``teach-K``, ``[sensor] teach_frames``);
- exact features (what a perfect detector would measure: :func:`vision.observe_legs`
  through the true camera, interpreted with the estimated one) for the goal only
  (``exact-goal``), for the current images only (``exact-current``), or both
  (``exact-both``);
- no pixel noise, no calibration error, other blur or noise levels;
- the fallback renderer (``opencv-render``: OpenCV's anti-aliased polygons, what runs
  without a C compiler, and what the project used before the exact-coverage
  renderer), whose edges are up to about 0.1 px off depending on their direction and
  sub-pixel position.

Columns: trials within the scenario's tolerances at the end (``conv``) and by the
median of the last 20 % of the run (``tail conv``); final rotation and position
errors (median, 90th percentile, max); ``bias``: the error of the mean pose of the
last 20 % (median over trials), ``jitter``: the RMS of the pose about that mean
(median over trials). A bias much larger than the jitter is a static floor that no
averaging of the current images can lower.
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from benchmarks.sim import (
    GeometricSensor,
    TrialResult,
    TrialSetup,
    make_sensor,
    run_trials,
)
from benchmarks.study.scenario import Scenario, load_scenario
from controllers.base import ObservationBatch
from hexapod.se3 import log_so3
from vision.render import Renderer


class _Mixed:
    """The goal from one sensor, the current features from another."""

    def __init__(self, current: Any, goal: Any) -> None:
        self.current = current
        self.goal = goal
        self.detect_times: list[float] = getattr(current, "detect_times", [])

    def measure(self, *args: Any, **kwargs: Any) -> ObservationBatch:
        return self.current.measure(*args, **kwargs)  # type: ignore[no-any-return]

    def measure_goal(self, *args: Any, **kwargs: Any) -> ObservationBatch:
        return self.goal.measure_goal(*args, **kwargs)  # type: ignore[no-any-return]


class _Exact(GeometricSensor):
    """Noise-free geometric features: what a perfect detector would measure."""

    def measure(self, rotations: np.ndarray, translations: np.ndarray,
                rngs: Sequence[Any], apply_noise: bool = True) -> ObservationBatch:
        return super().measure(rotations, translations, rngs, apply_noise=False)


def _exact(sc: Scenario, setup: TrialSetup) -> _Exact:
    return _Exact(sc, setup.world, setup.estimated_camera)


def _exact_goal(sc: Scenario, setup: TrialSetup) -> Any:
    return _Mixed(make_sensor(sc, setup), _exact(sc, setup))


def _exact_current(sc: Scenario, setup: TrialSetup) -> Any:
    return _Mixed(_exact(sc, setup), make_sensor(sc, setup))


def _opencv_render(sc: Scenario, setup: TrialSetup) -> Any:
    sensor = make_sensor(sc, setup)
    image = sensor.sensor
    image.renderer = Renderer(image.true_camera, image.geometry, image.renderer.style,
                              image.renderer.rng, use_compiled=False)
    return sensor


@dataclass(frozen=True)
class Variant:
    """One row: a change of the scenario and, optionally, of the sensor."""

    label: str
    change: Callable[[Scenario], Scenario]
    sensor: Callable[[Scenario, TrialSetup], Any] | None = None


def _same(sc: Scenario) -> Scenario:
    return sc


def _teach(k: int) -> Callable[[Scenario], Scenario]:
    return lambda sc: replace(sc, teach_frames=k)


def _image(**changes: Any) -> Callable[[Scenario], Scenario]:
    return lambda sc: replace(sc, image=replace(sc.image, **changes))


def _no_calibration_error(sc: Scenario) -> Scenario:
    return replace(sc, calibration_error=replace(sc.calibration_error, scale=0.0))


VARIANTS: dict[str, Variant] = {
    "shipped": Variant("as shipped", _same),
    "teach-10": Variant("goal: mean of 10 frames", _teach(10)),
    "teach-30": Variant("goal: mean of 30 frames", _teach(30)),
    "teach-100": Variant("goal: mean of 100 frames", _teach(100)),
    "exact-goal": Variant("goal: exact features", _same, _exact_goal),
    "exact-current": Variant("current: exact features", _same, _exact_current),
    "exact-both": Variant("goal and current: exact features", _same, _exact),
    "no-noise": Variant("no pixel noise", _image(noise_std=0.0)),
    "no-calibration-error": Variant("no calibration error", _no_calibration_error),
    "no-calibration-error-teach-30": Variant(
        "no calibration error, goal: 30 frames",
        lambda sc: _teach(30)(_no_calibration_error(sc))),
    "blur-0": Variant("blur 0 px", _image(blur_px=0.0)),
    "blur-1.5": Variant("blur 1.5 px", _image(blur_px=1.5)),
    "noise-6": Variant("pixel noise 6 grey levels", _image(noise_std=6.0)),
    "noise-6-teach-30": Variant("pixel noise 6, goal: 30 frames",
                                lambda sc: _teach(30)(_image(noise_std=6.0)(sc))),
    "opencv-render": Variant("OpenCV anti-aliased rendering (fallback)", _same,
                             _opencv_render),
    "opencv-render-no-noise": Variant("OpenCV rendering, no pixel noise",
                                      _image(noise_std=0.0), _opencv_render),
}


@dataclass
class FloorRow:
    """Figures of one variant (errors in degrees and millimetres)."""

    variant: str
    label: str
    trials: int
    converged: int
    tail_converged: int
    rot_median_deg: float
    rot_p90_deg: float
    rot_max_deg: float
    pos_median_mm: float
    pos_max_mm: float
    bias_rot_median_deg: float
    jitter_rot_median_deg: float
    seconds: float


def _tail_pose_figures(res: TrialResult) -> tuple[float, float]:
    """(bias, jitter) of the rotation over the last 20 % of a recorded trial [deg]."""
    ser = res.series
    if ser is None or len(ser["t"]) < 5:
        return math.nan, math.nan
    n = len(ser["t"])
    rot = ser["rotations"][n - n // 5:]
    goal = ser["goal_rotation"]
    w = np.array([log_so3(goal.T @ r) for r in rot])
    mean = w.mean(axis=0)
    return (math.degrees(float(np.linalg.norm(mean))),
            math.degrees(float(np.sqrt(np.mean(np.sum((w - mean) ** 2, axis=1))))))


def run_variant(sc: Scenario, key: str, controller_index: int, trials: int) -> FloorRow:
    """Run one variant over trials ``0 .. trials-1`` (all recorded)."""
    v = VARIANTS[key]
    scv = v.change(sc)
    start = time.perf_counter()
    results = run_trials(scv, controller_index, list(range(trials)), record_trials=trials,
                         sensor_factory=v.sensor)
    seconds = time.perf_counter() - start
    rows = [r.row for r in results]
    pos = np.array([r["final_position_error_mm"] or math.nan for r in rows], float)
    rot = np.array([r["final_orientation_error_deg"] or math.nan for r in rows], float)
    tail_pos = np.array([r.get("tail_position_error_mm", math.nan) for r in rows], float)
    tail_rot = np.array([r.get("tail_orientation_error_deg", math.nan) for r in rows], float)
    tol_p, tol_r = sc.task.position_tolerance_mm, sc.task.orientation_tolerance_deg
    figures = np.array([_tail_pose_figures(r) for r in results])
    return FloorRow(
        variant=key, label=v.label, trials=trials,
        converged=int(sum(bool(r["converged"]) for r in rows)),
        tail_converged=int(np.sum((tail_pos < tol_p) & (tail_rot < tol_r))),
        rot_median_deg=float(np.nanmedian(rot)), rot_p90_deg=float(np.nanpercentile(rot, 90)),
        rot_max_deg=float(np.nanmax(rot)), pos_median_mm=float(np.nanmedian(pos)),
        pos_max_mm=float(np.nanmax(pos)),
        bias_rot_median_deg=float(np.nanmedian(figures[:, 0])),
        jitter_rot_median_deg=float(np.nanmedian(figures[:, 1])), seconds=seconds)


def format_rows(rows: list[FloorRow]) -> str:
    """A markdown table."""
    out = ["| variant | conv | tail conv | rot med deg | rot p90 deg | rot max deg | "
           "pos med mm | pos max mm | bias rot med deg | jitter rot med deg | s |",
           "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        out.append(f"| {r.label} (`{r.variant}`) | {r.converged}/{r.trials} | "
                   f"{r.tail_converged}/{r.trials} | {r.rot_median_deg:.4f} | "
                   f"{r.rot_p90_deg:.4f} | {r.rot_max_deg:.4f} | {r.pos_median_mm:.3f} | "
                   f"{r.pos_max_mm:.3f} | {r.bias_rot_median_deg:.4f} | "
                   f"{r.jitter_rot_median_deg:.4f} | {r.seconds:.0f} |")
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    """Command line (see the module docstring)."""
    p = argparse.ArgumentParser(prog="python -m benchmarks.perf.image_floor",
                                description=__doc__.split("\n")[0])
    p.add_argument("--scenario", default="andreff2006-images")
    p.add_argument("--controller", default="leg-edge", help="label in the scenario")
    p.add_argument("--trials", type=int, default=20)
    p.add_argument("--variants", default=",".join(VARIANTS),
                   help=f"comma-separated, among: {', '.join(VARIANTS)}")
    args = p.parse_args(argv)
    sc = load_scenario(args.scenario)
    labels = [c.label for c in sc.controllers]
    if args.controller not in labels:
        p.error(f"--controller: {args.controller!r} is not in {sc.name} ({', '.join(labels)})")
    if args.trials < 1:
        p.error(f"--trials must be >= 1, got {args.trials}")
    keys = [k.strip() for k in args.variants.split(",") if k.strip()]
    unknown = [k for k in keys if k not in VARIANTS]
    if unknown:
        p.error(f"--variants: unknown {unknown}; known: {', '.join(VARIANTS)}")
    print(f"# {sc.name}, controller {args.controller}, trials 0..{args.trials - 1}, "
          f"tolerances {sc.task.position_tolerance_mm} mm, "
          f"{sc.task.orientation_tolerance_deg} deg", flush=True)
    rows = []
    for key in keys:
        rows.append(run_variant(sc, key, labels.index(args.controller), args.trials))
        print(format_rows(rows[-1:]).splitlines()[-1], flush=True)
    print()
    print(format_rows(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
