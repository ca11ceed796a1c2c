"""Reproduce the calibration study of seed 001 (``docs/math.md`` sections 7 and 10).

100 repetitions of the linear calibration of the base points on the 64 extremal
configurations, at 0.01 / 0.05 / 0.1 deg of rotation noise on every edge normal,
front camera; median and maximal error of each base point beside the seed's figures
(median < 1 mm at 0.05 deg; maximal error 0.5 / 1.4 / 10 mm, measured in the seed
on "each of the components of each attachment point").

Run::

    python -m benchmarks.perf.calibration [--repeats 100] [--camera front|omni]
        [--eye X Y Z] [--visibility] [--method lstsq|irls] [--seed 1] [--json out.json]
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.perf import check_counts, seed
from benchmarks.study.outdir import OutputFile
from hexapod.geometry import deltalab
from hexapod.kinematics import Transform
from hexapod.outputs import check_replace, write_output
from hexapod.se3 import look_at
from vision.calibration import StudyResult, calibration_study
from vision.cameras import camera_preset

#: Seed 001: maximal calibration error [mm] per noise amplitude [deg].
SEED_MAX_MM = {0.01: 0.5, 0.05: 1.4, 0.1: 10.0}
#: Seed 001: median error on each base point at 0.05 deg is below this [mm].
SEED_MEDIAN_BOUND_MM = {0.05: 1.0}


def run_study(noise_levels: Sequence[float], repeats: int, seed: int, camera_name: str,
              visibility: bool, method: str, eye: Sequence[float] | None = None
              ) -> list[StudyResult]:
    """One :func:`calibration_study` per noise level (independent seeded generators).

    ``eye`` (base frame [m]) replaces the preset's placement by a camera there looking
    at the point (0, 0, 0.2 m) of the base axis, image rows vertical.
    """
    geometry = deltalab()
    camera = camera_preset(camera_name, geometry)
    if eye is not None:
        e = np.asarray(eye, dtype=float)
        base_R_cam = look_at(e, np.array([0.0, 0.0, 0.2]), np.array([0.0, 0.0, 1.0]))
        camera = camera.replace(camera_from_base=Transform(base_R_cam, e).inverse())
    target: Any = camera if visibility else camera.camera_from_base
    return [calibration_study(geometry, target, a, repeats,
                              rng=np.random.default_rng([seed, k]),
                              method=method)  # type: ignore[arg-type]
            for k, a in enumerate(noise_levels)]


def format_table(results: Sequence[StudyResult]) -> str:
    """A plain-text table of the figures (millimetres) beside the seed's."""
    lines = []
    for res in results:
        d = res.to_dict()
        seed_max = SEED_MAX_MM.get(res.noise_deg)
        seed_med = SEED_MEDIAN_BOUND_MM.get(res.noise_deg)
        lines.append(f"noise {res.noise_deg:g} deg, {d['repetitions']} repetitions, "
                     f"method {res.method}, worst conditioning "
                     f"{res.smallest_singular_ratio:.4f}")
        lines.append("  base point          " + "".join(f"{i:>8d}" for i in range(6)))
        lines.append("  median error [mm]   " + "".join(f"{x:8.3f}"
                                                         for x in d["per_point_median_mm"]))
        lines.append("  max error [mm]      " + "".join(f"{x:8.3f}"
                                                         for x in d["per_point_max_mm"]))
        lines.append("  max |component| [mm]" + "".join(f"{x:8.3f}"
                                                         for x in d["per_point_max_component_mm"]))
        seed_txt = (f"seed: max {seed_max:g} mm" if seed_max is not None else "seed: -") + (
            f", median < {seed_med:g} mm" if seed_med is not None else "")
        lines.append(f"  all points: median {d['median_error_mm']:.3f} mm, max "
                     f"{d['max_error_mm']:.3f} mm, max |component| "
                     f"{d['max_component_error_mm']:.3f} mm   ({seed_txt})")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """Command-line entry point; prints the table and optionally writes JSON."""
    parser = argparse.ArgumentParser(prog="hexapod-bench perf calibration",
                                     description=__doc__.split("\n\n")[0] if __doc__ else None)
    parser.add_argument("--repeats", type=int, default=100,
                        help="repetitions of the calibration per noise amplitude (default 100)")
    parser.add_argument("--noise", type=float, nargs="+", default=[0.01, 0.05, 0.1],
                        help="rotation-noise amplitudes [deg] (default 0.01 0.05 0.1)")
    parser.add_argument("--camera", default="front",
                        help="camera preset (front, omni; default front)")
    parser.add_argument("--visibility", action="store_true",
                        help="hide edges outside the image or occluded (the seed used every edge)")
    parser.add_argument("--eye", type=float, nargs=3, default=None, metavar=("X", "Y", "Z"),
                        help="place the camera here [m, base frame], looking at (0, 0, 0.2) "
                             "(default: the preset's placement)")
    parser.add_argument("--method", choices=["lstsq", "irls"], default="lstsq",
                        help="solver of the calibration (default lstsq)")
    parser.add_argument("--seed", type=seed, default=1, help="random seed (default 1)")
    parser.add_argument("--json", type=Path, default=None, action=OutputFile, metavar="FILE",
                        help="write the figures here (default: not written)")
    parser.add_argument("--overwrite", action="store_true",
                        help="replace --json even if hexapod-bench did not write it")
    args = parser.parse_args(argv)
    check_counts(parser, args, "--repeats")
    for amplitude in args.noise:
        if not (math.isfinite(amplitude) and amplitude >= 0):
            parser.error(f"--noise: finite non-negative amplitudes in degrees, got {amplitude}")
    if args.json is not None:
        check_replace(args.json, args.overwrite, kind="JSON")
    results = run_study(args.noise, args.repeats, args.seed, args.camera, args.visibility,
                        args.method, args.eye)
    where = f" at {args.eye} m" if args.eye else " (preset placement)"
    print(f"Calibration of the base points (seed 001), camera '{args.camera}'{where}"
          f"{' with visibility' if args.visibility else ''}, 64 extremal configurations")
    print(format_table(results))
    if args.json is not None:
        write_output(args.json, {"camera": args.camera, "visibility": args.visibility,
                                 "seed": args.seed, "eye": args.eye,
                                 "results": [r.to_dict() for r in results]}, args.overwrite)
    return 0


if __name__ == "__main__":
    sys.exit(main())
