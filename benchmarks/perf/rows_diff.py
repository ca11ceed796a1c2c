"""Row-by-row comparison of two code trees on every built-in scenario (a refactor's check).

``run TREE OUT [ENGINE] [ONLY]`` runs every built-in scenario of ``TREE``
(``benchmarks/scenarios/*.toml``, or the comma-separated names ``ONLY``) at reduced
trial counts (3 per controller and sweep point; 1, with 60 steps, for the image
scenarios), one worker, keeping every trial's time series; ``diff OUT_A OUT_B``
compares two such runs: per scenario ``bitwise`` or the largest relative difference of
a row field and the largest absolute difference of a series, with the controllers that
differ; the rows of controllers and the scenarios only one run has are named. The
controller and detector timings are left out.

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
from collections import Counter
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
    """Print the comparison of two runs; returns the number of scenarios that differ.

    The rows both runs have are compared (a scenario's controllers that differ named);
    rows of controllers only one run has (a controller added to a scenario) are counted
    and named, and make the scenario differ; a scenario only one run has is named, not
    compared. A row field only the second run has (a new metric) is not compared."""
    differing = 0
    names_a = {os.path.basename(f.rstrip("/")) for f in glob.glob(f"{a}/*/")}
    names_b = {os.path.basename(f.rstrip("/")) for f in glob.glob(f"{b}/*/")}
    for name in sorted(names_a ^ names_b):
        print(f"{name}: only in {a if name in names_a else b} (not compared)")
    for name in sorted(names_a & names_b):
        folder_a, folder_b = f"{a}/{name}", f"{b}/{name}"
        ra, rb = _rows(folder_a), _rows(folder_b)
        both = ra.keys() & rb.keys()
        alone = [_by_controller(ra.keys() - both), _by_controller(rb.keys() - both)]
        worst = 0.0
        other: list[tuple[Any, ...]] = []
        changed: set[str] = set()
        for k in both:
            for field, x in ra[k].items():
                y = rb[k].get(field)
                if x == y:
                    continue
                changed.add(k[2])
                if isinstance(x, float) and isinstance(y, float):
                    worst = max(worst, abs(x - y) / max(1.0, abs(x)))
                else:
                    other.append((k, field, x, y))
        n_series, series_worst = _series(folder_a, folder_b, changed, other)
        status = ("bitwise" if not changed else
                  f"max relative difference of a row field {worst:.3g}, of a series "
                  f"{series_worst:.3g} (controllers {', '.join(sorted(changed))})")
        extra = "".join(f"; {n} rows only in {side}: {which}" for side, (n, which)
                        in zip((a, b), alone, strict=True) if n)
        print(f"{name}: {len(both)} rows, {n_series} series: {status}{extra}"
              + (f"; other differences: {other[:3]}" if other else ""))
        differing += 1 if changed or extra else 0
    return differing


def _series(folder_a: str, folder_b: str, changed: set[str],
            other: list[tuple[Any, ...]]) -> tuple[int, float]:
    """Compare the recorded series of the trials both folders have (a trial only one has
    is a row named by :func:`diff`), those of the first run (a series only the second
    records is a new recording, as a row field only it has): how many series, and the
    largest absolute difference; the controllers whose series differ added to ``changed``,
    what cannot be subtracted (another shape, a series the second lacks, non-numbers) to
    ``other``."""
    n_series, worst = 0, 0.0
    for fa in sorted(glob.glob(f"{folder_a}/trials/*.npz")):
        fb = fa.replace(folder_a, folder_b)
        if not os.path.exists(fb):
            continue
        za, zb = np.load(fa), np.load(fb)
        controller = str(za["controller"]) if "controller" in za.files else "?"
        for key in za.files:
            if "time" in key:
                continue
            n_series += 1
            if key not in zb.files:
                changed.add(controller)
                other.append((fa, key, "not in", fb))
                continue
            xa, xb = za[key], zb[key]
            if xa.shape != xb.shape:
                changed.add(controller)
                other.append((fa, key, xa.shape, xb.shape))
            elif not np.array_equal(xa, xb, equal_nan=xa.dtype.kind in "fc"):
                changed.add(controller)
                if xa.dtype.kind in "fc":
                    worst = max(worst, float(np.nanmax(np.abs(xa - xb))))
                else:
                    other.append((fa, key, "differs", ""))
    return n_series, worst


def _by_controller(keys: set[tuple[Any, ...]]) -> tuple[int, str]:
    """How many row keys, and their controllers with their counts (``"a (3), b (1)"``)."""
    counts = Counter(str(k[2]) for k in keys)
    return len(keys), ", ".join(f"{c} ({n})" for c, n in sorted(counts.items()))


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
