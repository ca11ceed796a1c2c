"""Detection benchmark: time per frame and accuracy of the leg-edge detectors.

Renders ``--frames`` random poses of the reference robot for the omnidirectional
(640x480, unified, xi = 1) and the front perspective (1024x780) cameras, detects
the twelve edges and compares the normals with the truth of
:func:`vision.legs.observe_legs`. The omnidirectional detector runs without
initialisation (home-pose association reference); the perspective tracker gets the
model prediction at a pose 3 mm off in each axis (tracking between frames).

With ``--distortion`` each camera also runs through a distorted lens, on the same
poses: the front camera with the 4.8 mm lens's distortion
(:data:`vision.cameras.FRONT_DISTORTION`, k1 = -0.28) and the omnidirectional one
with a mild Mei distortion (:data:`vision.cameras.OMNI_DISTORTION`, k1 = -0.08);
the front camera also through the other lens models (:func:`lens_models`: OpenCV's
full model, a Kannala-Brandt fisheye, a double sphere and an extended unified lens,
with the front camera's K and pose). The frames are rendered through the lens
(curved limbs) and the detectors use the camera model with the lens. The ``lens``
column tells the rows apart; ``vs ideal`` is the detection time over the same
camera's ideal-lens time (goal of the lens models: 2x at most).

``--rounds N`` also times the detection of every camera round by round, the cameras
interleaved, so that the ratios to the ideal lens hold when the machine's load changes.

Run: ``python -m benchmarks.perf.detect [--frames N] [--background plain|cluttered]
[--distortion] [--rounds N] [--pictures DIR]``.
"""

from __future__ import annotations

import argparse
import math
import platform
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from benchmarks.perf import check_counts, seed
from benchmarks.study.outdir import OutputDir
from hexapod import deltalab
from hexapod.outputs import check_replace, write_output
from hexapod.workspace import sample_poses
from vision import kernels
from vision.cameras import (
    FRONT_DISTORTION,
    OMNI_DISTORTION,
    Camera,
    DoubleSphereCamera,
    ExtendedUnifiedCamera,
    FisheyeCamera,
    PerspectiveCamera,
    front_camera,
    omni_camera,
)
from vision.cameras.presets import FISHEYE_DISTORTION
from vision.detect import LegPrediction, OmniDetector, PerspectiveTracker, draw_detection
from vision.legs import observe_legs
from vision.render import Renderer, RenderStyle

#: Goals of the issue [ms per frame].
GOALS_MS = {"omni": 0.3, "front": 2.0}

#: OpenCV's full model of :func:`lens_models`: the 4.8 mm lens's five coefficients plus
#: rational, thin-prism and tilt terms.
FULL_DISTORTION = (-0.28, 0.09, 5e-4, -3e-4, -0.012, 0.02, 0.004, 0.0, 2e-4, -1e-4, 3e-4,
                   1e-4, 0.002, -0.001)
#: The double sphere and extended unified lenses of :func:`lens_models`.
DS_LENS = (-0.15, 0.57)
EUCM_LENS = (0.6, 1.1)

#: Below this visible fraction a reported edge is invented (nothing of it to see).
INVENTED_FRACTION = 0.25


@dataclass
class EdgeCounts:
    """Bookkeeping of detected edges against the truth, accumulated over frames.

    Attributes:
        truth: Edges the truth calls visible (:func:`vision.legs.observe_legs`).
        found: Of those, the ones the detector reported (``found + missed == truth``).
        missed: Of those, the ones it did not report.
        partly_hidden: Edges reported although the truth calls them hidden, with at least
            :data:`INVENTED_FRACTION` of their length in view (a legitimate find of a
            partly occluded edge; not counted in ``found``).
        invented: Edges reported with less than :data:`INVENTED_FRACTION` in view.
    """

    truth: int = 0
    found: int = 0
    missed: int = 0
    partly_hidden: int = 0
    invented: int = 0

    def add(self, truth_visible: np.ndarray, visible_fraction: np.ndarray,
            detected: np.ndarray) -> None:
        """Count one frame: (6, 2) truth visibility, visible fraction and detections."""
        truth_visible = np.asarray(truth_visible, bool)
        detected = np.asarray(detected, bool)
        extra = detected & ~truth_visible
        self.truth += int(truth_visible.sum())
        self.found += int((truth_visible & detected).sum())
        self.missed += int((truth_visible & ~detected).sum())
        self.invented += int((extra & (visible_fraction < INVENTED_FRACTION)).sum())
        self.partly_hidden += int((extra & (visible_fraction >= INVENTED_FRACTION)).sum())


def lens_models(front: PerspectiveCamera) -> list[tuple[str, Camera]]:
    """The front camera through the other lens models, labelled: OpenCV's full model
    (:data:`FULL_DISTORTION`), the fisheye (Kannala-Brandt, the fisheye preset's
    coefficients), the double sphere (:data:`DS_LENS`, its focal lengths times
    ``1 + xi`` so that the centre of the image is magnified as by the front camera)
    and the extended unified model (:data:`EUCM_LENS`)."""
    xi = DS_LENS[0]
    Kd = front.K.copy()
    Kd[:2, :2] *= 1.0 + xi
    Kd[0, 1] = 0.0
    pose, w, h = front.camera_from_base, front.width, front.height
    return [("opencv-full", front.replace(distortion=FULL_DISTORTION)),
            ("fisheye", FisheyeCamera(front.K, w, h, pose, distortion=FISHEYE_DISTORTION)),
            ("double-sphere", DoubleSphereCamera(Kd, w, h, pose, distortion=DS_LENS)),
            ("eucm", ExtendedUnifiedCamera(front.K, w, h, pose, distortion=EUCM_LENS))]


def picture_name(omni: bool, lens: str, style: RenderStyle) -> str:
    """``detect-omni.png``, ``detect-front-cluttered-distorted.png``..."""
    suffix = "" if style.background == "plain" else f"-{style.background}"
    suffix += "" if lens == "ideal" else f"-{lens}"
    return f"detect-{'omni' if omni else 'front'}{suffix}.png"


def _run(cam: Camera, frames: int, style: RenderStyle, seed: int,
         pictures: Path | None, repeats: int, lens: str = "ideal",
         overwrite: bool = False) -> dict[str, float]:
    geo = deltalab()
    rng = np.random.default_rng(seed)
    Rs, ts = sample_poses(geo, frames, rng)
    renderer = Renderer(cam, geo, style, rng=rng)
    omni = cam.family == "unified"
    det_o = OmniDetector(cam) if omni else None
    det_p = None if omni else PerspectiveTracker(cam)
    auto = det_o.default_prediction(geo) if det_o is not None else None
    render_t: list[float] = []
    detect_t: list[float] = []
    numpy_t: list[float] = []
    errs: list[np.ndarray] = []
    counts = EdgeCounts()
    for k in range(frames):
        t0 = time.perf_counter()
        img = renderer.render(Rs[k], ts[k])
        render_t.append(time.perf_counter() - t0)
        obs = observe_legs(cam, geo, Rs[k], ts[k])
        pred = auto if omni else LegPrediction.from_pose(cam, geo, Rs[k], ts[k] + 0.003)
        for compiled, times in ((True, detect_t), (False, numpy_t)):
            best = np.inf
            for _ in range(repeats):
                t0 = time.perf_counter()
                if det_o is not None:
                    d = det_o.detect(img, pred, use_compiled=compiled)
                else:
                    assert det_p is not None and pred is not None
                    d = det_p.detect(img, pred, use_compiled=compiled)
                best = min(best, time.perf_counter() - t0)
            times.append(best)
            if compiled:
                d_compiled = d
        d = d_compiled
        e = np.degrees(np.arccos(np.clip(np.sum(d.normals * obs.normals, -1), -1.0, 1.0)))
        errs.append(e[d.edge_visible & obs.edge_visible])
        counts.add(obs.edge_visible, obs.visible_fraction, d.edge_visible)
        if pictures is not None and k == 0:
            pictures.mkdir(parents=True, exist_ok=True)
            ok, png = cv2.imencode(".png", draw_detection(img, cam, d))
            if ok:
                write_output(pictures / picture_name(omni, lens, style), png.tobytes(),
                             overwrite)
    e = np.concatenate(errs) if errs else np.array([np.nan])
    return {
        "render_ms": 1e3 * float(np.median(render_t)),
        "detect_ms": 1e3 * float(np.median(detect_t)),
        "detect_p95_ms": 1e3 * float(np.percentile(detect_t, 95)),
        "numpy_ms": 1e3 * float(np.median(numpy_t)),
        "speedup": float(np.median(np.array(numpy_t) / np.array(detect_t))),
        "median_deg": float(np.median(e)),
        "p95_deg": float(np.percentile(e, 95)),
        "max_deg": float(np.max(e)),
        "found": float(counts.found),
        "truth_visible": float(counts.truth),
        "missed": float(counts.missed),
        "partly_hidden": float(counts.partly_hidden),
        "invented": float(counts.invented),
    }


def interleaved_times(cameras: list[tuple[str, str, Camera]], frames: int, rounds: int,
                      style: RenderStyle, seed: int) -> list[tuple[float, float]]:
    """Detection time of each camera measured round by round, the cameras interleaved
    (so that a change of the machine's load hits them alike): ``frames`` rendered
    frames per camera (the same poses), every round detecting all of them with each
    camera in turn. Returns per camera the fastest and the median round [ms per
    frame]."""
    geo = deltalab()
    Rs, ts = sample_poses(geo, frames, np.random.default_rng(seed))
    work: list[tuple[OmniDetector | PerspectiveTracker, list[np.ndarray],
                     list[LegPrediction]]] = []
    for _, _, cam in cameras:
        renderer = Renderer(cam, geo, style, rng=np.random.default_rng(seed))
        imgs = [renderer.render(Rs[k], ts[k]) for k in range(frames)]
        det: OmniDetector | PerspectiveTracker
        if cam.family == "unified":
            det = OmniDetector(cam)
            preds = [det.default_prediction(geo)] * frames
        else:
            det = PerspectiveTracker(cam)
            preds = [LegPrediction.from_pose(cam, geo, Rs[k], ts[k] + 0.003)
                     for k in range(frames)]
        work.append((det, imgs, preds))
    times: list[list[float]] = [[] for _ in cameras]
    for _ in range(rounds):
        for c, (det, imgs, preds) in enumerate(work):
            t0 = time.perf_counter()
            for k in range(frames):
                det.detect(imgs[k], preds[k])
            times[c].append(1e3 * (time.perf_counter() - t0) / frames)
    return [(float(np.min(t)), float(np.median(t))) for t in times]


def main(argv: Sequence[str] | None = None) -> int:
    """Command-line entry point; returns the exit status."""
    p = argparse.ArgumentParser(prog="hexapod-bench perf detect",
                                description=__doc__.splitlines()[0])
    p.add_argument("--frames", type=int, default=200,
                   help="random poses per camera (default 200)")
    p.add_argument("--background", choices=("plain", "cluttered"), default="plain",
                   help="background of the rendered frames (default plain)")
    p.add_argument("--blur", type=float, default=0.8,
                   help="Gaussian blur sigma [px] (default 0.8)")
    p.add_argument("--noise", type=float, default=3.0,
                   help="pixel noise std [grey levels] (default 3)")
    p.add_argument("--repeats", type=int, default=1,
                   help="detections per frame, the fastest kept (default 1: each frame's "
                        "first detection, as a camera's new frame is detected; with more, "
                        "the frame's data are in the CPU's caches from the first: about 1.5 "
                        "times faster)")
    p.add_argument("--seed", type=seed, default=2026,
                   help="random seed of the poses and the rendering (default 2026)")
    p.add_argument("--distortion", action="store_true",
                   help="also run each camera through a distorted lens (same poses)")
    p.add_argument("--rounds", type=int, default=0,
                   help="also time the detection of every camera round by round, the "
                        "cameras interleaved (N rounds of 10 frames each): the ratios to "
                        "the ideal lens under a changing machine load (default 0: not "
                        "timed)")
    p.add_argument("--pictures", type=Path, default=None, action=OutputDir,
                   help="write detect-omni.png / detect-front.png of the first frame here "
                        "(-cluttered before .png on a cluttered background; with "
                        "--distortion also detect-omni-distorted.png, "
                        "detect-front-distorted.png and detect-front-LENS.png of the other "
                        "lens models; default: none written)")
    p.add_argument("--overwrite", action="store_true",
                   help="replace pictures of those names that hexapod-bench did not write")
    args = p.parse_args(argv)
    check_counts(p, args, "--frames", "--repeats")
    for name, unit in (("blur", "a blur sigma [px]"), ("noise", "a noise std [grey levels]")):
        value = getattr(args, name)
        if not (math.isfinite(value) and value >= 0):
            p.error(f"--{name}: {unit} >= 0, got {value}")
    style = RenderStyle(background=args.background, blur_px=args.blur, noise_std=args.noise)
    out = sys.stdout
    out.write(f"# Leg-edge detection benchmark ({args.frames} frames per camera, background "
              f"{args.background}, blur {args.blur} px, noise {args.noise} grey levels)\n")
    out.write(f"# detection: {'compiled (vision.kernels)' if kernels.available() else 'numpy'}"
              f"; the numpy reference is timed on the same frames\n")
    out.write(f"# {platform.processor() or platform.machine()}, Python "
              f"{platform.python_version()}, numpy {np.__version__}, OpenCV {cv2.__version__}\n")
    if args.distortion:
        out.write(f"# lenses: front distorted {_coefficients(FRONT_DISTORTION)} (k1, k2, p1, "
                  f"p2, k3), omni distorted {_coefficients(OMNI_DISTORTION)} (Mei: k1, k2, "
                  f"p1, p2); front also through opencv-full {_coefficients(FULL_DISTORTION)}, "
                  f"fisheye {_coefficients(FISHEYE_DISTORTION)} (k1..k4), double-sphere "
                  f"{_coefficients(DS_LENS)} (xi, alpha), eucm {_coefficients(EUCM_LENS)} "
                  f"(alpha, beta); same poses for every lens\n")
    header = ("camera", "size", "render ms", "detect ms (median)", "detect ms (p95)",
              "goal ms", "numpy ms (median)", "numpy / compiled", "err median deg",
              "err p95 deg", "err max deg", "found/visible", "missed", "partly hidden found",
              "invented", "lens", "vs ideal")
    out.write("| " + " | ".join(header) + " |\n|" + "---|" * len(header) + "\n")
    cameras: list[tuple[str, str, Camera]] = []
    front = front_camera()
    presets: list[tuple[str, Camera, tuple[float, ...]]] = [
        ("omni", omni_camera(), OMNI_DISTORTION), ("front", front, FRONT_DISTORTION)]
    for name, ideal, distortion in presets:
        cameras.append((name, "ideal", ideal))
        if args.distortion:
            cameras.append((name, "distorted", ideal.replace(distortion=distortion)))
    if args.distortion:
        cameras += [("front", label, cam) for label, cam in lens_models(front)]
    if args.pictures is not None:  # refused before any work, never half-way
        for name, lens, _ in cameras:
            check_replace(args.pictures / picture_name(name == "omni", lens, style),
                          args.overwrite)
    ideal_ms: dict[str, float] = {}
    for name, lens, cam in cameras:
        r = _run(cam, args.frames, style, args.seed, args.pictures, args.repeats, lens,
                 args.overwrite)
        ideal_ms.setdefault(name, r["detect_ms"])
        out.write(f"| {name} | {cam.width}x{cam.height} | {r['render_ms']:.2f} | "
                  f"{r['detect_ms']:.3f} | {r['detect_p95_ms']:.3f} | {GOALS_MS[name]} | "
                  f"{r['numpy_ms']:.3f} | {r['speedup']:.1f}x | "
                  f"{r['median_deg']:.4f} | {r['p95_deg']:.4f} | {r['max_deg']:.4f} | "
                  f"{int(r['found'])}/{int(r['truth_visible'])} | {int(r['missed'])} | "
                  f"{int(r['partly_hidden'])} | {int(r['invented'])} | {lens} | "
                  f"{r['detect_ms'] / ideal_ms[name]:.2f}x |\n")
    if args.rounds > 0:
        out.write(f"\n# interleaved: {args.rounds} rounds of 10 frames per camera, the "
                  "cameras in turn in each round\n| camera | lens | fastest round ms | vs "
                  "ideal (fastest) | median round ms | vs ideal (median) |\n"
                  "|---|---|---|---|---|---|\n")
        rounds = interleaved_times(cameras, 10, args.rounds, style, args.seed)
        base: dict[str, tuple[float, float]] = {}
        for (name, lens, _), (fast, med) in zip(cameras, rounds, strict=True):
            b = base.setdefault(name, (fast, med))
            out.write(f"| {name} | {lens} | {fast:.3f} | {fast / b[0]:.2f}x | {med:.3f} | "
                      f"{med / b[1]:.2f}x |\n")
    return 0


def _coefficients(c: Sequence[float]) -> str:
    return "(" + ", ".join(f"{v:g}" for v in c) + ")"


if __name__ == "__main__":
    raise SystemExit(main())
