"""The loop closed: computed-torque tracking with the identified model, paired against the
exact and the wrong model (``docs/identification.md``).

Three runs of the same trials (the same seed, so the same true robot, start poses and
reference) that differ only in the controllers' model (``[robot] model``): the exact
model, the identified one, the wrong one. Per trial, the RMS tracking error of the true
pose; the medians, their ratio to the exact model's, and the Wilcoxon signed-rank test of
the paired differences.

Prepare the files (the true robot of ``inertia-error``'s point with the model 30 % too
light, and the three scenarios):
``python -m benchmarks.identify.closed_loop --prepare DIR``; then, in ``DIR``,
``hexapod-bench identify deltalab --truth deltalab-heavy.toml --out ident``, run the three
scenarios (``hexapod-bench run inertia-error-exact.toml --trials 200 --out run-exact``,
and ``-identified``, ``-wrong``) and compare:
``python -m benchmarks.identify.closed_loop run-exact run-identified run-wrong``.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np
import scipy.stats

METRIC = "tracking_rms_position_mm"


def per_trial(run_dir: Path, controller: str = "computed-torque") -> dict[int, float]:
    """``trial -> METRIC`` of a run's ``results.jsonl``."""
    out = {}
    for line in (run_dir / "results.jsonl").read_text().splitlines():
        row = json.loads(line)
        if row.get("controller") == controller and row.get(METRIC) is not None:
            out[int(row["trial"])] = float(row[METRIC])
    return out


def compare(exact: Path, identified: Path, wrong: Path) -> dict[str, Any]:
    """The paired comparison (module docstring)."""
    runs = {"exact": per_trial(exact), "identified": per_trial(identified),
            "wrong": per_trial(wrong)}
    trials = sorted(set.intersection(*(set(r) for r in runs.values())))
    x = {k: np.array([r[t] for t in trials]) for k, r in runs.items()}
    out: dict[str, Any] = {"trials": len(trials), "metric": METRIC}
    for k, v in x.items():
        out[f"median_{k}_mm"] = float(np.median(v))
    out["ratio_identified_to_exact"] = out["median_identified_mm"] / out["median_exact_mm"]
    for a, b in (("identified", "exact"), ("wrong", "identified")):
        d = x[a] - x[b]
        test = scipy.stats.wilcoxon(x[a], x[b]) if np.any(d != 0) else None
        out[f"{a}_vs_{b}"] = {"median_difference_mm": float(np.median(d)),
                              "better_in": int(np.sum(d < 0)), "worse_in": int(np.sum(d > 0)),
                              "wilcoxon_p": float(test.pvalue) if test is not None else 1.0}
    return out


def prepare(out: Path, overwrite: bool = False) -> list[Path]:
    """Write ``deltalab-heavy.toml`` (the true robot of ``inertia-error`` with the model
    30 % too light in mass and inertia) and the scenarios ``inertia-error-exact.toml``,
    ``-identified.toml`` (its model ``ident/identified.toml``) and ``-wrong.toml``."""
    import tomli_w

    from benchmarks.sim.world import model_error_inertia
    from benchmarks.study.scenario import load_scenario
    from hexapod.config import load_toml
    from hexapod.geometry import preset
    from hexapod.outputs import write_output

    g = preset("deltalab")
    heavy = g.replace(name="deltalab-heavy",
                      inertia=model_error_inertia(g.inertia, -30.0, -30.0))
    written = [write_output(out / "deltalab-heavy.toml",
                            tomli_w.dumps(heavy.to_dict(dynamics=True)), overwrite)]
    base = load_toml(Path(str(load_scenario("inertia-error").source)))
    for variant, model in (("exact", "deltalab-heavy.toml"),
                           ("identified", "ident/identified.toml"), ("wrong", None)):
        table = dict(base)
        table["name"] = f"inertia-error-{variant}"
        table["description"] = (f"inertia-error's point with the model 30 % too light in mass "
                                f"and inertia (the truth: deltalab-heavy), computed torque "
                                f"with the {variant} model (docs/identification.md)")
        table["controllers"] = ["computed-torque"]
        table["robot"] = dict(base["robot"], **({"model": model} if model else {}))
        table["calibration_error"] = {"model_mass_error_percent": -30.0,
                                      "model_inertia_error_percent": -30.0}
        written.append(write_output(out / f"inertia-error-{variant}.toml",
                                    tomli_w.dumps(table), overwrite))
    return written


def main(argv: list[str] | None = None) -> int:
    """Print the comparison as JSON, or ``--prepare DIR`` the files."""
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("runs", type=Path, nargs="*", metavar="RUN_DIR",
                   help="the exact, identified and wrong runs")
    p.add_argument("--prepare", type=Path, metavar="DIR")
    p.add_argument("--overwrite", action="store_true")
    args = p.parse_args(argv)
    if args.prepare is not None:
        for path in prepare(args.prepare, args.overwrite):
            print(f"wrote {path}")
        return 0
    if len(args.runs) != 3:
        p.error("give the three run folders: exact, identified, wrong")
    print(json.dumps(compare(*args.runs), indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
