"""The dynamic world's cost: microseconds per trial per control period, against the
kinematic world in the same run.

The plants of a batch of trials (default: 1,000 trials of seed 003's convergence study,
its 20 ms control period, 1 ms physics) advance over control periods with leg velocity
setpoints drawn at random within a fifth of the speed limit, both worlds alternately,
several times; a figure is the CPU time of this process (``time.process_time``, less
disturbed by the other processes of a shared machine than the wall clock) divided by the
trial-periods integrated (a trial whose leg hits an end stop stops), the median over the
repetitions. Also timed: the dynamic world's compiled
period alone (the C code of every physics step of a period, without the packing of its
input rows), to show where the time goes: the lane-parallel C the plant runs and
CasADi's folded period (its fallback), alternately.

Run: ``hexapod-bench perf dynamic-world [--scenario NAME] [--trials N] [--periods P]
[--repeats K] [--physics-dt MS]``.
"""

from __future__ import annotations

import argparse
import platform
import statistics
import sys
import time
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from benchmarks.perf import check_counts

#: Goal and moonshot of the issue [us per trial per control period, 20 ms / 1 ms].
GOAL_US = 20.0
MOONSHOT_US = 5.0


def _setups(sc: Any, trials: int) -> list[Any]:
    from benchmarks.sim.world import load_camera, load_geometry, make_trials

    nominal = load_geometry(sc)
    made = make_trials(sc, list(range(trials)), nominal, load_camera(sc, nominal))
    return [m for m in made if not isinstance(m, Exception)]


def _plant(sc: Any, setups: list[Any]) -> tuple[Any, np.ndarray]:
    from benchmarks.sim.plant import make_plant

    q = np.array([s.start_lengths for s in setups])
    R = np.array([s.start_rotation for s in setups])
    t = np.array([s.start_translation for s in setups])
    A = np.array([s.world.geometry.base_points for s in setups])
    E = np.array([s.world.geometry.platform_points for s in setups])
    return make_plant(sc, setups, q, R, t, A, E), q


def _time_plant(sc: Any, setups: list[Any], periods: int, seed: int) -> float:
    """CPU seconds per trial per period of ``periods`` periods of a fresh plant."""
    plant, _ = _plant(sc, setups)
    n = len(setups)
    rng = np.random.default_rng(seed)
    vmax = setups[0].world.geometry.max_speed
    v = rng.uniform(-0.2 * vmax, 0.2 * vmax, (periods, n, 6))
    alive = np.ones(n, dtype=bool)
    done = 0  # trial-periods integrated
    t0 = time.process_time()
    for k in range(periods):
        done += int(alive.sum())
        failed = plant.advance(np.flatnonzero(alive), v[k][alive], sc.dt)
        alive[list(failed)] = False  # a leg at an end stop: that trial stops
    return (time.process_time() - t0) / done


def _time_compiled(sc: Any, setups: list[Any], repeats: int) -> tuple[float, float]:
    """CPU seconds per trial per period of the compiled period alone: the code the plant
    runs (lane-parallel C) and CasADi's folded period (the code it replaced), alternately."""
    from hexapod.dynamics.robots_compiled import pack_period, period_function, run_period

    plant, _ = _plant(sc, setups)
    n = len(setups)
    x = pack_period(plant.robots, np.arange(n), np.zeros((n, 6)), plant.h)
    f = period_function(plant.steps)
    used, casadi = [], []
    for _ in range(repeats):
        t0 = time.process_time()
        run_period(x, plant.steps)
        t1 = time.process_time()
        f.batch(x)
        t2 = time.process_time()
        used.append((t1 - t0) / n)
        casadi.append((t2 - t1) / n)
    return statistics.median(used), statistics.median(casadi)


def main(argv: Sequence[str] | None = None) -> int:
    """Print the table of the dynamic world's cost."""
    from benchmarks.study.scenario import load_scenario

    p = argparse.ArgumentParser(prog="hexapod-bench perf dynamic-world",
                                description=__doc__.split("\n\n")[0].replace("\n", " "))
    p.add_argument("--scenario", default="tahri2009-convergence",
                   help="the study whose trials and control period are used (default "
                        "tahri2009-convergence)")
    p.add_argument("--trials", type=int, default=1000,
                   help="trials in the batch (default 1000)")
    p.add_argument("--periods", type=int, default=20,
                   help="control periods advanced per repetition (default 20)")
    p.add_argument("--repeats", type=int, default=5,
                   help="repetitions, the median taken (default 5)")
    p.add_argument("--physics-dt", type=float, default=1.0, metavar="MS",
                   help="the dynamic world's physics step [ms] (default 1)")
    args = p.parse_args(argv)
    check_counts(p, args, "--trials", "--periods", "--repeats")
    if not args.physics_dt > 0:
        p.error(f"--physics-dt: a positive step in milliseconds, got {args.physics_dt}")
    base = load_scenario(args.scenario)
    kin = replace(base, world="kinematic")
    dyn = replace(base, world="dynamic", physics_dt=args.physics_dt / 1e3)
    setups = _setups(base, args.trials)
    _time_plant(dyn, setups[:4], 1, 0)  # compile (or load) the period function first
    k_times, d_times = [], []
    for r in range(args.repeats):
        k_times.append(_time_plant(kin, setups, args.periods, r))
        d_times.append(_time_plant(dyn, setups, args.periods, r))
    k_us = statistics.median(k_times) * 1e6
    d_us = statistics.median(d_times) * 1e6
    c_us, f_us = (x * 1e6 for x in _time_compiled(dyn, setups, args.repeats))
    steps = round(dyn.dt / dyn.physics_dt)
    print(f"hexapod-bench perf dynamic-world ({platform.machine()}, Python "
          f"{platform.python_version()}): {len(setups)} trials of {args.scenario}, "
          f"{args.periods} periods of {dyn.dt * 1e3:g} ms, physics {dyn.physics_dt * 1e3:g} ms "
          f"({steps} steps), median of {args.repeats} (CPU time)")
    print()
    print("| world | us per trial per period | us per trial per physics step | ratio |")
    print("|---|---|---|---|")
    print(f"| kinematic (clamp, integrate, forward kinematics) | {k_us:.2f} | - | 1 |")
    print(f"| dynamic (drives, mechanism, integration, legs) | {d_us:.1f} | {d_us / steps:.2f} "
          f"| {d_us / k_us:.1f} |")
    print(f"| dynamic: the compiled period alone (lane-parallel C, used) | {c_us:.1f} | "
          f"{c_us / steps:.2f} | {c_us / k_us:.1f} |")
    print(f"| dynamic: the compiled period alone (CasADi's C, fallback) | {f_us:.1f} | "
          f"{f_us / steps:.2f} | {f_us / k_us:.1f} |")
    print()
    verdict = ("meets the moonshot" if d_us <= MOONSHOT_US else "meets the goal"
               if d_us <= GOAL_US else "misses the goal")
    print(f"goal {GOAL_US:g} us, moonshot {MOONSHOT_US:g} us per trial per period: the dynamic "
          f"world {verdict} ({d_us:.1f} us).")
    return 0


if __name__ == "__main__":
    sys.exit(main())
