"""``hexapod-bench identify ROBOT_OR_SCENARIO --out DIR``: the command line."""

from __future__ import annotations

import argparse
import shlex
import time
from pathlib import Path

import numpy as np

from benchmarks.exceptions import BenchmarkError
from hexapod.geometry import HexapodGeometry

#: The longest excitation ``--duration`` takes [s] (its 1 kHz record is held in memory).
MAX_DURATION_S = 3600.0


def add_arguments(s: argparse.ArgumentParser) -> None:
    """The ``identify`` subcommand's options."""
    from benchmarks.study.outdir import OutputDir

    s.add_argument("robot", metavar="ROBOT_OR_SCENARIO",
                   help="robot file (TOML), preset name, or scenario (its robot)")
    s.add_argument("--out", required=True, action=OutputDir, help="output directory")
    s.add_argument("--backend", default="world", metavar="SPEC",
                   help="where the excitation runs: 'world' (default: the dynamic world, the "
                        "simulated truth) or a backend that reports forces")
    s.add_argument("--truth", metavar="ROBOT",
                   help="the dynamic world's true robot (default: the robot file itself)")
    s.add_argument("--duration", type=float, default=20.0, metavar="S",
                   help="excitation length [s] (default 20)")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--force-noise", type=float, default=1.0, metavar="PERCENT",
                   help="force noise, percent of each leg's RMS force (default 1)")
    s.add_argument("--encoder-resolution", type=float, metavar="UM",
                   help="encoder resolution [um] (default: the robot file's)")
    s.add_argument("--search-candidates", type=int, default=16, metavar="N",
                   help="excitation shapes the search tries (default 16, under a second)")
    s.add_argument("--cutoff-hz", type=float, default=50.0, metavar="HZ",
                   help="the zero-phase filter's cutoff [Hz] applied to the lengths and "
                        "forces before they are differentiated (default 50, chosen for "
                        "1 um encoders; docs/identification.md, \"The filter's cutoff\")")
    s.add_argument("--overwrite", action="store_true",
                   help="replace a user's files of the same names in --out")


#: The robot presets ``identify`` takes by name.
PRESETS = ("deltalab",)


def load_robot(name: str, option: str = "ROBOT_OR_SCENARIO") -> HexapodGeometry:
    """A robot file, a preset, or a scenario's robot (``option``: where it was given).

    Raises:
        BenchmarkError: None of the three, naming the option, every choice and the close
            one.
    """
    from benchmarks.study.scenario import builtin_scenarios, load_scenario
    from hexapod.config import KIND_MARKERS, load_toml, suggest
    from hexapod.geometry import preset

    path = Path(name)
    if name in PRESETS:
        return preset(name)
    if path.suffix == ".toml" and path.exists():
        table = load_toml(path)  # a robot file's own key, or any (from_toml names a missing one)
        if any(k in table for k in KIND_MARKERS["robot file"]) and "controllers" not in table:
            return HexapodGeometry.from_toml(path)
    elif name not in builtin_scenarios():
        choices = [*PRESETS, *sorted(builtin_scenarios())]
        hint = suggest(name, choices)
        raise BenchmarkError(f"{option} {name!r}: no such robot file, preset or built-in "
                             f"scenario; presets: {', '.join(PRESETS)}; scenarios: "
                             f"{', '.join(choices[len(PRESETS):])}"
                             + (f" (did you mean '{hint}'?)" if hint else ""))
    from benchmarks.sim.world import load_geometry

    return load_geometry(load_scenario(name))


#: The encoder resolution [m] above which the estimate is biased (the filter is chosen
#: for 1 um encoders; a review measured the bias at 10 um).
COARSE_ENCODER = 2e-6
#: How far the mass moving with the platform may be from the robot file's before the
#: command says so (a factor: CAD masses are within tens of percent, a unit slip is 1000).
MASS_FACTOR = 3.0


def mass_slip(doc: dict) -> str | None:
    """A warning when the identified mass moving with the platform (``m_p + 6 m_r``) is
    more than :data:`MASS_FACTOR` times off the robot file's: forces in other units than
    newtons (kN gave a thousand times too light a robot, silently), or another robot."""
    mass = doc["base_parameters"][0]
    if mass["name"] != "m_p + 6 m_r" or not mass["prior"] > 0:
        return None
    ratio = mass["estimate"] / mass["prior"]
    if 1 / MASS_FACTOR <= ratio <= MASS_FACTOR:
        return None
    return (f"the identified m_p + 6 m_r is {mass['estimate']:.4g} kg, {ratio:.3g} times the "
            f"robot file's {mass['prior']:.4g} kg: forces in other units than newtons (kN, "
            "mN, a current without its gain), or another robot than the file's?")


def end_reading(record: dict) -> str | None:
    """A warning when a backend's forces are read at each period's end (said, or not
    said: ``force_timing``): the drives' velocity loop answers each new setpoint with a
    transient that a reading at the period's end does not see."""
    if record.get("force_timing") != "end":
        return None
    said = ("" if record.get("force_timing_declared") else
            "the backend does not say when its force is read (force_timing), so ")
    return (f"{said}the forces are taken as read at each period's end: the drives' "
            "response to each new setpoint within the period is not in them, and the rotor "
            "inertias come out low (13-19 % on the test suite's stand-in robot, exact "
            "readings); a drive that reports the period's mean or a mid-period reading "
            "(force_timing = \"mean\" or \"middle\") is aligned with the lengths "
            "(docs/identification.md)")


def run(args: argparse.Namespace) -> int:
    """Identify, print the table, write the outputs."""
    from rich.markup import escape
    from rich.table import Table

    from benchmarks.identify.outputs import write_all
    from benchmarks.identify.pipeline import WORLD_BACKENDS, Settings, check_backend, identify
    from benchmarks.study.commands import console
    from hexapod.dynamics.identification.excitation import BASE_FREQUENCY_HZ
    from hexapod.exceptions import IdentificationError

    if args.search_candidates < 2:
        raise IdentificationError(f"--search-candidates {args.search_candidates}: at least 2")
    for key, value in (("--duration", args.duration),
                       ("--force-noise", args.force_noise), ("--cutoff-hz", args.cutoff_hz)):
        positive = key in ("--duration", "--cutoff-hz")
        if not np.isfinite(value) or value < 0 or (positive and value <= 0):
            raise IdentificationError(f"{key} {value}: must be a finite "
                                      f"{'positive' if positive else 'non-negative'} number")
    if args.duration > MAX_DURATION_S:  # (a 1 kHz record of every joint, in memory)
        raise IdentificationError(f"--duration {args.duration:g}: at most {MAX_DURATION_S:g} s "
                                  "(the default excitation lasts 20 s)")
    if args.seed < 0:
        raise IdentificationError(f"--seed {args.seed}: must be >= 0")
    res = args.encoder_resolution
    if res is not None and not (np.isfinite(res) and res >= 0):
        raise IdentificationError(f"--encoder-resolution {res}: must be a finite number >= 0 "
                                  "[um] (0: exact lengths)")
    if args.truth and args.backend not in WORLD_BACKENDS:
        raise IdentificationError(f"--truth {args.truth}: the dynamic world's true robot; "
                                  f"--backend {args.backend} has its own (drop --truth, or "
                                  "use --backend world)")
    check_backend(args.backend)
    from benchmarks.identify.outputs import OUTPUTS
    from hexapod.outputs import check_output_dir, check_replace

    # a directory of other things (a run's results and report) is refused, even with
    # --overwrite only our own files would be replaced: a run's report.md is not ours
    check_output_dir(Path(args.out), lambda e: e.name in OUTPUTS,
                     f"directory of identify's outputs ({', '.join(OUTPUTS)})", args.overwrite)
    for name in OUTPUTS:  # before the run: a user's file is refused at once
        check_replace(Path(args.out) / name, args.overwrite, "--overwrite")
    robot = load_robot(args.robot)
    truth = load_robot(args.truth, "--truth") if args.truth else None
    settings = Settings(duration=args.duration, seed=args.seed,
                        force_noise=args.force_noise / 100,
                        resolution=(args.encoder_resolution * 1e-6
                                    if args.encoder_resolution is not None else None),
                        candidates=args.search_candidates, backend=args.backend,
                        cutoff_hz=args.cutoff_hz)
    if not settings.cutoff_hz < 0.5 / settings.sample_dt:  # (before the record, not after)
        raise IdentificationError(f"--cutoff-hz {args.cutoff_hz:g}: must be below the "
                                  f"Nyquist frequency of the {settings.sample_dt * 1e3:g} ms "
                                  f"record, {0.5 / settings.sample_dt:g} Hz")
    con = console()
    period = 1.0 / BASE_FREQUENCY_HZ
    if args.duration < period:
        con.print(f"warning: --duration {args.duration:g} s is shorter than one period of "
                  f"the excitation ({period:g} s): the record holds its fade-in only, and the "
                  "standard errors say how little it determines", markup=False,
                  highlight=False)
    coarse = (args.encoder_resolution * 1e-6 if args.encoder_resolution is not None
              else float(np.max((truth or robot).drives.encoder_resolution)))
    if coarse > COARSE_ENCODER:
        con.print(f"warning: encoders of {coarse * 1e6:g} um: the 50 Hz filter is chosen for "
                  "1 um ones, and coarser quantisation noise in the accelerations biases the "
                  "estimate (at 10 um: m_p + 6 m_r 3 % low, rotor inertias off by up to 60 %; "
                  "docs/identification.md)", markup=False, highlight=False)
    if truth is not None:
        for what, a, b in (("stroke", truth.stroke, robot.stroke),):
            if a[0] > b[0] + 1e-9 or a[1] < b[1] - 1e-9:
                con.print(f"warning: --truth {args.truth}: its {what} [{a[0] * 1e3:.3f}, "
                          f"{a[1] * 1e3:.3f}] mm is narrower than the robot file's "
                          f"[{b[0] * 1e3:.3f}, {b[1] * 1e3:.3f}] mm, which the excitation "
                          "keeps to: the true legs may pass their ends (the simulation does "
                          "not stop them)", markup=False, highlight=False)
    t0 = time.perf_counter()
    ident = identify(robot, settings, truth)
    con.print(f"excitation: condition number {ident.excitation.condition:.4g} (scaled base "
              f"regressor over one period, {ident.basis.size} base parameters)")
    command = "hexapod-bench " + shlex.join(getattr(args, "argv", []) or ["identify", args.robot])
    doc = write_all(ident, Path(args.out), command, args.overwrite)
    t = Table(title=f"Identified base parameters ({args.robot})")
    has_true = ident.truth is not None
    for col in ("base parameter", "unit", "estimate", "SE") + (("true", "z") if has_true
                                                                else ()):
        t.add_column(col, justify="left" if col == "base parameter" else "right")
    for p in doc["base_parameters"]:
        row = [escape(p["name"]), escape(p["unit"]), f"{p['estimate']:.6g}", f"{p['se']:.3g}"]
        if has_true:
            row += [f"{p['true']:.6g}", f"{p['z']:.2f}"]
        t.add_row(*row)
    con.print(t)
    for line in ident.estimate.consistency:
        con.print(f"consistency: {line}")
    if (slip := mass_slip(doc)) is not None:
        con.print(f"warning: {slip}", markup=False, highlight=False)
    if (late := end_reading(ident.record)) is not None:
        con.print(f"warning: {late}", markup=False, highlight=False)
    con.print(f"residual sigma per leg {np.round(ident.estimate.sigma_legs, 4).tolist()} N; "
              f"{time.perf_counter() - t0:.1f} s; wrote {args.out}/identified.toml, "
              "identification.json, report.md, residuals.png")
    return 0
