"""Performance figures (``python -m benchmarks.perf.fk fk``, also ``hexapod-bench perf``).

Timings are medians over many calls, with the ratio to the baseline measured in
the same run (the machines are shared and noisy).
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass

import numpy as np

from benchmarks.perf import check_counts, seed
from hexapod import build_model, deltalab, forward_kinematics, inverse_kinematics, sample_poses
from hexapod.fk import newton_kernel
from hexapod.se3 import exp_so3, pose_error


@dataclass
class FkFigure:
    """Timing and accuracy of one forward-kinematics method and start."""

    method: str
    start: str
    median_us: float
    p95_us: float
    max_position_error_m: float
    max_orientation_error_rad: float
    max_residual_m: float
    median_iterations: float


def fk_figures(n: int = 1000, seed: int = 0) -> list[FkFigure]:
    """Time both forward-kinematics methods on ``n`` random poses, cold and warm started.

    Cold start: from the home pose. Warm start: from the true pose moved by
    1 mm and 1 mrad (about one control period of motion), as in a servo loop.
    """
    g = deltalab()
    hm = build_model(g)
    rng = np.random.default_rng(seed)
    R, t = sample_poses(g, n, rng=rng)
    q = inverse_kinematics(g, R, t)
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    R_warm = exp_so3(1e-3 * d) @ R
    t_warm = t + 1e-3 * d[:, [1, 2, 0]]
    forward_kinematics(g, q[0])  # compile / load before timing
    figures = []
    for method in ("newton", "pinocchio"):
        for start in ("cold", "warm"):
            times, perr, oerr, res, its = [], [], [], [], []
            for k in range(n):
                guess = None if start == "cold" else (R_warm[k], t_warm[k])
                t0 = time.perf_counter()
                sol = forward_kinematics(g, q[k], guess=guess, method=method,  # type: ignore[arg-type]
                                         model=hm)
                times.append(time.perf_counter() - t0)
                dp, da = pose_error(sol.rotation, sol.translation, R[k], t[k])
                perr.append(float(dp))
                oerr.append(float(da))
                res.append(sol.residual)
                its.append(sol.iterations)
            us = np.array(times) * 1e6
            figures.append(FkFigure(method, start, float(np.median(us)),
                                    float(np.percentile(us, 95)), max(perr), max(oerr), max(res),
                                    float(np.median(its))))
    return figures


def format_fk(figures: list[FkFigure]) -> str:
    """A plain-text table with the speed-up of the fast method over the baseline."""
    base = {f.start: f.median_us for f in figures if f.method == "pinocchio"}
    lines = [
        f"forward kinematics, {'compiled C' if newton_kernel().compiled else 'CasADi VM'} Newton "
        "vs Pinocchio constrained Gauss-Newton (reference robot)",
        f"{'method':<10} {'start':<5} {'median us':>10} {'p95 us':>9} {'speed-up':>9} "
        f"{'iters':>6} {'max pos err m':>14} {'max rot err rad':>16} {'max residual m':>15}",
    ]
    for f in figures:
        lines.append(
            f"{f.method:<10} {f.start:<5} {f.median_us:>10.1f} {f.p95_us:>9.1f} "
            f"{base[f.start] / f.median_us:>8.1f}x {f.median_iterations:>6.0f} "
            f"{f.max_position_error_m:>14.2e} {f.max_orientation_error_rad:>16.2e} "
            f"{f.max_residual_m:>15.2e}"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``python -m benchmarks.perf.fk``."""
    parser = argparse.ArgumentParser(prog="hexapod-bench perf fk")
    parser.add_argument("-n", type=int, default=1000,
                        help="number of random poses (default 1000)")
    parser.add_argument("--seed", type=seed, default=0,
                        help="random seed of the poses (default 0)")
    args = parser.parse_args(argv)
    check_counts(parser, args, "-n")
    print(format_fk(fk_figures(args.n, args.seed)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
