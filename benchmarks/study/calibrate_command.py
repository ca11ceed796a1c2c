"""``hexapod-bench calibrate``: the base points calibrated in a scenario's worlds, or from
a user's observations (``--observations``), with what the result says of itself."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

from benchmarks.exceptions import BenchmarkError
from benchmarks.study.commands import console

#: The rigid-fit RMS [mm] of a calibration from a user's observations above which it is
#: warned of (two random configurations gave 10.8 mm and points 28 mm off, unwarned).
FIT_RMS_WARN_MM = 5.0
#: How far from 1 the estimates' scale may be before a poor fit also names the leg
#: radius, when dividing by it halves the fit's RMS at least (a 10 % radius error gave a
#: scale of 0.909 and a warning that blamed the rest).
SCALE_WARN = 0.02


def cmd_calibrate(args: argparse.Namespace) -> int:
    """Calibrate the base points in a scenario's worlds (calibration.json, calibrated.toml)."""
    from rich.table import Table

    from benchmarks.study.calibration import run_calibration
    from benchmarks.study.metrics import format_sweep
    from benchmarks.study.scenario import load_scenario

    sc = load_scenario(args.scenario).with_overrides(seed=args.seed)
    sc = _with_ratio_options(sc, args)
    _setup_warnings(sc)
    out = Path(args.out)
    if args.observations:
        from benchmarks.study.calibration import calibrate_from_file

        simulated = [f"--{name} {value}" for name, value in (
            ("configurations", args.configurations), ("repeat", args.repeat),
            ("seed", args.seed)) if value is not None]
        if simulated:  # (they were dropped without a word)
            raise BenchmarkError(
                f"{', '.join(simulated)}: options of the simulated calibration (its "
                f"configurations, repetitions and draws); --observations {args.observations} "
                "is calibrated once from the configurations it holds: drop them")

        doc = calibrate_from_file(sc, Path(args.observations), out, args.solver,
                                  args.correct_scale, overwrite=args.overwrite)
        res = doc["result"]
        print(f"calibrated {doc['configurations']} configurations from {args.observations}: "
              f"rigid-fit RMS {res['fit_rms_mm']:.3f} mm, scale {res['scale']:.5f}; wrote "
              f"{out / 'calibration.json'} and {out / 'calibrated.toml'}")
        _print_far_from_nominal(doc, out)
        if res["fit_rms_mm"] > FIT_RMS_WARN_MM:
            scaled = (f"; the estimates are {res['scale']:.3f} times the robot's size: a leg "
                      "radius off by as much? (--correct-scale divides it out)"
                      if (abs(res["scale"] - 1.0) > SCALE_WARN and not args.correct_scale
                          and doc["fit_rms_scale_corrected_mm"] < 0.5 * res["fit_rms_mm"])
                      else "")
            print(f"warning: {args.observations}: the calibrated base points fit the robot's "
                  f"base only to {res['fit_rms_mm']:.1f} mm RMS (a rigid fit; CAD errors give "
                  "a millimetre or two): too few configurations for the noise, legs seen at "
                  "too few inclinations, or another robot's observations; do not trust "
                  f"calibrated.toml without more configurations{scaled}", file=sys.stderr)
        if doc["normals_flipped"]:
            print(f"note: {doc['normals_flipped']} edge normal(s) of {args.observations} "
                  "oriented to the calibration's sign (n . A = -r at the nominal base "
                  "point: a fitted line's normal has either sign)", file=sys.stderr)
        if doc["equations_disagree"]:
            worst = max(res["linear"]["residual_rms_mm"])
            print(f"warning: {args.observations}: the observations do not agree with one "
                  f"base point per leg (a leg's RMS residual n . A + r is {worst:.3f} mm, "
                  "noise gives a fraction of a millimetre): normals of the wrong sign that "
                  "orienting could not mend, normals not in this camera's frame, or another "
                  "robot's; do not trust calibrated.toml", file=sys.stderr)
        if doc["lengths_outside_stroke_count"]:
            k, leg, mm = doc["lengths_outside_stroke"][0]
            print(f"warning: {args.observations}: {doc['lengths_outside_stroke_count']} leg "
                  f"length(s) outside the robot's stroke (configuration {k}, leg {leg}: "
                  f"{mm:g} mm): lengths_mm is in mm and of this robot? (the calibration does "
                  "not use them; they are recorded)", file=sys.stderr)
        lin = res["linear"]
        for leg in lin["ill_conditioned_legs"]:
            print(f"warning: leg {leg} is ill-conditioned (singular-value ratio "
                  f"{lin['singular_value_ratio'][leg]:.2e} < {lin['warn_singular_ratio']:.2e}): "
                  "its base point is poorly determined; add configurations that show this "
                  "leg at other inclinations", file=sys.stderr)
        return 0
    if args.configurations is not None:  # the scenario file's rule, named by the option
        from benchmarks.study.scenario_checks import check_configurations

        check_configurations(args.configurations, "--configurations")
    repeat = 1 if args.repeat is None else args.repeat
    if repeat < 1:
        raise BenchmarkError(f"--repeat {repeat}: at least 1 repetition")
    t0 = time.perf_counter()
    doc = run_calibration(sc, out, args.configurations, repeat, args.solver,
                          args.correct_scale, overwrite=args.overwrite)
    con = console()
    t = Table(title=f"Base-point calibration ({sc.name}, {doc['configurations']}, "
                    f"{doc['solver']}, {repeat} repetition(s))")
    for col in ("sweep", "median error mm", "max error mm", "max component mm",
                "worst point median mm", "min singular ratio", "ill-conditioned legs"):
        t.add_column(col, justify="left" if col == "sweep" else "right")
    for p in doc["points"]:
        t.add_row(format_sweep({k.replace(".", "_"): v for k, v in p["sweep"].items()}),
                  f"{p['median_error_mm']:.3f}", f"{p['max_error_mm']:.3f}",
                  f"{p['max_component_error_mm']:.3f}",
                  f"{max(p['per_point_median_mm']):.3f}", f"{p['min_singular_ratio']:.4f}",
                  ", ".join(str(leg) for leg in p["ill_conditioned_legs"]) or "-")
    con.print(t)
    _print_far_from_nominal(doc["points"][0], out)
    con.print(f"{time.perf_counter() - t0:.1f} s; wrote {out / 'calibration.json'} and "
              f"{out / 'calibrated.toml'} (use: hexapod-bench run ... --calibration "
              f"{out / 'calibrated.toml'})")
    return 0


def _setup_warnings(sc: Any) -> None:
    """The warnings ``run``'s pre-flight gives of the scenario's robot and camera (a camera
    pose in metres, a focal length in millimetres, ...), on stderr before calibrating:
    a calibration in such a setup failed with a message naming neither ("leg 0: seen in
    0 configuration(s)") or ran without a word."""
    from benchmarks.study.check_command import examine, scenario_setup

    for p in examine(scenario_setup(sc)).problems:
        if p.severity != "error":  # (an error of the setup's is the calibration's to say)
            print(f"hexapod-bench: warning: {sc.name}: {p.text}", file=sys.stderr)


def _print_far_from_nominal(part: dict[str, Any], out: Path) -> None:
    """Flag the base points of calibrated.toml far from the nominal ones (stderr)."""
    from benchmarks.study.provenance import far_message

    text = far_message(str(out / "calibrated.toml"), part["distance_from_nominal_mm"],
                       part["far_from_nominal_threshold_mm"])
    if text:
        print(f"warning: {text}", file=sys.stderr)


def _with_ratio_options(sc: Any, args: argparse.Namespace) -> Any:
    """Apply ``--warn-ratio`` / ``--min-ratio`` to the scenario's ``[calibration]``."""
    from dataclasses import replace

    from benchmarks.study.scenario import check_range

    cal = sc.calibration
    for option, field in (("warn_ratio", "warn_singular_ratio"),
                          ("min_ratio", "min_singular_ratio")):
        value = getattr(args, option)
        if value is not None:
            check_range(value, f"calibration.{field}", f"--{option.replace('_', '-')}")
            cal = replace(cal, **{field: value})
    if cal.min_singular_ratio > cal.warn_singular_ratio:
        hard = ("--min-ratio" if args.min_ratio is not None
                else "[calibration] min_singular_ratio")
        warn = ("--warn-ratio" if args.warn_ratio is not None
                else "[calibration] warn_singular_ratio")
        raise BenchmarkError(f"{hard} {cal.min_singular_ratio:g} (refused below) exceeds "
                             f"{warn} {cal.warn_singular_ratio:g} (warned below): the warning "
                             f"ratio must be at least the refusal ratio; give --warn-ratio "
                             f"{cal.min_singular_ratio:g} or more")
    return replace(sc, calibration=cal)
