"""Accuracy of edge-normal and leg-direction estimates from noisy edge pixels.

``python -m benchmarks.perf.vision`` (options: ``--poses``, ``--points``,
``--sigma``, ``--seed``): for the front perspective camera and the
omnidirectional camera of the seeds, at random poses of the reference robot,
sample ``--points`` pixels along the visible part of every observed edge, add
Gaussian pixel noise of ``--sigma`` pixels, estimate each edge normal with both
fits (:func:`vision.estimate.fit_normal`, SVD on lifted points;
:func:`vision.estimate.fit_normal_conic`, the conic / line coefficient fit) and
each leg direction from its two normals, and print the median and 95th
percentile angle errors [deg] against the truth, and each fit's time per edge: the
median of ``--repeats`` calls on the same edges (default 7) divided by the edges.

Angle errors are between planes (normals) and between lines (directions),
i.e. independent of the sign; the signs themselves are fixed by the base-point
rule of :mod:`vision.estimate` and are right for the SVD fit.
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import dataclass

import numpy as np

from benchmarks.perf import check_counts, seed
from benchmarks.study.outdir import OutputFile
from hexapod import deltalab, sample_poses
from vision.cameras import Camera, front_camera, omni_camera
from vision.estimate import angle_between, direction_from_normals, fit_normal, fit_normal_conic
from vision.legs import observation_edge_points, observe_legs
from vision.noise import pixel_noise

#: Fewest ``--points`` per edge: the conic fit of the omnidirectional camera needs 5
#: (with fewer its rows are NaN).
MIN_POINTS = 5


@dataclass
class AccuracyFigure:
    """Angle errors of one fit, one camera, one feature."""

    camera: str
    fit: str
    feature: str
    median_deg: float
    p95_deg: float
    count: int
    failed: int
    fit_us: float


def accuracy_figures(
    n_poses: int = 300, n_points: int = 20, sigma_px: float = 0.5, seed: int = 0,
    repeats: int = 7,
) -> list[AccuracyFigure]:
    """Compute the accuracy table (see the module docstring; ``repeats`` calls of each
    fit timed, the median kept: one call's time varied by 1.8 times from run to run)."""
    g = deltalab()
    rng = np.random.default_rng(seed)
    R, t = sample_poses(g, n_poses, rng)
    figures: list[AccuracyFigure] = []
    cams: list[Camera] = [front_camera(g), omni_camera(g)]
    for cam in cams:
        obs = observe_legs(cam, g, R, t)
        pix, vis = observation_edge_points(cam, obs, n_points)
        noisy = pixel_noise(pix, sigma_px, rng)
        A = obs.base_points[..., None, :]
        for name, fit in (("svd", fit_normal), ("conic", fit_normal_conic)):
            times = []
            for _ in range(repeats):  # (the same inputs: the same result each time)
                start = time.perf_counter()
                res = fit(cam, noisy, weights=vis, base_point=A)
                times.append(time.perf_counter() - start)
            elapsed = float(np.median(times))
            ok = obs.edge_visible
            e_n = np.degrees(angle_between(res.normal, obs.normals, oriented=False))[ok]
            u = direction_from_normals(res.normal[..., 0, :], res.normal[..., 1, :])
            both = obs.direction_visible
            e_u = np.degrees(angle_between(u, obs.directions, oriented=False))[both]
            per_fit = elapsed / max(int(ok.size), 1) * 1e6
            for feature, e in (("normal", e_n), ("direction", e_u)):
                good = e[np.isfinite(e)]
                figures.append(AccuracyFigure(
                    camera=cam.name, fit=name, feature=feature,
                    median_deg=float(np.median(good)) if good.size else float("nan"),
                    p95_deg=float(np.percentile(good, 95)) if good.size else float("nan"),
                    count=int(e.size), failed=int(e.size - good.size), fit_us=per_fit,
                ))
    return figures


def _circle(centre: np.ndarray, normal: np.ndarray, radius: float, n: int = 400) -> np.ndarray:
    a = np.cross(normal, [1.0, 0.0, 0.0])
    if np.linalg.norm(a) < 1e-6:
        a = np.cross(normal, [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(normal, a)
    phi = np.linspace(0.0, 2 * np.pi, n)
    return centre + radius * (np.cos(phi)[:, None] * a + np.sin(phi)[:, None] * b)


def edges_figure(path: str, seed: int = 0, overwrite: bool = False) -> None:
    """Draw what the front and the omnidirectional cameras see of the reference robot
    (home pose and one tilted pose): the edges (solid where observed, dotted where
    hidden by another leg or the platform), the base and platform circles, and for the
    omnidirectional camera the annulus of diameters 184-370 px of seed 003."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from hexapod.se3 import rotation_from_rpy
    from vision.legs import edge_points

    g = deltalab()
    h = g.home_height
    poses = [
        ("home pose", np.eye(3), np.array([0.0, 0.0, h])),
        ("roll -10, pitch 10, yaw -15 deg",
         rotation_from_rpy(*np.deg2rad([-10.0, 10.0, -15.0])), np.array([0.0, 0.0, h])),
    ]
    cams: list[Camera] = [front_camera(g), omni_camera(g)]
    colours = [plt.get_cmap("tab10")(k) for k in range(10)]
    fig, axes = plt.subplots(2, 2, figsize=(13, 11.5))
    for col, cam in enumerate(cams):
        for row, (label, R, t) in enumerate(poses):
            ax = axes[row, col]
            obs = observe_legs(cam, g, R, t)
            pix, vis = edge_points(
                cam, obs.base_points, obs.directions, obs.radius, obs.lengths, 300,
                normals=obs.normals,
                platform=(obs.platform_centre, obs.platform_normal, obs.platform_radius))
            T = cam.camera_from_base
            for centre, normal, radius in (
                (np.zeros(3), np.array([0.0, 0.0, 1.0]),
                 float(np.max(np.linalg.norm(g.base_points, axis=1)))),
                (t, R[:, 2], obs.platform_radius),
            ):
                ring, ok = cam.project(T.apply(_circle(centre, normal, radius)))
                ax.plot(np.where(ok, ring[:, 0], np.nan), np.where(ok, ring[:, 1], np.nan),
                        color="0.75", lw=1.0)
            for i in range(6):
                for j in range(2):
                    p, v = pix[i, j], vis[i, j]
                    ax.plot(np.where(v, p[:, 0], np.nan), np.where(v, p[:, 1], np.nan),
                            color=colours[i], lw=1.6,
                            label=f"leg {i}" if (j == 0) else None)
                    ax.plot(np.where(~v, p[:, 0], np.nan), np.where(~v, p[:, 1], np.nan),
                            color=colours[i], lw=1.0, ls=":", alpha=0.6)
                end = obs.segments[i, 0, 1]
                if np.all(np.isfinite(end)):
                    ax.annotate(str(i), end, color=colours[i], fontsize=9,
                                xytext=(4, 4), textcoords="offset points")
            if cam.kind == "unified":
                for d in (184.0, 370.0):
                    phi = np.linspace(0, 2 * np.pi, 200)
                    ax.plot(cam.cx + d / 2 * np.cos(phi), cam.cy + d / 2 * np.sin(phi),
                            color="k", lw=0.8, ls="--")
            hidden = int((~obs.edge_visible).sum())
            ax.set_title(f"{cam.name} ({cam.kind}, {cam.width}x{cam.height}): {label}\n"
                         f"{hidden} of 12 edges hidden (dotted: hidden samples)", fontsize=10)
            ax.set_xlim(-0.5, cam.width - 0.5)
            ax.set_ylim(cam.height - 0.5, -0.5)
            ax.set_aspect("equal")
            ax.set_xlabel("u [px]")
            ax.set_ylabel("v [px]")
            if row == 0 and col == 0:
                ax.legend(loc="lower right", fontsize=8)
    fig.suptitle("Simulated leg edges of the reference robot (vision.observe_legs, "
                 "vision.edge_points)")
    fig.tight_layout()
    import io

    from hexapod.outputs import PNG_METADATA, write_output

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90, metadata=PNG_METADATA)
    plt.close(fig)
    write_output(path, buf.getvalue(), overwrite)  # marked; a user's file refused


def main(argv: list[str] | None = None) -> int:
    """Print the accuracy table."""
    parser = argparse.ArgumentParser(prog="hexapod-bench perf vision",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--poses", type=int, default=300, help="random poses (default 300)")
    parser.add_argument("--points", type=int, default=20,
                        help=f"points per edge, at least {MIN_POINTS} (default 20)")
    parser.add_argument("--sigma", type=float, default=0.5, help="pixel noise [px] (default 0.5)")
    parser.add_argument("--seed", type=seed, default=0, help="random seed (default 0)")
    parser.add_argument("--repeats", type=int, default=7,
                        help="timed calls of each fit, the median kept (default 7)")
    parser.add_argument("--figure", metavar="PNG", action=OutputFile,
                        help="also draw the simulated edges of both cameras to this file "
                             "(docs/vision-edges.png; default: not drawn)")
    parser.add_argument("--overwrite", action="store_true",
                        help="replace --figure even if hexapod-bench did not write it")
    args = parser.parse_args(argv)
    check_counts(parser, args, "--poses", "--repeats")
    if args.points < MIN_POINTS:
        parser.error(f"--points: at least {MIN_POINTS} (the conic fit's least), got "
                     f"{args.points}")
    if not (math.isfinite(args.sigma) and args.sigma >= 0):
        parser.error(f"--sigma: a finite non-negative pixel noise, got {args.sigma}")
    if args.figure:
        from hexapod.outputs import check_replace

        check_replace(args.figure, args.overwrite, kind="PNG")
        edges_figure(args.figure, overwrite=args.overwrite)
        print(f"figure written to {args.figure}")
    start = time.perf_counter()
    figures = accuracy_figures(args.poses, args.points, args.sigma, args.seed, args.repeats)
    total = time.perf_counter() - start
    print(f"Edge-normal and leg-direction accuracy: reference robot, {args.poses} random "
          f"poses, {args.points} points per visible edge, {args.sigma} px Gaussian pixel "
          f"noise, seed {args.seed}; us/edge: the median of {args.repeats} calls")
    print("  front: perspective 1024x780, f = 1032 px, 0.8 m from the base centre")
    print("  omni:  unified xi = 1, 640x480, f = 200 px, at the base centre looking up")
    header = (f"{'camera':<7}{'fit':<7}{'feature':<11}{'median [deg]':>14}{'p95 [deg]':>12}"
              f"{'count':>8}{'failed':>8}{'us/edge':>9}")
    print(header)
    print("-" * len(header))
    for f in figures:
        print(f"{f.camera:<7}{f.fit:<7}{f.feature:<11}{f.median_deg:>14.4f}{f.p95_deg:>12.4f}"
              f"{f.count:>8d}{f.failed:>8d}{f.fit_us:>9.2f}")
    print(f"({total:.2f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
