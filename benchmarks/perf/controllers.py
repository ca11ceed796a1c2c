"""Time per ``step`` of every registered controller (``python -m benchmarks.perf.controllers``).

Each controller is reset on the reference robot with its camera (front perspective
camera, or the omnidirectional one with ``--camera omni``), then stepped on a
fixed set of precomputed observations (random poses near a goal, all features
visible); the median time per step is printed in microseconds with the ratio to
``joint-space`` measured in the same run (the machines are shared and noisy).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from dataclasses import dataclass

import numpy as np

from controllers import registry
from controllers.base import ControllerContext, Goal, Observation
from hexapod import deltalab, legs_in_frame, sample_poses
from vision.cameras import Camera, front_camera, omni_camera
from vision.legs import leg_edges

#: Budgets of the issue [us]: direction and edge laws, QP law.
BUDGET_US = {"leg-direction": 100.0, "leg-edge": 100.0, "leg-edge-qp": 300.0,
             "leg-direction-qp": 300.0}


@dataclass
class StepTiming:
    """Timing of one controller.

    Attributes:
        name: Registry name.
        median_us: Median time per step [us].
        p95_us: 95th percentile [us].
        ratio: ``median_us`` over the joint-space median of the same run.
        refused: Steps that returned a zero command (should be 0).
    """

    name: str
    median_us: float
    p95_us: float
    ratio: float
    refused: int


def _observation(camera: Camera, geometry, R: np.ndarray, t: np.ndarray, time_s: float  # type: ignore[no-untyped-def]
                 ) -> tuple[Observation, Goal]:
    legs = legs_in_frame(geometry, R, t, camera.camera_from_base)
    normals, _ = leg_edges(legs.base_points, legs.directions, geometry.leg_radius)
    lines = camera.normal_to_line(normals) if camera.kind == "perspective" else None  # type: ignore[attr-defined]
    obs = Observation(time_s, legs.lengths, normals=normals, lines=lines,
                      directions=legs.directions)
    goal = Goal(normals=normals, lines=lines, directions=legs.directions, lengths=legs.lengths,
                rotation=R, translation=t)
    return obs, goal


def time_controllers(names: list[str] | None = None, steps: int = 5000, camera: str = "front",
                     seed: int = 0, repeats: int = 5) -> list[StepTiming]:
    """Median time per ``step`` of each controller over ``steps`` calls.

    The controllers are interleaved ``repeats`` times (``steps / repeats`` calls each
    time) so that a burst of load on the machine affects them alike.
    """
    geo = deltalab()
    cam = front_camera(geo) if camera == "front" else omni_camera(geo)
    rng = np.random.default_rng(seed)
    Rs, ts = sample_poses(geo, 65, rng=rng, max_translation=0.03, max_angle=np.deg2rad(6),
                          margin=0.01)
    _, goal = _observation(cam, geo, Rs[0], ts[0], 0.0)
    observations = [_observation(cam, geo, R, t, 0.02 * k)[0]
                    for k, (R, t) in enumerate(zip(Rs[1:], ts[1:], strict=True))]
    base = cam.camera_from_base.apply(geo.base_points)
    names = list(names or registry.names())
    if "joint-space" not in names:
        names.append("joint-space")
    controllers = {}
    for name in names:
        ctrl = registry.create(name)
        ctrl.reset(ControllerContext(base, geo, cam, 0.02, goal))
        controllers[name] = ctrl
    samples: dict[str, list[float]] = {n: [] for n in names}
    refused = dict.fromkeys(names, 0)
    per_round = max(steps // repeats, 1)
    n_obs = len(observations)
    clock = time.perf_counter
    for _ in range(repeats):
        for name, ctrl in controllers.items():
            out = samples[name]
            for k in range(per_round):
                obs = observations[k % n_obs]
                t0 = clock()
                cmd = ctrl.step(obs)
                out.append(clock() - t0)
                if cmd.reason is not None:
                    refused[name] += 1
    ref = statistics.median(samples["joint-space"]) * 1e6
    result = []
    for name in names:
        us = np.array(samples[name]) * 1e6
        med = float(np.median(us))
        result.append(StepTiming(name, med, float(np.percentile(us, 95)), med / ref,
                                 refused[name]))
    return result


def format_timings(timings: list[StepTiming], camera: str) -> str:
    """A plain-text table."""
    lines = [f"controller step time, reference robot, {camera} camera, all features visible",
             f"{'controller':<20} {'median us':>10} {'p95 us':>9} {'x joint':>8} "
             f"{'budget us':>10} {'refused':>8}"]
    for t in timings:
        budget = BUDGET_US.get(t.name)
        lines.append(f"{t.name:<20} {t.median_us:>10.1f} {t.p95_us:>9.1f} {t.ratio:>8.1f} "
                     f"{'' if budget is None else f'{budget:.0f}':>10} {t.refused:>8}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Print the median time per ``step`` of each registered controller."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks.perf.controllers",
                                     description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("names", nargs="*", help="controllers (default: every registered one)")
    parser.add_argument("--steps", type=int, default=5000, help="steps per controller")
    parser.add_argument("--camera", choices=("front", "omni"), default="front")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    timings = time_controllers(args.names or None, args.steps, args.camera, args.seed)
    sys.stdout.write(format_timings(timings, args.camera) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
