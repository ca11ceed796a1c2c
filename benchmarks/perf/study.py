"""Study engine benchmark: microseconds per trial-step, batched against per-trial.

Runs the same trials of a scenario (default: seed 003's convergence study) through both
engines of :func:`benchmarks.sim.run_trials`, in this process, alternately, several
times: the per-trial path (one controller object and one ``step`` call per trial and
period) and the batched engine (every trial as arrays). A trial-step is one period of
one trial (measure, command, integrate, forward kinematics); the time is the whole run
(trial set-up included) divided by the trial-steps, the median over the repetitions,
in CPU time of this process (``time.process_time``: other processes on a shared
machine disturb it less than the wall clock). The rows of both engines are checked
equal on the way.

Run: ``hexapod-bench perf study [--scenario NAME] [--trials N] [--repeats K]``.
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from collections.abc import Sequence

import numpy as np

#: Goal of the issue [us per trial-step, batched engine].
GOAL_US = 5.0


def _run(sc: object, controller: int, trials: int, engine: str) -> tuple[float, float,
                                                                          list[dict]]:
    from benchmarks.sim import run_trials
    from benchmarks.study.calibration import calibration_hook

    t0, w0 = time.process_time(), time.perf_counter()
    res = run_trials(sc, controller, list(range(trials)), 0,  # type: ignore[arg-type]
                     calibrate=calibration_hook(sc),  # type: ignore[arg-type]
                     engine=engine)
    return time.process_time() - t0, time.perf_counter() - w0, [r.row for r in res]


def _same(a: list[dict], b: list[dict]) -> bool:
    keys = ("trial", "converged", "steps", "final_position_error_mm", "failure")
    return all(all(x[k] == y[k] for k in keys) for x, y in zip(a, b, strict=True))


def main(argv: Sequence[str] | None = None) -> int:
    """Command-line entry point; returns the exit status."""
    import controllers  # noqa: F401 - registers the built-ins
    from benchmarks.study.scenario import load_scenario

    p = argparse.ArgumentParser(prog="hexapod-bench perf study",
                                description=__doc__.splitlines()[0])
    p.add_argument("--scenario", default="tahri2009-convergence")
    p.add_argument("--trials", type=int, default=300, help="trials per controller")
    p.add_argument("--repeats", type=int, default=3, help="runs of each engine (median)")
    args = p.parse_args(argv)
    sc = load_scenario(args.scenario).with_overrides(trials=args.trials).expand()[0]
    out = sys.stdout
    out.write(f"# Study engine: {args.scenario} (first sweep point), {args.trials} trials per "
              f"controller, median of {args.repeats} runs per engine (CPU time of this "
              "process, set-up included)\n")
    out.write(f"# {platform.processor() or platform.machine()}, Python "
              f"{platform.python_version()}, numpy {np.__version__}\n")
    header = ("controller", "trial-steps", "per-trial us/step", "batched us/step",
              "speed-up", "goal us", "rows equal")
    out.write("| " + " | ".join(header) + " |\n|" + "---|" * len(header) + "\n")
    for c, spec in enumerate(sc.controllers):
        times: dict[str, list[float]] = {"per-trial": [], "batched": []}
        rows: dict[str, list[dict]] = {}
        for _ in range(args.repeats):
            for engine in ("per-trial", "batched"):
                cpu, _wall, rows[engine] = _run(sc, c, args.trials, engine)
                times[engine].append(cpu)
        steps = sum(int(r["steps"]) + 1 for r in rows["batched"])
        per = 1e6 * float(np.median(times["per-trial"])) / steps
        bat = 1e6 * float(np.median(times["batched"])) / steps
        out.write(f"| {spec.label} | {steps} | {per:.1f} | {bat:.1f} | {per / bat:.1f}x | "
                  f"{GOAL_US:g} | {'yes' if _same(rows['per-trial'], rows['batched']) else 'NO'}"
                  " |\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
