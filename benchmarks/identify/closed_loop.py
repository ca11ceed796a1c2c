"""The loop closed: computed-torque tracking with the identified model, paired against the
exact and the wrong model (``docs/identification.md``).

Three runs of the same trials (the same seed, so the same true robot, start poses and
reference) that differ only in the controllers' model (``[robot] model``): the exact
model, the identified one, the wrong one. Per trial, the RMS tracking error of the true
pose; the medians, their ratio to the exact model's, and the Wilcoxon signed-rank test of
the paired differences.

Run: ``python -m benchmarks.identify.closed_loop EXACT_DIR IDENTIFIED_DIR WRONG_DIR``.
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


def main(argv: list[str] | None = None) -> int:
    """Print the comparison as JSON."""
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("exact", type=Path)
    p.add_argument("identified", type=Path)
    p.add_argument("wrong", type=Path)
    args = p.parse_args(argv)
    print(json.dumps(compare(args.exact, args.identified, args.wrong), indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
