"""Forward dynamics per state (``hexapod-bench perf dynamics``).

Both sides in the same run, on the reference robot with its default inertia and the
same random states (poses in the workspace, twists of about 0.1 m/s and 0.5 rad/s,
leg forces of about 30 N):

- ``pinocchio constraintDynamics``: one call of ``pin.constraintDynamics`` on the
  closed-chain model (six 3D loop constraints), the tree state prepared beforehand
  (the baseline, timed call by call);
- ``pinocchio lcaba``: one call of ``pin.lcaba`` (mu = 1e-3, 50 iterations);
- ``compiled single``: the compiled C function on one state;
- ``compiled batch``: the compiled C function looped in C over a batch, per state;
- ``DynamicModel.forward_batch``: the same with the packing of the rows, the input
  checks and the finiteness check, per state.

Times are medians over many runs (``--repeats``); the accuracy columns give the largest
relative difference of each method's platform acceleration from constraintDynamics.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from hexapod import deltalab, sample_poses
from hexapod.dynamics import DynamicModel
from hexapod.dynamics import compiled as dyn_compiled
from hexapod.dynamics.reference import ReferenceDynamics

#: Goal of the issue for the compiled forward dynamics in a batch of 1,000 [us/state].
GOAL_US = 1.0


@dataclass
class DynamicsFigure:
    """Timing and accuracy of one way of computing the forward dynamics.

    Attributes:
        method: What was timed.
        median_us: Median time per state [us].
        speedup: constraintDynamics' median over this one's.
        max_relative_error: Largest ``|a - a_ref| / |a_ref|`` over the states.
    """

    method: str
    median_us: float
    speedup: float
    max_relative_error: float


def _relative(a: np.ndarray, ref: np.ndarray) -> float:
    return float(np.max(np.linalg.norm(a - ref, axis=1) / np.linalg.norm(ref, axis=1)))


def dynamics_figures(n: int = 1000, repeats: int = 30, seed: int = 0) -> list[DynamicsFigure]:
    """Time every method on the same ``n`` random states (module docstring)."""
    g = deltalab()
    rng = np.random.default_rng(seed)
    R, t = sample_poses(g, n, rng=rng)
    twist = np.concatenate([rng.normal(scale=0.1, size=(n, 3)),
                            rng.normal(scale=0.5, size=(n, 3))], axis=1)
    forces = rng.normal(scale=30.0, size=(n, 6))
    ref = ReferenceDynamics(g)
    states = [ref.state(R[k], t[k], twist[k])[:2] for k in range(n)]
    taus = [ref._tau(forces[k]) for k in range(n)]
    model, data = ref.model, ref.data

    # Pinocchio constraintDynamics, call by call (the baseline).
    acc_ref = np.empty((n, 6))
    times = []
    for _ in range(max(1, repeats // 10)):
        for k, (q, v) in enumerate(states):
            t0 = time.perf_counter()
            a = pin.constraintDynamics(model, data, q, v, taus[k], ref.constraints,
                                       ref.constraint_datas, ref.prox)
            times.append(time.perf_counter() - t0)
            acc_ref[k] = ref._classical(R[k], v, a)
    base_us = float(np.median(times)) * 1e6
    figures = [DynamicsFigure("pinocchio constraintDynamics", base_us, 1.0, 0.0)]

    # Pinocchio lcaba, its own datas (see ReferenceDynamics.forward_lcaba).
    ldata = model.createData()
    ldatas = pin.StdVec_RigidConstraintData()
    for cm in ref.constraints:
        ldatas.append(cm.createData())
    pin.computeJointMinimalOrdering(model, ldata, ref.constraints)
    prox = pin.ProximalSettings(1e-14, 1e-3, 50)
    acc_l = np.empty((n, 6))
    times = []
    for _ in range(max(1, repeats // 10)):
        for k, (q, v) in enumerate(states):
            t0 = time.perf_counter()
            a = pin.lcaba(model, ldata, q, v, taus[k], ref.constraints, ldatas, prox)
            times.append(time.perf_counter() - t0)
            acc_l[k] = ref._classical(R[k], v, a)
    us = float(np.median(times)) * 1e6
    figures.append(DynamicsFigure("pinocchio lcaba (mu 1e-3)", us, base_us / us,
                                  _relative(acc_l, acc_ref)))

    # Compiled: one state per call, a batch in C, and through DynamicModel.
    dyn = DynamicModel(g)
    rows = dyn.rows(R, t, twist, forces)
    forward = dyn_compiled.compiled("forward")
    acc_single = np.empty((n, 6))
    times = []
    for _ in range(max(1, repeats // 10)):
        for k in range(n):
            t0 = time.perf_counter()
            acc_single[k] = forward.single(rows[k])
            times.append(time.perf_counter() - t0)
    us = float(np.median(times)) * 1e6
    figures.append(DynamicsFigure("compiled single", us, base_us / us,
                                  _relative(acc_single, acc_ref)))
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        acc_batch = forward.batch(rows)
        times.append((time.perf_counter() - t0) / n)
    us = float(np.median(times)) * 1e6
    figures.append(DynamicsFigure(f"compiled batch of {n}", us, base_us / us,
                                  _relative(acc_batch, acc_ref)))
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        acc_model = dyn.forward_batch(R, t, twist, forces)
        times.append((time.perf_counter() - t0) / n)
    us = float(np.median(times)) * 1e6
    figures.append(DynamicsFigure(f"DynamicModel.forward_batch ({n})", us, base_us / us,
                                  _relative(acc_model, acc_ref)))
    return figures


def format_dynamics(figures: list[DynamicsFigure], n: int) -> str:
    """A plain-text table, with the goal of the compiled batch."""
    compiled = dyn_compiled.compiled("forward").compiled
    lines = [
        f"forward dynamics of the closed chain, reference robot, {n} random states "
        f"({'compiled C' if compiled else 'CasADi VM (no C compiler)'}); goal: compiled "
        f"batch below {GOAL_US:g} us/state",
        f"{'method':<36} {'median us/state':>16} {'speed-up':>9} {'max rel err':>12}",
    ]
    for f in figures:
        lines.append(f"{f.method:<36} {f.median_us:>16.3f} {f.speedup:>8.1f}x "
                     f"{f.max_relative_error:>12.1e}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``python -m benchmarks.perf.dynamics``."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks.perf.dynamics",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("-n", type=int, default=1000, help="states (the batch size)")
    parser.add_argument("--repeats", type=int, default=30,
                        help="timed runs of the batch (a tenth of it for the per-call "
                             "methods, over all states)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    print(format_dynamics(dynamics_figures(args.n, args.repeats, args.seed), args.n))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
