"""Time per ``step`` of every registered controller (``python -m benchmarks.perf.controllers``).

Each controller is reset on the reference robot with its camera (front perspective
camera, or the omnidirectional one with ``--camera omni``), then stepped on a
fixed set of precomputed observations (random poses near a goal, all features
visible); the median and 95th-percentile times per step are printed in
microseconds with the ratio to ``joint-space`` measured in the same run (the
machines are shared and noisy). For the predictive controllers (``*-mpc``) the
table adds the mean SQP iterations per step, the steps that applied an unconverged
iterate and the fallbacks to the QP law. A controller may be given options as
``NAME+key=value+...`` (e.g. ``leg-edge-mpc+model=global+horizon=5``); by default
the global-model variants of the predictive controllers are timed too. With
``--hidden`` one edge of leg 2 (and the direction of leg 2) is hidden in every
observation: the laws' hidden-feature path (zero-weight rows of the compiled core, the
leg's direction from the estimate). With ``--arrays`` a second column times the same
observations through the controller's batch path on a batch of one (its ``step_batch``
when it has its own, else ``step_arrays`` and the rows it leaves stepped by their
instance): what a lone row would cost if the per-trial step were only the batch step
(for a law whose one step is its batch's, what its per-trial step costs).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from benchmarks.perf import check_counts, seed
from controllers import registry
from controllers.base import Controller, ControllerContext, Goal, Observation
from controllers.data import CommandBatch, ObservationBatch
from hexapod import deltalab, legs_in_frame, sample_poses
from vision.cameras import Camera, front_camera, omni_camera
from vision.legs import leg_edges

#: Budgets of the issue [us]: direction and edge laws, QP law, predictive laws (N = 10).
BUDGET_US = {"leg-direction": 100.0, "leg-edge": 100.0, "leg-edge-qp": 300.0,
             "leg-direction-qp": 300.0, "leg-edge-mpc": 2000.0, "leg-direction-mpc": 2000.0,
             "leg-edge-mpc+model=global": 2000.0, "leg-direction-mpc+model=global": 2000.0,
             "computed-torque": 50.0, "cartesian-ctc": 50.0, "vision-ctc": 100.0,
             "leg-edge-ctc": 100.0, "leg-direction-ctc": 100.0, "leg-edge-force-mpc": 2000.0,
             "pose-force-mpc": 2000.0}
#: Variants timed by default besides the registered names.
DEFAULT_VARIANTS = ("leg-edge-mpc+model=global", "leg-direction-mpc+model=global")


@dataclass
class StepTiming:
    """Timing of one controller.

    Attributes:
        name: Registry name.
        median_us: Median time per step [us].
        p95_us: 95th percentile [us].
        ratio: ``median_us`` over the joint-space median of the same run.
        refused: Steps that returned a zero command (should be 0).
        iterations: Mean SQP iterations per step (predictive controllers; else NaN).
        unconverged: Steps that applied an unconverged SQP iterate (predictive).
        fallbacks: Steps that fell back to the QP law (predictive; else 0).
        arrays_us: Median time per step through the batch path on a batch of one [us]
            (``arrays``; else NaN).
    """

    name: str
    median_us: float
    p95_us: float
    ratio: float
    refused: int
    iterations: float = float("nan")
    unconverged: int = 0
    fallbacks: int = 0
    arrays_us: float = float("nan")


def parse_variant(spec: str) -> tuple[str, dict[str, object]]:
    """``NAME+key=value+...`` -> the registry name and its options (numbers parsed)."""
    name, *pairs = spec.split("+")
    options: dict[str, object] = {}
    for pair in pairs:
        key, _, text = pair.partition("=")
        value: object = text
        for cast in (int, float):
            try:
                value = cast(text)
                break
            except ValueError:
                continue
        if text in ("true", "false"):
            value = text == "true"
        options[key] = value
    return name, options


def _observation(camera: Camera, geometry, R: np.ndarray, t: np.ndarray, time_s: float  # type: ignore[no-untyped-def]
                 ) -> tuple[Observation, Goal]:
    legs = legs_in_frame(geometry, R, t, camera.camera_from_base)
    normals, _ = leg_edges(legs.base_points, legs.directions, geometry.leg_radius)
    lines = camera.normal_to_line(normals) if camera.family == "perspective" else None  # type: ignore[attr-defined]
    # leg rates for the force laws (1 mm/s, fixed), ignored by the velocity laws
    q_dot = 1e-3 * np.sin(np.arange(6) + time_s)
    obs = Observation(time_s, legs.lengths, normals=normals, lines=lines,
                      directions=legs.directions, q_dot=q_dot)
    goal = Goal(normals=normals, lines=lines, directions=legs.directions, lengths=legs.lengths,
                rotation=R, translation=t)
    return obs, goal


def time_controllers(names: list[str] | None = None, steps: int = 5000, camera: str = "front",
                     seed: int = 0, repeats: int = 5, hidden: bool = False,
                     arrays: bool = False) -> list[StepTiming]:
    """Median time per ``step`` of each controller over ``steps`` calls.

    The controllers are interleaved ``repeats`` times (``steps / repeats`` calls each
    time) so that a burst of load on the machine affects them alike. ``hidden``: edge
    (2, 0) and direction 2 hidden in every observation. ``arrays``: also time the batch
    path on a batch of one (another instance of each controller, interleaved alike).
    """
    geo = deltalab()
    cam = front_camera(geo) if camera == "front" else omni_camera(geo)
    rng = np.random.default_rng(seed)
    Rs, ts = sample_poses(geo, 65, rng=rng, max_translation=0.03, max_angle=np.deg2rad(6),
                          margin=0.01)
    _, goal = _observation(cam, geo, Rs[0], ts[0], 0.0)
    observations = [_observation(cam, geo, R, t, 0.02 * k)[0]
                    for k, (R, t) in enumerate(zip(Rs[1:], ts[1:], strict=True))]
    if hidden:
        for obs in observations:
            obs.edge_visible = np.ones((6, 2), dtype=bool)
            obs.edge_visible[2, 0] = False
            obs.direction_visible = np.arange(6) != 2
    base = cam.camera_from_base.apply(geo.base_points)
    names = list(names or [*registry.names(), *DEFAULT_VARIANTS])
    if "joint-space" not in names:
        names.append("joint-space")
    controllers: dict[str, Any] = {}
    batched: dict[str, Any] = {}
    for name in names:
        base_name, options = parse_variant(name)
        for into in (controllers, batched) if arrays else (controllers,):
            ctrl = registry.create(base_name, **options)
            ctrl.reset(ControllerContext(base, geo, cam, 0.02, goal))
            into[name] = ctrl
    samples: dict[str, list[float]] = {n: [] for n in names}
    array_samples: dict[str, list[float]] = {n: [] for n in names}
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
            if name in batched:
                _time_arrays(batched[name], observations, per_round, array_samples[name])
    ref = statistics.median(samples["joint-space"]) * 1e6
    result = []
    for name in names:
        us = np.array(samples[name]) * 1e6
        med = float(np.median(us))
        timing = StepTiming(name, med, float(np.percentile(us, 95)), med / ref, refused[name])
        stats: Any = getattr(controllers[name], "stats", None)
        if stats is not None and stats.steps:
            timing.iterations = stats.total_sqp_iterations / stats.steps
            timing.unconverged = stats.unconverged
            timing.fallbacks = stats.fallbacks
        if array_samples[name]:
            timing.arrays_us = float(np.median(array_samples[name])) * 1e6
        result.append(timing)
    return result


def _time_arrays(ctrl: Any, observations: list[Observation], steps: int,
                 out: list[float]) -> None:
    """Append the times [s] of ``steps`` steps of ``ctrl`` through its batch path on a
    batch of one (its own ``step_batch``, else ``step_arrays`` and the rows it leaves by
    their instance)."""
    clock = time.perf_counter
    own = type(ctrl).step_batch is not Controller.step_batch
    for k in range(steps):
        obs = observations[k % len(observations)]
        t0 = clock()
        batch = ObservationBatch.of(obs)
        if batch is None:
            raise ValueError(f"{ctrl.name}: the benchmark's observation is malformed")
        if own:
            cmds = ctrl.step_batch(batch)
        else:
            cmds = CommandBatch.zeros(1, ctrl.actuation)
            ctrl.step_rows(batch, ctrl.step_arrays(batch, cmds), cmds)
        cmds.command(0)
        out.append(clock() - t0)


def format_timings(timings: list[StepTiming], camera: str, hidden: bool = False) -> str:
    """A plain-text table."""
    seen = "edge (2, 0) and direction 2 hidden" if hidden else "all features visible"
    lines = [f"controller step time, reference robot, {camera} camera, {seen}",
             f"{'controller':<32} {'median us':>10} {'p95 us':>9} {'x joint':>8} "
             f"{'budget us':>10} {'refused':>8} {'SQP it':>7} {'unconv':>7} {'fallback':>8}"]
    arrays = any(t.arrays_us == t.arrays_us for t in timings)
    if arrays:
        lines[1] += f" {'arrays us':>10}"
    for t in timings:
        budget = BUDGET_US.get(t.name)
        mpc = t.iterations == t.iterations  # not NaN
        lines.append(f"{t.name:<32} {t.median_us:>10.1f} {t.p95_us:>9.1f} {t.ratio:>8.1f} "
                     f"{'' if budget is None else f'{budget:.0f}':>10} {t.refused:>8} "
                     f"{f'{t.iterations:.2f}' if mpc else '':>7} "
                     f"{t.unconverged if mpc else '':>7} {t.fallbacks if mpc else '':>8}"
                     + (f" {t.arrays_us:>10.1f}" if arrays else ""))
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Print the median time per ``step`` of each registered controller."""
    parser = argparse.ArgumentParser(prog="hexapod-bench perf controllers",
                                     description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("names", nargs="*",
                        help="controllers, optionally NAME+key=value+... (default: every "
                             "registered one and the global-model predictive variants)")
    parser.add_argument("--steps", type=int, default=5000,
                        help="steps per controller (default 5000)")
    parser.add_argument("--camera", choices=("front", "omni"), default="front",
                        help="the robot's camera (default front)")
    parser.add_argument("--seed", type=seed, default=0,
                        help="random seed of the observations (default 0)")
    parser.add_argument("--hidden", action="store_true",
                        help="hide edge (2, 0) and direction 2 in every observation")
    parser.add_argument("--arrays", action="store_true",
                        help="also time each controller's batch path on a batch of one")
    args = parser.parse_args(argv)
    check_counts(parser, args, "--steps")
    timings = time_controllers(args.names or None, args.steps, args.camera, args.seed,
                               hidden=args.hidden, arrays=args.arrays)
    sys.stdout.write(format_timings(timings, args.camera, args.hidden) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
