"""hexapod-bench reproduce --sensitivity: the grid's parameters reach the scenarios, the
report says which points match every figure, and a tiny run works end to end."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from benchmarks.exceptions import BenchmarkError
from benchmarks.sim import load_camera, load_geometry
from benchmarks.study.paper_figures import builtin_figures
from benchmarks.study.reproduce import Result, verdicts
from benchmarks.study.scenario import load_scenario
from benchmarks.study.sensitivity import (
    EXCLUDED_STUDIES,
    Point,
    PointResult,
    evaluated,
    grid,
    parse_axis,
    report,
    run_sensitivity,
)


def test_a_point_changes_radius_camera_gain_and_goal_noise() -> None:
    sc = load_scenario("andreff2006-front-camera")
    assert sc.controllers[0].options["adaptive_gain"] == [5.0, 1.0, 30.0]
    p = Point(10.0, 0.9, 2.0, "off")
    out = p.apply(sc)
    assert load_geometry(out).leg_radius == pytest.approx(0.010)
    eye = load_camera(out, load_geometry(out)).base_from_camera.translation
    eye0 = load_camera(sc, load_geometry(sc)).base_from_camera.translation
    assert np.hypot(*eye[:2]) == pytest.approx(0.9 / 0.8 * np.hypot(*eye0[:2]))
    assert all(c.options["gain"] == 2.0 and "adaptive_gain" not in c.options
               for c in out.controllers)
    assert sc.noise.on_goal and not out.noise.on_goal
    # "declared" leaves the study's own gain and goal noise; the omni camera stays
    same = Point(15.0, 0.7, "declared", "declared").apply(sc)
    assert same.controllers == sc.controllers and same.noise == sc.noise
    omni = load_scenario("tahri2009-convergence")
    assert Point(15.0, 0.7, "declared", "on").apply(omni).camera_data is None


def test_parse_axis_and_grid() -> None:
    assert parse_axis("leg_radius_mm", "10, 15") == (10.0, 15.0)
    assert parse_axis("gain", "declared,1") == ("declared", 1.0)
    assert parse_axis("goal_noise", "on,off") == ("on", "off")
    with pytest.raises(BenchmarkError, match="--camera-distance-m: 'far' is not a number"):
        parse_axis("camera_distance_m", "0.8,far")
    with pytest.raises(BenchmarkError, match="--leg-radius-mm: '-1' must be positive"):
        parse_axis("leg_radius_mm", "-1")
    with pytest.raises(BenchmarkError, match="--goal-noise: 'maybe'"):
        parse_axis("goal_noise", "maybe")
    assert len(grid({})) == 3 * 3 * 2 * 3
    assert grid({"leg_radius_mm": (15.0,), "camera_distance_m": (0.8,), "gain": ("declared",),
                 "goal_noise": ("declared",)}) == [Point(15.0, 0.8, "declared", "declared")]
    assert not any(f.study in EXCLUDED_STUDIES for f in evaluated())
    assert len(evaluated()) < len(builtin_figures())


def test_report_names_the_points_matching_every_figure() -> None:
    f = next(f for f in builtin_figures() if f.id == "seed003-convergence-edges")
    v = replace(f, id="v", variant_of=f.id)

    def point(p: Point, ok: bool) -> PointResult:
        rs = [Result(f, "", 1.0 if ok else 0.9, (0.99, 1.0) if ok else (0.8, 0.95), 20),
              Result(v, "", 0.5, (0.3, 0.7), 20)]
        verdicts(rs)
        return PointResult(p, rs)

    a, b = Point(10.0, 0.8, "declared", "on"), Point(15.0, 0.8, "declared", "on")
    text = report([point(a, False), point(b, True)], 3)
    assert f"Points with every paper figure within: {b.name}" in text
    assert "`OO`" in text and "`WO`" in text  # the variant does not count
    assert f"1. `{f.id}`: within at 1 of 2 points ({b.name})" in text
    text = report([point(a, False)], 3)
    assert "Points with every paper figure within: none (at best 0 of 1)" in text


def test_sensitivity_json_is_standard_json(tmp_path: Path) -> None:
    """An interval's end beyond the sample was written as bare -Infinity, which a
    standard JSON reader refuses: it is "-inf" now, as compare --json writes it."""
    from benchmarks.study.sensitivity import write

    f = next(f for f in builtin_figures() if f.id == "seed003-convergence-edges")
    rs = [Result(f, "", 0.9, (-math.inf, 0.95), 3)]
    verdicts(rs)
    j, _ = write(tmp_path, [PointResult(Point(15.0, 0.8, "declared", "on"), rs)], 3)

    def refuse(name: str) -> float:
        raise ValueError(f"non-standard JSON constant {name}")

    text = json.dumps(json.loads(j.read_text(), parse_constant=refuse))
    assert '"-inf"' in text


@pytest.mark.slow
def test_tiny_sensitivity_run(tmp_path: Path) -> None:
    from benchmarks.study.sensitivity import write

    figs = [f for f in builtin_figures() if f.study == "run:tahri2009-convergence"]
    points = [Point(r, 0.8, "declared", "declared") for r in (10.0, 20.0)]
    res = run_sensitivity(points, tmp_path, trials=2, say=lambda _t: None, figures=figs)
    assert [len(pr.results) for pr in res] == [2, 2]
    assert all(r.n == 2 for pr in res for r in pr.results)
    j, m = write(tmp_path, res, 2)
    doc = json.loads(j.read_text())
    assert [p["point"]["leg_radius_mm"] for p in doc["points"]] == [10.0, 20.0]
    assert "Points with every paper figure within" in m.read_text()
    assert (tmp_path / points[0].name / "run_tahri2009-convergence-quick").is_dir()
