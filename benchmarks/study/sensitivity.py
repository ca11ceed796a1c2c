"""``hexapod-bench reproduce --sensitivity``: the declared paper figures over a grid of the
free parameters chosen while matching the papers.

The parameters (docs/reproduction.md, "Sensitivity"):

- the legs' radius (15 mm in the ``deltalab`` preset; the papers do not give it): the
  edges the camera sees and the calibration from them;
- the front camera's horizontal distance from the base centre (0.8 m in the ``front``
  preset; seed 002 says "about 0.7 m", at which the nearest legs leave the image);
- the control gain: the studies' declared adaptive gain ``[5, 1, 30]``, or a constant
  ``lambda`` [1/s] (the papers' law);
- noise on the goal's features: as each study declares it (seed 001's simulation has a
  noise-free goal, seed 002's real robot a noisy one), on everywhere, or off everywhere.

Every point of the grid runs the studies of the declared rows into its own directory
and applies the scorecard's rules (:mod:`benchmarks.study.reproduce`); the report says
which points have every paper figure within, and, row by row, at which points it is.
The image-in-the-loop studies are left out (they cost minutes per trial on this
machine's cores); their rows are not evaluated.
"""

from __future__ import annotations

import itertools
import json
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from benchmarks.exceptions import BenchmarkError
from benchmarks.study.paper_figures import Figure, builtin_figures
from benchmarks.study.reproduce import Result, reproduce, summary
from hexapod.outputs import json_signed

#: Studies the sensitivity study leaves out (rendered images in the loop).
EXCLUDED_STUDIES = ("run:andreff2006-images", "run:tahri2009-images")
#: The default grid.
DEFAULT_GRID: dict[str, tuple[Any, ...]] = {
    "leg_radius_mm": (10.0, 15.0, 20.0),
    "camera_distance_m": (0.7, 0.8, 0.9),
    "gain": ("declared", 1.0),
    "goal_noise": ("declared", "on", "off"),
}
#: Short names of the verdict categories in the grid table.
LETTERS = {"within": "W", "outside": "O", "contradicts": "C", "not comparable": "N"}
#: What the sensitivity study writes into its directory.
REPORT_FILES = ("sensitivity.json", "sensitivity.md")


@dataclass(frozen=True)
class Point:
    """One point of the grid.

    Attributes:
        leg_radius_mm: The legs' radius [mm].
        camera_distance_m: The front camera's distance from the base centre [m].
        gain: ``"declared"`` (each study's own) or a constant gain [1/s].
        goal_noise: ``"declared"``, ``"on"`` or ``"off"``.
    """

    leg_radius_mm: float
    camera_distance_m: float
    gain: str | float
    goal_noise: str

    @property
    def name(self) -> str:
        """The point's directory name."""
        g = "declared" if self.gain == "declared" else f"{float(self.gain):g}"
        return (f"r{self.leg_radius_mm:g}mm_d{self.camera_distance_m:g}m_gain-{g}"
                f"_goalnoise-{self.goal_noise}")

    def apply(self, sc: Any) -> Any:
        """The scenario with this point's parameters (a robot preset or camera preset the
        parameter does not apply to, e.g. the omnidirectional camera, is left as is)."""
        from benchmarks.sim import load_geometry
        from hexapod.geometry import preset as geometry_preset
        from vision.cameras.presets import front_camera

        if sc.geometry_data is None and sc.robot_geometry is None:
            geometry = replace(geometry_preset(sc.robot_preset or "deltalab"),
                               leg_radius=1e-3 * self.leg_radius_mm)
            sc = replace(sc, geometry_data=geometry)
        if sc.camera_preset == "front" and sc.camera_data is None:
            sc = replace(sc, camera_data=front_camera(load_geometry(sc),
                                                      self.camera_distance_m))
        if self.gain != "declared":
            controllers = tuple(
                replace(c, options={**{k: v for k, v in c.options.items()
                                       if k != "adaptive_gain"}, "gain": float(self.gain)})
                for c in sc.controllers)
            sc = replace(sc, controllers=controllers)
        if self.goal_noise != "declared":
            sc = replace(sc, noise=replace(sc.noise, on_goal=self.goal_noise == "on"))
        return sc


def parse_axis(key: str, text: str) -> tuple[Any, ...]:
    """Values of one grid axis from a comma-separated option.

    Raises:
        BenchmarkError: A value that is not a number (or, for ``gain`` and
            ``goal_noise``, not one of the words), naming the option and the value.
    """
    out: list[Any] = []
    for token in (t.strip() for t in text.split(",")):
        if key == "goal_noise":
            if token not in ("declared", "on", "off"):
                raise BenchmarkError(f"--goal-noise: {token!r}: expected declared, on, off")
            out.append(token)
            continue
        if key == "gain" and token == "declared":
            out.append(token)
            continue
        try:
            v = float(token)
        except ValueError:
            raise BenchmarkError(f"--{key.replace('_', '-')}: {token!r} is not a number"
                                 + (" or 'declared'" if key == "gain" else "")) from None
        if not v > 0 or v == float("inf"):
            raise BenchmarkError(f"--{key.replace('_', '-')}: {token!r} must be positive "
                                 "and finite")
        out.append(v)
    if not out:
        raise BenchmarkError(f"--{key.replace('_', '-')}: no value")
    return tuple(out)


def grid(axes: Mapping[str, Sequence[Any]]) -> list[Point]:
    """Every point of the Cartesian product of the axes (missing axes: the defaults)."""
    full = {k: tuple(axes.get(k, v)) for k, v in DEFAULT_GRID.items()}
    return [Point(*values) for values in itertools.product(*full.values())]


def evaluated(figures: Sequence[Figure] | None = None) -> list[Figure]:
    """The declared rows the sensitivity study evaluates (not the image studies)."""
    figs = list(builtin_figures()) if figures is None else list(figures)
    return [f for f in figs if f.study not in EXCLUDED_STUDIES]


@dataclass
class PointResult:
    """The scorecard at one point of the grid."""

    point: Point
    results: list[Result]

    @property
    def all_within(self) -> bool:
        """Every paper figure (variants aside) within."""
        return all(r.category == "within" for r in self.results if not r.figure.variant_of)

    @property
    def within(self) -> int:
        """Paper figures within (variants aside)."""
        return sum(r.category == "within" for r in self.results if not r.figure.variant_of)


def run_sensitivity(points: Sequence[Point], out: Path, trials: int, workers: int = 1,
                    say: Callable[[str], None] = print,
                    figures: Sequence[Figure] | None = None) -> list[PointResult]:
    """Evaluate the declared rows at every point, each point in ``out / point.name``.

    Args:
        points: The grid.
        out: The study's directory.
        trials: Trials per run study and calibrations per calibration study.
        workers: Worker processes.
        say: Progress lines.
        figures: The declared rows (default: :func:`evaluated`).
    """
    figs = evaluated(figures)
    res = []
    for i, p in enumerate(points):
        say(f"sensitivity point {i + 1}/{len(points)}: {p.name}")
        res.append(PointResult(p, reproduce("all", out / p.name, True, workers, say,
                                            figures=figs, transform=p.apply,
                                            trials=trials)))
    return res


def report(results: Sequence[PointResult], trials: int) -> str:
    """The sensitivity study as Markdown: the grid (a letter per row), the points with
    every paper figure within, and the points at which each row is within."""
    if not results:
        return "no point\n"
    figs = [r.figure for r in results[0].results]
    own = [f for f in figs if not f.variant_of]
    lines = [f"Sensitivity of the scorecard ({trials} trials per study and point; "
             f"{len(own)} paper figures and {len(figs) - len(own)} variants evaluated, the "
             "image studies left out). W within, O outside, C contradicts, N not "
             "comparable; columns in the order of the rows below.", "",
             "| leg radius mm | camera m | gain | goal noise | paper figures within | "
             "verdicts |", "|---|---|---|---|---|---|"]
    for pr in results:
        p = pr.point
        letters = "".join(LETTERS[r.category] for r in pr.results)
        lines.append(f"| {p.leg_radius_mm:g} | {p.camera_distance_m:g} | {p.gain} | "
                     f"{p.goal_noise} | {pr.within}/{len(own)} | `{letters}` |")
    match = [pr.point.name for pr in results if pr.all_within]
    best = max(pr.within for pr in results)
    lines += ["", "Points with every paper figure within: "
              + (", ".join(match) if match else f"none (at best {best} of {len(own)})"), "",
              "Rows (column order), and the points at which each is within:", ""]
    for j, f in enumerate(figs):
        at = [pr.point.name for pr in results if pr.results[j].category == "within"]
        tag = f" (variant of {f.variant_of})" if f.variant_of else ""
        lines.append(f"{j + 1}. `{f.id}`{tag}: within at {len(at)} of {len(results)} points"
                     + (f" ({', '.join(at)})" if 0 < len(at) < len(results) else ""))
    lines += ["", "Per point: " + "; ".join(f"{pr.point.name}: {summary(pr.results).split('. ')[0]}"
                                            for pr in results)]
    return "\n".join(lines) + "\n"


def to_json(results: Sequence[PointResult], trials: int) -> dict[str, Any]:
    """The sensitivity study as data (``sensitivity.json``)."""
    return {"trials": trials, "points": [
        {"point": {"leg_radius_mm": pr.point.leg_radius_mm,
                   "camera_distance_m": pr.point.camera_distance_m,
                   "gain": pr.point.gain, "goal_noise": pr.point.goal_noise},
         "all_within": pr.all_within,
         "rows": {r.figure.id: {"verdict": r.verdict, "value": r.value,
                                "interval": list(r.interval) if r.interval else None,
                                "n": r.n} for r in pr.results}}
        for pr in results]}


def write(out: Path, results: Sequence[PointResult], trials: int) -> tuple[Path, Path]:
    """Write ``sensitivity.json`` and ``sensitivity.md`` into ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    j, m = out / REPORT_FILES[0], out / REPORT_FILES[1]
    # standard JSON: an interval's end beyond the sample is "inf"/"-inf", not -Infinity
    j.write_text(json.dumps(json_signed(to_json(results, trials)), indent=2,
                            allow_nan=False) + "\n")
    m.write_text(report(results, trials))
    return j, m


def sensitivity_entry(entry: Path) -> bool:
    """Whether an entry of ``reproduce --sensitivity --out`` is the study's own: its
    report files, or a point's directory of study directories."""
    from benchmarks.study.outdir import study_entry

    if entry.name in REPORT_FILES:
        return entry.is_file()
    return entry.is_dir() and all(study_entry(e) for e in entry.iterdir())
