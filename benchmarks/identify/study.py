"""The identification study: Monte Carlo coverage of the standard errors.

A robot with lopsided inertia (:func:`lopsided`: the platform's centre of mass off its
axis, products of inertia, drives that differ leg by leg) is the dynamic world's truth;
the robot file handed to the identification is the nominal DeltaLab (its inertia and
drives the assumed defaults, so the prior is wrong). For every excitation length the
excitation is searched and run once (the truth's motion is deterministic); then, for
each configuration of encoder resolution and force noise, ``reps`` sensor realisations
(an encoder zero drawn within one count, then quantised; Gaussian force noise) are
identified. Reported per configuration: every base parameter's mean error, its RMS z
score and the fraction of the 95 % intervals (estimate +- 1.96 SE) that cover the truth.

Run: ``python -m benchmarks.identify.study --out DIR [--reps N]``
(``docs/identification.md``).
"""

from __future__ import annotations

import argparse
import logging
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.identify.pipeline import Settings, measured
from benchmarks.identify.simulate import run
from hexapod.dynamics.identification.base import base_parameters
from hexapod.dynamics.identification.estimation import weighted_least_squares
from hexapod.dynamics.identification.excitation import optimise
from hexapod.dynamics.identification.parameters import standard_vector
from hexapod.dynamics.identification.processing import samples
from hexapod.dynamics.identification.regressor import regressor
from hexapod.geometry import HexapodGeometry, preset
from hexapod.outputs import write_output

log = logging.getLogger(__name__)

#: (resolution [m], force noise [fraction], excitation length [s]) of the default study.
CONFIGURATIONS = ((1e-6, 0.01, 10.0), (10e-6, 0.01, 10.0), (1e-6, 0.05, 10.0),
                  (1e-6, 0.01, 20.0))


def lopsided(geometry: HexapodGeometry) -> HexapodGeometry:
    """``geometry`` with lopsided inertia and uneven drives (the study's truth)."""
    inertia = geometry.inertia.replace(
        platform_mass=2.6, platform_com=np.array([0.015, -0.010, 0.008]),
        platform_inertia=np.array([0.016, 0.021, 0.030, 0.002, -0.0015, 0.001]),
        body_mass=0.6, rod_mass=0.25, rod_com=0.12)
    drives = geometry.drives.replace(
        rotor_inertia=np.array([2.2, 2.5, 2.8, 2.4, 2.6, 2.3]),
        viscous=np.array([45.0, 50.0, 55.0, 60.0, 48.0, 52.0]),
        coulomb=np.array([4.0, 5.0, 6.0, 4.5, 5.5, 5.0]))
    return geometry.replace(name=f"{geometry.name}-lopsided", inertia=inertia, drives=drives)


def study(reps: int, configurations: tuple[tuple[float, float, float], ...] = CONFIGURATIONS,
          seed: int = 0, candidates: int = 16,
          progress: Callable[[dict[str, Any]], None] | None = None,
          constrained_fit: bool = False) -> dict[str, Any]:
    """Run the study (module docstring); returns the JSON document. ``progress`` gets the
    document so far after every configuration (e.g. to write it). The intervals are
    those of the weighted least squares; ``constrained_fit`` also solves the physically
    constrained fit where the estimate is not physical (slow: SLSQP every time the
    prior's split is not physical, as with this truth and the nominal file)."""
    nominal = preset("deltalab")
    truth = lopsided(nominal)
    basis = base_parameters(nominal, seed=seed)
    true_base = basis.of(standard_vector(truth.inertia, truth.drives))
    prior = standard_vector(nominal.inertia, nominal.drives)
    excitation = optimise(nominal, basis, seed=seed, candidates=candidates)
    records = {}
    points = []
    for resolution, noise, duration in configurations:
        if duration not in records:
            t0 = time.perf_counter()
            records[duration] = run(truth, excitation, duration)
            log.info("simulated %.0f s in %.1f s", duration, time.perf_counter() - t0)
        rec = records[duration]
        settings = Settings(duration=duration, resolution=resolution, force_noise=noise)
        z = np.full((reps, basis.size), np.nan)
        z_free = np.full((reps, basis.size), np.nan)
        est_all = np.full((reps, basis.size), np.nan)
        se_all = np.full((reps, basis.size), np.nan)
        constrained = 0
        failed = 0
        t0 = time.perf_counter()
        for r in range(reps):
            rng = np.random.default_rng([seed, r, int(resolution * 1e9), int(noise * 1e4),
                                         int(duration)])
            lengths, forces = measured(rec, settings, rng)
            try:
                s = samples(nominal, rec.time_step, lengths, forces)
                Y, _, _ = regressor(nominal, s.R, s.t, s.twist, s.acc)
                est = weighted_least_squares(basis.columns(Y), s.forces, basis, prior,
                                             nominal.inertia, nominal.drives, s.mask(),
                                             constrain=constrained_fit,
                                             q_min=nominal.stroke[0])
                log.info("repetition %d: %s", r, est.consistency[0][:40])
            except Exception as exc:  # one repetition's failure, counted
                log.warning("repetition %d failed: %s", r, exc)
                failed += 1
                continue
            constrained += int(not est.consistency[0].startswith("physically consistent"))
            est_all[r], se_all[r] = est.theta, est.se
            z[r] = (est.theta - true_base) / est.se
            assert est.unconstrained is not None
            z_free[r] = (est.unconstrained - true_base) / est.se
        ok = ~np.isnan(z[:, 0])
        cover = np.mean(np.abs(z[ok]) <= 1.96, axis=0)
        points.append({
            "encoder_resolution_um": resolution * 1e6, "force_noise_percent": noise * 100,
            "duration_s": duration, "repetitions": reps, "failed": failed,
            "constrained": constrained, "seconds": time.perf_counter() - t0,
            "coverage_95_overall": float(np.mean(np.abs(z[ok]) <= 1.96)),
            "coverage_95_overall_unconstrained": float(np.mean(np.abs(z_free[ok]) <= 1.96)),
            "within_3se_all_fraction": float(np.mean(np.all(np.abs(z[ok]) <= 3, axis=1))),
            "platform_mass_combination_rel_error_max": float(
                np.max(np.abs(est_all[ok, 0] / true_base[0] - 1))),
            "parameters": [{"name": n, "true": float(tb), "mean": float(np.mean(est_all[ok, i])),
                            "mean_se": float(np.mean(se_all[ok, i])),
                            "sd": float(np.std(est_all[ok, i], ddof=1)),
                            "rms_z": float(np.sqrt(np.mean(z[ok, i] ** 2))),
                            "coverage_95": float(cover[i]),
                            "coverage_95_unconstrained": float(
                                np.mean(np.abs(z_free[ok, i]) <= 1.96))}
                           for i, (n, tb) in enumerate(zip(basis.names, true_base, strict=True))],
        })
        log.info("point %s done", points[-1]["coverage_95_overall"])
        doc = {"truth": truth.to_dict(dynamics=True), "excitation": excitation.to_dict(),
               "points": points}
        if progress is not None:
            progress(doc)
    return doc


def markdown(doc: dict[str, Any]) -> str:
    """The study's summary table."""
    lines = ["# Identification study (Monte Carlo coverage)", "",
             "| encoder um | force noise % | excitation s | reps | coverage of the 95 % "
             "intervals (unconstrained WLS) | all within 3 SE | max rel. error m_p + 6 m_r | "
             "not physical as estimated | "
             "worst parameter (coverage, RMS z) |", "|---|---|---|---|---|---|---|---|---|"]
    for p in doc["points"]:
        worst = min(p["parameters"], key=lambda q: q["coverage_95"])
        lines.append(f"| {p['encoder_resolution_um']:g} | {p['force_noise_percent']:g} | "
                     f"{p['duration_s']:g} | {p['repetitions'] - p['failed']} | "
                     f"{p['coverage_95_overall']:.3f} "
                     f"({p['coverage_95_overall_unconstrained']:.3f}) | "
                     f"{p['within_3se_all_fraction']:.2f} | "
                     f"{p['platform_mass_combination_rel_error_max']:.4f} | "
                     f"{p['constrained']} | {worst['name']} ({worst['coverage_95']:.2f}, "
                     f"{worst['rms_z']:.2f}) |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    """``python -m benchmarks.identify.study --out DIR [--reps N]``."""
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--out", required=True)
    p.add_argument("--reps", type=int, default=50)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--overwrite", action="store_true")
    p.add_argument("--constrained", action="store_true",
                   help="also solve the physically constrained fit (slow)")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s")
    out = Path(args.out)

    def write(doc: dict[str, Any]) -> None:
        write_output(out / "study.json", doc, args.overwrite)
        write_output(out / "study.md", markdown(doc), args.overwrite)

    doc = study(args.reps, seed=args.seed, progress=write, constrained_fit=args.constrained)
    print(markdown(doc))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
