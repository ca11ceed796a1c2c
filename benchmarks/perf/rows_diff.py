"""Row-by-row comparison of two code trees on every built-in scenario (a refactor's check).

``run TREE OUT [ENGINE] [ONLY]`` runs every built-in scenario of ``TREE``
(``benchmarks/scenarios/*.toml``, or the comma-separated names ``ONLY``) at reduced
trial counts (3 per controller and sweep point; 1, with 60 steps, for the image
scenarios), one worker, keeping every trial's time series; ``diff OUT_A OUT_B``
compares two such runs: per scenario ``bitwise`` or the largest relative difference of
a row field and the largest absolute difference of a series. The controller and
detector timings are left out.

Run: ``python -m benchmarks.perf.rows_diff run /path/to/old /tmp/rows/old`` (a second
tree from ``git worktree add /path/to/old REV``), the same for the new tree, then
``python -m benchmarks.perf.rows_diff diff /tmp/rows/old /tmp/rows/new``.
"""

from __future__ import annotations

import glob
import json
import os
import sys
import time
from typing import Any

import numpy as np

from benchmarks.perf import cli_in_tree

#: Scenarios that render images (slow): one trial of 60 steps.
IMAGE = {"andreff2006-images", "andreff2006-images-distorted", "tahri2009-images"}
#: Row fields that are timings, not results.
TIMING = {"step_time_us", "detect_time_ms"}


def run(tree: str, out: str, engine: str = "batched", only: str = "") -> None:
    """Run the scenarios of ``tree`` into ``out/NAME`` (see the module docstring; both
    paths from the working directory: the runs read theirs from the tree)."""
    tree, out = os.path.abspath(tree), os.path.abspath(out)
    os.makedirs(out, exist_ok=True)
    for path in sorted(glob.glob(f"{tree}/benchmarks/scenarios/*.toml")):
        name = os.path.basename(path)[:-5]
        if only and name not in only.split(","):
            continue
        trials = 1 if name in IMAGE else 3
        cmd = ["run", path, "--out", f"{out}/{name}", "--workers", "1", "--trials",
               str(trials), "--no-progress", "--record", str(trials), "--engine", engine]
        if name in IMAGE:
            cmd += ["--max-steps", "60"]
        start = time.time()
        proc = cli_in_tree(tree, cmd)
        print(f"{name}: rc={proc.returncode} {time.time() - start:.0f}s", flush=True)
        if proc.returncode:
            print(proc.stderr[-2000:], flush=True)


def _rows(folder: str) -> dict[tuple[Any, ...], dict[str, Any]]:
    out = {}
    with open(f"{folder}/results.jsonl") as f:
        for line in f:
            r = json.loads(line)
            key = (r["scenario"], r["point"], r["controller"], r["trial"])
            out[key] = {k: v for k, v in r.items() if k not in TIMING}
    return out


def diff(a: str, b: str) -> int:
    """Print the comparison of two runs; returns the number of scenarios that differ."""
    differing = 0
    for folder_a in sorted(glob.glob(f"{a}/*/")):
        name = os.path.basename(folder_a.rstrip("/"))
        folder_b = f"{b}/{name}"
        ra, rb = _rows(folder_a), _rows(folder_b)
        if ra.keys() != rb.keys():
            print(f"{name}: different rows ({len(ra)} against {len(rb)})")
            differing += 1
            continue
        worst, series_worst, exact = 0.0, 0.0, True
        other: list[tuple[Any, ...]] = []
        for k, row in ra.items():
            for field, x in row.items():
                y = rb[k].get(field)
                if x == y:
                    continue
                exact = False
                if isinstance(x, float) and isinstance(y, float):
                    worst = max(worst, abs(x - y) / max(1.0, abs(x)))
                else:
                    other.append((k, field, x, y))
        n_series = 0
        for fa in sorted(glob.glob(f"{folder_a}/trials/*.npz")):
            za = np.load(fa)
            zb = np.load(fa.replace(folder_a.rstrip("/"), folder_b))
            for key in za.files:
                if "time" in key:
                    continue
                n_series += 1
                xa, xb = za[key], zb[key]
                if xa.shape != xb.shape:
                    exact = False
                    other.append((fa, key, xa.shape, xb.shape))
                elif not np.array_equal(xa, xb, equal_nan=xa.dtype.kind in "fc"):
                    exact = False
                    if xa.dtype.kind in "fc":
                        series_worst = max(series_worst, float(np.nanmax(np.abs(xa - xb))))
                    else:
                        other.append((fa, key, "differs", ""))
        status = ("bitwise" if exact else f"max relative difference of a row field {worst:.3g}"
                  f", of a series {series_worst:.3g}")
        print(f"{name}: {len(ra)} rows, {n_series} series: {status}"
              + (f"; other differences: {other[:3]}" if other else ""))
        differing += 0 if exact else 1
    return differing


def main(argv: list[str] | None = None) -> int:
    """``run TREE OUT [ENGINE] [ONLY]`` or ``diff OUT_A OUT_B``."""
    args = sys.argv[1:] if argv is None else argv
    if len(args) >= 3 and args[0] == "run":
        run(*args[1:5])
        return 0
    if len(args) == 3 and args[0] == "diff":
        return 1 if diff(args[1], args[2]) else 0
    print(__doc__)
    return 2


if __name__ == "__main__":
    sys.exit(main())
