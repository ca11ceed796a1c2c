"""What a saturation strategy changes: each labelled variant of a computed-torque law
against the law's default (``saturation = "clip"``), paired on the same trials.

A variant is a controller labelled ``LAW+STRATEGY`` (``computed-torque+scale``,
``leg-edge-ctc+qp``, as in ``benchmarks/scenarios/payload-saturation.toml``) beside the
plain ``LAW`` in the same run. At each payload where either saturated, the median paired
difference variant - clip of the RMS position error from the reference [mm] with its 95 %
interval and Wilcoxon's signed-rank p, Holm-adjusted over every comparison printed (the
report's own :mod:`benchmarks.study.stats`); trials that failed in either are left out,
and a pair with fewer than :data:`MIN_PAIRS` trials left is named, not tested.

Run: ``python -m benchmarks.perf.saturation_pairs DIR/results.jsonl``.
"""

from __future__ import annotations

import json
import sys
from typing import Any

from benchmarks.study import exact, stats
from benchmarks.study.failures import is_failure

#: The strategies that label a variant.
STRATEGIES = ("scale", "qp")
#: The fewest paired trials a comparison is tested on.
MIN_PAIRS = 6


def _errors(rows: list[dict[str, Any]]) -> dict[int, float]:
    """RMS position error [mm] of each trial that ran to its end, by trial index."""
    return {int(r["trial"]): float(r["tracking_rms_position_mm"]) for r in rows
            if not is_failure(r) and r.get("tracking_rms_position_mm") is not None}


def _saturated(rows: list[dict[str, Any]]) -> bool:
    return any((r.get("saturation_time_s") or 0) > 0 for r in rows if not is_failure(r))


def comparisons(rows: list[dict[str, Any]]) -> list[str]:
    """One line per (variant, payload) where the law or its variant saturated (the
    tested ones first, then those with too few paired trials)."""
    groups: dict[tuple[str, float], list[dict[str, Any]]] = {}
    for r in rows:
        groups.setdefault((str(r["controller"]), float(r.get("payload_mass_kg", 0.0))),
                          []).append(r)
    found, few = [], []
    for (name, mass), variant in sorted(groups.items()):
        law, _, strategy = name.rpartition("+")
        if strategy not in STRATEGIES or (law, mass) not in groups:
            continue
        clip = groups[(law, mass)]
        if not (_saturated(clip) or _saturated(variant)):
            continue
        a, b = _errors(clip), _errors(variant)
        trials = sorted(set(a) & set(b))
        if len(trials) < MIN_PAIRS:
            few.append(f"{mass:g} kg {name} - {law}: {len(trials)} paired trials ran to their "
                       f"end, fewer than {MIN_PAIRS}: not tested")
            continue
        test = stats.wilcoxon_signed_rank([b[k] for k in trials], [a[k] for k in trials])
        found.append((mass, name, law, len(trials), test))
    adjusted = stats.holm([t.p_value for *_, t in found])
    return [f"{mass:g} kg {name} - {law}: {t.difference:+.3g} mm [{t.low:.3g}, {t.high:.3g}]"
            f", {n} trials, Holm p {exact.format_p(p)}"
            for (mass, name, law, n, t), p in zip(found, adjusted, strict=True)] + few


def main(argv: list[str] | None = None) -> int:
    """``RESULTS_JSONL``: print the comparisons."""
    args = sys.argv[1:] if argv is None else argv
    if args in (["-h"], ["--help"]):
        print(__doc__)
        return 0
    if len(args) != 1:
        print(__doc__)
        return 2
    with open(args[0]) as f:
        rows = [json.loads(line) for line in f if line.strip()]
    lines = comparisons(rows)
    print("\n".join(lines) if lines else "no saturated variant beside its law")
    return 0


if __name__ == "__main__":
    sys.exit(main())
