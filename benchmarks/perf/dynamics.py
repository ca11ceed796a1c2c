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
- ``compiled forward_drives batch``: the same with the drives' leg-space masses (zero
  here) and the leg rates and accelerations as outputs;
- ``compiled inverse batch``: the inverse dynamics (leg forces from constraintDynamics'
  accelerations; its error column compares the forces with those given);
- ``DynamicModel.forward_batch``: the forward batch with the packing of the rows, the input
  checks and the finiteness check, per state.

Times are medians over many runs (``--repeats``); the accuracy columns give the largest
relative difference of each method's platform acceleration from constraintDynamics.

``--mujoco`` adds MuJoCo's ``mj_forward`` on the same closed chain (six ``connect``
equality constraints, :mod:`benchmarks.perf.dynamics_mujoco`) when ``mujoco`` is
installed (it is not a dependency of the project).

``--energy`` adds the energy drift of free motion (no gravity, no force) over one
second, integrated with classical RK4 (``R`` as nine numbers, ``R_dot = [w]x R``,
``t_dot = v``, ``twist_dot`` from the compiled forward dynamics) at several steps.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from benchmarks.perf import check_counts, seed
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


def dynamics_figures(n: int = 1000, repeats: int = 30, seed: int = 0,
                     mujoco: bool = False) -> list[DynamicsFigure]:
    """Time every method on the same ``n`` random states (module docstring)."""
    g = deltalab()
    rng = np.random.default_rng(seed)
    R, t = sample_poses(g, n, rng=rng)
    twist = np.concatenate([rng.normal(scale=0.1, size=(n, 3)),
                            rng.normal(scale=0.5, size=(n, 3))], axis=1)
    forces = rng.normal(scale=30.0, size=(n, 6))
    ref = ReferenceDynamics(g)
    states = [ref.state(R[k], t[k], twist[k])[:2] for k in range(n)]
    taus = [ref.generalized_forces(forces[k]) for k in range(n)]
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
            acc_ref[k] = ref.classical_acceleration(R[k], v, a)
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
            acc_l[k] = ref.classical_acceleration(R[k], v, a)
    us = float(np.median(times)) * 1e6
    figures.append(DynamicsFigure("pinocchio lcaba (mu 1e-3)", us, base_us / us,
                                  _relative(acc_l, acc_ref)))

    if mujoco:
        from benchmarks.perf.dynamics_mujoco import MujocoHexapod

        mj = MujocoHexapod(g)
        acc_mj = np.empty((n, 6))
        times = []
        for _ in range(max(1, repeats // 10)):
            for k, (q, v) in enumerate(states):
                mj.set_state(q, v, R[k], twist[k], forces[k])
                t0 = time.perf_counter()
                mj.forward()
                times.append(time.perf_counter() - t0)
                acc_mj[k] = mj.platform_acceleration(R[k])
        us = float(np.median(times)) * 1e6
        figures.append(DynamicsFigure("mujoco mj_forward (soft constraints)", us,
                                      base_us / us, _relative(acc_mj, acc_ref)))

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
    figures.append(_batch_figure(f"compiled batch of {n}", lambda: forward.batch(rows), n,
                                 repeats, base_us, acc_ref))
    drive_rows = np.concatenate([rows, np.zeros((n, 12))], axis=1)
    drives = dyn_compiled.compiled("forward_drives")
    figures.append(_batch_figure(f"compiled forward_drives batch of {n}",
                                 lambda: drives.batch(drive_rows)[:, :6], n, repeats, base_us,
                                 acc_ref))
    inverse_rows = rows.copy()
    inverse_rows[:, 18:24] = acc_ref
    inverse = dyn_compiled.compiled("inverse")
    figures.append(_batch_figure(f"compiled inverse batch of {n} (forces)",
                                 lambda: inverse.batch(inverse_rows)[:, :6], n, repeats,
                                 base_us, forces))
    figures.append(_batch_figure(f"DynamicModel.forward_batch ({n})",
                                 lambda: dyn.forward_batch(R, t, twist, forces), n, repeats,
                                 base_us, acc_ref))
    return figures



def _batch_figure(label: str, call: Callable[[], np.ndarray], n: int, repeats: int,
                  base_us: float, reference: np.ndarray) -> DynamicsFigure:
    """Time ``call`` (a batch of ``n`` states) ``repeats`` times: the median per state [us],
    the speed-up over ``base_us`` and the result's largest relative error to ``reference``."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = call()
        times.append((time.perf_counter() - t0) / n)
    us = float(np.median(times)) * 1e6
    return DynamicsFigure(label, us, base_us / us, _relative(out, reference))

def _rk4_step(dyn: DynamicModel, R: np.ndarray, t: np.ndarray, tw: np.ndarray, dt: float
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One classical RK4 step of a batch in free motion (no force)."""
    zero = np.zeros_like(tw)

    def f(R: np.ndarray, t: np.ndarray, tw: np.ndarray
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        w = tw[:, 3:]
        wx = np.zeros((len(w), 3, 3))
        wx[:, 0, 1], wx[:, 0, 2], wx[:, 1, 2] = -w[:, 2], w[:, 1], -w[:, 0]
        wx -= np.swapaxes(wx, 1, 2)
        return wx @ R, tw[:, :3], dyn.forward_batch(R, t, tw, zero)

    k1 = f(R, t, tw)
    k2 = f(*(x + 0.5 * dt * k for x, k in zip((R, t, tw), k1, strict=True)))
    k3 = f(*(x + 0.5 * dt * k for x, k in zip((R, t, tw), k2, strict=True)))
    k4 = f(*(x + dt * k for x, k in zip((R, t, tw), k3, strict=True)))
    R, t, tw = (x + dt / 6 * (a + 2 * b + 2 * c + d)
                for x, a, b, c, d in zip((R, t, tw), k1, k2, k3, k4, strict=True))
    return R, t, tw


def energy_drift(steps: tuple[float, ...] = (1e-2, 5e-3, 1e-3), n: int = 10,
                 seed: int = 0) -> list[tuple[float, float, float]]:
    """Largest relative energy drift over 1 s of free motion, RK4, per step.

    Returns:
        ``(step [s], max |E(1 s) - E(0)| / E(0), max orthogonality error of R)`` per
        step, over ``n`` random starts (twists about 0.05 m/s and 0.5 rad/s).
    """
    g = deltalab()
    g = g.replace(inertia=g.inertia.replace(gravity=np.zeros(3)))
    dyn = DynamicModel(g)
    rng = np.random.default_rng(seed)
    R0, t0 = sample_poses(g, n, rng=rng, max_translation=0.03, max_angle=np.deg2rad(5))
    tw0 = np.concatenate([rng.normal(scale=0.03, size=(n, 3)),
                          rng.normal(scale=0.3, size=(n, 3))], axis=1)
    E0 = dyn.energy_batch(R0, t0, tw0)
    out = []
    for dt in steps:
        R, t, tw = R0, t0, tw0
        for _ in range(round(1.0 / dt)):
            R, t, tw = _rk4_step(dyn, R, t, tw, dt)
        drift = np.abs(dyn.energy_batch(R, t, tw) - E0) / E0
        ortho = np.abs(np.swapaxes(R, 1, 2) @ R - np.eye(3)).max()
        out.append((dt, float(drift.max()), float(ortho)))
    return out


def format_energy(rows: list[tuple[float, float, float]]) -> str:
    """A plain-text table of :func:`energy_drift`."""
    lines = ["energy drift of free motion over 1 s (no gravity, no force), classical RK4",
             f"{'step ms':>8} {'max rel drift':>14} {'max |R^T R - I|':>16}"]
    lines += [f"{dt * 1e3:>8g} {d:>14.1e} {o:>16.1e}" for dt, d, o in rows]
    return "\n".join(lines)


def format_dynamics(figures: list[DynamicsFigure], n: int) -> str:
    """A plain-text table, with the goal of the compiled batch."""
    compiled = dyn_compiled.compiled("forward").compiled
    lines = [
        f"forward dynamics of the closed chain, reference robot, {n} random states "
        f"({'compiled C' if compiled else 'CasADi VM (no C compiler)'}); goal: compiled "
        f"batch below {GOAL_US:g} us/state",
        f"{'method':<40} {'median us/state':>16} {'speed-up':>9} {'max rel err':>12}",
    ]
    for f in figures:
        lines.append(f"{f.method:<40} {f.median_us:>16.3f} {f.speedup:>8.1f}x "
                     f"{f.max_relative_error:>12.1e}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``python -m benchmarks.perf.dynamics``."""
    parser = argparse.ArgumentParser(prog="hexapod-bench perf dynamics",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("-n", type=int, default=1000,
                        help="states (the batch size) (default 1000)")
    parser.add_argument("--repeats", type=int, default=30,
                        help="timed runs of the batch (a tenth of it for the per-call "
                             "methods, over all states) (default 30)")
    parser.add_argument("--seed", type=seed, default=0,
                        help="random seed of the states (default 0)")
    parser.add_argument("--mujoco", action="store_true",
                        help="also MuJoCo's mj_forward on the same chain (needs mujoco)")
    parser.add_argument("--energy", action="store_true",
                        help="also the energy drift of free motion over 1 s (RK4)")
    args = parser.parse_args(argv)
    check_counts(parser, args, "-n", "--repeats")
    if args.mujoco:
        import importlib.util

        if importlib.util.find_spec("mujoco") is None:
            parser.error("--mujoco needs MuJoCo (pip install mujoco); it is not a "
                         "dependency of the project")
    print(format_dynamics(dynamics_figures(args.n, args.repeats, args.seed, args.mujoco),
                          args.n))
    if args.energy:
        print()
        print(format_energy(energy_drift(seed=args.seed)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
