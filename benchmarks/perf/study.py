"""Study engine benchmark: microseconds per trial-step, batched against per-trial.

Runs the same trials of a scenario (default: seed 003's convergence study) through both
engines of :func:`benchmarks.sim.run_trials`, in this process, alternately, several
times: the per-trial path (one controller object and one ``step`` call per trial and
period) and the batched engine (every trial as arrays). A trial-step is one period of
one trial (measure, command, integrate, forward kinematics), every period the loop
stepped (a trajectory task steps each trial to its end, whenever it converged); the
time is the whole run (trial set-up included) divided by the trial-steps, the median
over the repetitions, in CPU time of this process (``time.process_time``: other
processes on a shared machine disturb it less than the wall clock). The rows of both
engines are checked equal on the way.

The default batch is one work unit of ``hexapod-bench run NAME --workers 2`` (the batched
engine's per-period overhead is shared by the trials of a unit, so a smaller batch costs
more per trial-step).

Run: ``hexapod-bench perf study [--scenario NAME] [--trials N] [--controllers A,B]
[--world kinematic|dynamic] [--repeats K] [--breakdown]`` (``--controllers``: names or
labels, as ``run --controllers`` takes them: the scenario's, or any registered
controller; the per-trial engine of a predictive controller over hundreds of dynamic
trials takes many minutes).
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from benchmarks.perf import check_counts

#: Goal of the batched engine [us per trial-step], set for seed 003's kinematic study
#: (:data:`GOAL_SCENARIO`); no other study has one (its column reads "-").
GOAL_US = 5.0
GOAL_SCENARIO = ("tahri2009-convergence", "kinematic")


def _run(sc: object, controller: int, trials: int, engine: str) -> tuple[float, float,
                                                                          list[dict]]:
    from benchmarks.sim import run_trials
    from benchmarks.sim.stepper import forget_trials
    from benchmarks.study.calibration import calibration_hook

    forget_trials()  # every repetition draws its trials (set-up included)
    t0, w0 = time.process_time(), time.perf_counter()
    res = run_trials(sc, controller, list(range(trials)), 0,  # type: ignore[type-var]
                     calibrate=calibration_hook(sc),  # type: ignore[arg-type]
                     engine=engine)
    return time.process_time() - t0, time.perf_counter() - w0, [r.row for r in res]


#: The stages of the batched engine timed by ``--breakdown``: (label, module, attribute).
STAGES = (
    ("trial set-up: worlds and poses", "benchmarks.sim.stepper", "make_trials"),
    ("trial set-up: goals", "benchmarks.sim.stepper", "_goals"),
    ("trial set-up: controller reset", "benchmarks.sim.stepper", "task_batch_controller"),
    ("observation (C)", "benchmarks.sim.sensors", "observe_batch"),
    ("features and noise", "benchmarks.sim.sensors", "noisy_features"),
    ("convergence test (pose errors)", "benchmarks.sim.book", "pose_error"),
    ("controller step_batch", "benchmarks.sim.loop", "_step_batch"),
    ("forward kinematics (C)", "benchmarks.sim.plant", "solve_rows"),
    ("dynamic world period (C)", "hexapod.dynamics.robots", "DynamicRobots.advance"),
)


def _breakdown(sc: object, controller: int, trials: int) -> tuple[int, float, dict[str, float]]:
    """One batched run with process-time wrappers around the engine's stages: the
    trial-steps, the total CPU time and the time of each stage [s] (exclusive: a stage
    called inside another, the observation of the goals, counts for itself only)."""
    import importlib


    spent: dict[str, float] = dict.fromkeys([label for label, _, _ in STAGES], 0.0)
    saved: list[tuple[object, str, object]] = []

    inner: list[float] = []  # time of the timed stages called by the running one

    def timed(label: str, f: Callable[..., object]) -> Callable[..., object]:
        def call(*args: object, **kwargs: object) -> object:
            t0 = time.process_time()
            inner.append(0.0)
            try:
                return f(*args, **kwargs)
            finally:
                elapsed = time.process_time() - t0
                spent[label] += elapsed - inner.pop()  # exclusive of the nested stages
                if inner:
                    inner[-1] += elapsed
        return call

    def reset_timed(f: Callable[..., object]) -> Callable[..., object]:
        def make(*args: object, **kwargs: object) -> object:
            ctl = f(*args, **kwargs)
            ctl.reset_batch = timed(STAGES[2][0], ctl.reset_batch)  # type: ignore[attr-defined]
            ctl.step_batch = timed(STAGES[6][0], ctl.step_batch)  # type: ignore[attr-defined]
            return ctl
        return make

    for label, module, attr in STAGES:
        if attr == "_step_batch":
            continue
        owner: Any = importlib.import_module(module)
        *path, name = attr.split(".")  # a function, or a class's method
        for part in path:
            owner = getattr(owner, part)
        saved.append((owner, name, getattr(owner, name)))
        setattr(owner, name, reset_timed(getattr(owner, name)) if name == "task_batch_controller"
                else timed(label, getattr(owner, name)))
    try:
        cpu, _, rows = _run(sc, controller, trials, "batched")
    finally:
        for owner, name, f in reversed(saved):
            setattr(owner, name, f)
    steps = trial_steps(sc, rows)
    return steps, cpu, spent


def trial_steps(sc: Any, rows: list[dict]) -> int:
    """The trial-steps of a run: the periods the loop stepped. A fixed-duration task (a
    trajectory) steps every trial ``max_steps`` periods, except one that failed, which
    stops where it failed; its row's ``steps`` is the period from which it stayed within
    tolerance (a failed trial was out of tolerance when it failed, or close before)."""
    n = int(sc.task.max_steps)
    if not getattr(sc.task, "fixed_duration", False):
        return sum(int(r["steps"]) + 1 for r in rows)
    return sum(n if r.get("converged") else min(n, int(r["steps"]) + 1) for r in rows)


def _same(a: list[dict], b: list[dict]) -> bool:
    keys = ("trial", "converged", "steps", "final_position_error_mm", "failure")
    return all(all(x[k] == y[k] for k in keys) for x, y in zip(a, b, strict=True))


def main(argv: Sequence[str] | None = None) -> int:
    """Command-line entry point; returns the exit status."""
    import controllers  # noqa: F401 - registers the built-ins
    from benchmarks.study.scenario import load_scenario

    p = argparse.ArgumentParser(prog="hexapod-bench perf study",
                                description=__doc__.splitlines()[0])
    p.add_argument("--scenario", default="tahri2009-convergence",
                   help="a built-in name or a file (default: tahri2009-convergence)")
    p.add_argument("--trials", type=int, default=None,
                   help="trials per controller (default: the work-unit size of "
                        "'hexapod-bench run SCENARIO --workers 2', capped at 1000)")
    p.add_argument("--controllers", default=None,
                   help="comma-separated names or labels to time, as run --controllers "
                        "takes them (default: the scenario's)")
    p.add_argument("--world", choices=["kinematic", "dynamic"], default=None,
                   help="run the scenario in this world (as run --world; default: its own)")
    p.add_argument("--repeats", type=int, default=3,
                   help="runs of each engine, the median taken (default 3)")
    p.add_argument("--breakdown", action="store_true",
                   help="also time the batched engine's stages (one more run per controller)")
    args = p.parse_args(argv)
    check_counts(p, args, "--trials", "--repeats")
    from benchmarks.study.commands import auto_chunk
    from benchmarks.study.scenario_checks import check_controllers

    scenario = load_scenario(args.scenario)
    if args.world is not None:  # (the force laws' refusal told to run with --world)
        scenario = replace(scenario, world=args.world)
    trials = auto_chunk([scenario], 2, "sim") if args.trials is None else args.trials
    names = ([c.strip() for c in args.controllers.split(",") if c.strip()]
             if args.controllers else None)
    # the controllers and their options checked as ``run`` checks them (a name that is
    # no controller refused here, not a failed row per trial)
    checked, _ = check_controllers(scenario.with_overrides(trials=trials, controllers=names))
    sc = checked.expand()[0]
    goal = (f"{GOAL_US:g}" if (scenario.name, scenario.world) == GOAL_SCENARIO else "-")
    out = sys.stdout
    out.write(f"# Study engine: {args.scenario} (first sweep point), {trials} trials per "
              f"controller in one batch (a work unit of the run), median of {args.repeats} "
              "runs per engine (CPU time of this process, trial set-up included)\n")
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
                cpu, _wall, rows[engine] = _run(sc, c, trials, engine)
                times[engine].append(cpu)
        steps = trial_steps(sc, rows["batched"])
        per = 1e6 * float(np.median(times["per-trial"])) / steps
        bat = 1e6 * float(np.median(times["batched"])) / steps
        out.write(f"| {spec.label} | {steps} | {per:.1f} | {bat:.1f} | {per / bat:.1f}x | "
                  f"{goal} | {'yes' if _same(rows['per-trial'], rows['batched']) else 'NO'}"
                  " |\n")
    if args.breakdown:
        _print_breakdown(out, sc, trials)
    return 0


def _print_breakdown(out: Any, sc: Any, trials: int) -> None:
    """The stages of one batched run per controller, in us per trial-step."""
    labels = [label for label, _, _ in STAGES]
    cols = []
    for c in range(len(sc.controllers)):
        steps, cpu, spent = _breakdown(sc, c, trials)
        cols.append((steps, cpu, spent))
    out.write("\n# Where the time goes (one batched run, CPU time of the stages; the set-up "
              "is per trial, spread over its trial-steps) [us per trial-step]\n")
    out.write("| stage | " + " | ".join(spec.label for spec in sc.controllers) + " |\n|"
              + "---|" * (1 + len(cols)) + "\n")
    for label in labels:
        out.write(f"| {label} | " + " | ".join(f"{1e6 * sp[label] / st:.2f}"
                                             for st, _, sp in cols) + " |\n")
    out.write("| other (the engine's numpy bookkeeping, rows) | " + " | ".join(
        f"{1e6 * (cpu - sum(sp.values())) / st:.2f}" for st, cpu, sp in cols) + " |\n")
    out.write("| total | " + " | ".join(f"{1e6 * cpu / st:.2f}" for st, cpu, _ in cols)
              + " |\n")


if __name__ == "__main__":
    raise SystemExit(main())
