"""The report's sections on the drives' force limits, for the scenarios with a
``[payload]`` (their rows carry :data:`benchmarks.sim.dynamic_plant.SATURATION_COLUMNS`
and the tracking error while saturated, :mod:`benchmarks.sim.tracking`):

- the saturation table, beside the tracking table: per sweep point and controller, the
  trials that reached a force limit, the fraction of the run any drive spent there, the
  most saturated leg, and the position error while saturated;
- with ``payload.mass_kg`` swept, where each controller stops tracking: per payload, its
  median RMS position error with its interval, and its paired change from the lightest
  payload (the same trials: the worlds and start poses are paired across the sweep) with
  Wilcoxon's signed-rank test, Holm-adjusted over the controller's payloads; it *stops
  tracking* at the first payload where more than half its trials fail, or where its error
  is significantly larger (adjusted p < 0.05) and its median increase is at least the
  median error at the lightest payload (the error at least doubled);
- who tracks best at each payload: the controller with the lowest median RMS position
  error, against each other one in a paired Wilcoxon test, Holm-adjusted over the
  comparisons of that payload (the lowest median need not be the lowest in the pairs:
  a controller with a negative median paired difference is named beside it, and one
  significantly lower in the pairs "tracks better in the pairs"); a controller most of
  whose trials failed at a payload is
  listed as failing there and not compared (its few surviving trials are not a sample
  of its trials).

The failed trials (an end stop, a diverged world) are counted and left out of the error
figures (those of the trials that ran to their end), as in the tracking table.
"""

from __future__ import annotations

from collections import defaultdict
from typing import Any

import numpy as np

from benchmarks.study import exact, intervals, stats
from benchmarks.study.metrics import format_sweep, sweep_values

#: Columns of the saturation table.
SATURATION_HEADER = ["sweep", "controller", "trials", "at a limit", "at limit % (median)",
                     "at limit % (worst)", "most saturated leg", "its % (median)",
                     "error saturated mm (median RMS)", "error saturated mm (worst)"]
#: The payload's sweep key in the rows.
MASS_KEY = "payload_mass_kg"
#: Family-wise level of the paired tests.
ALPHA = 0.05


def has_saturation(rows: list[dict[str, Any]]) -> bool:
    """Whether the rows carry the per-leg saturation (a scenario with a payload)."""
    return any("saturation_legs_s" in r for r in rows)


def _ran(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    from benchmarks.study.failures import is_failure

    return [r for r in rows if not is_failure(r)]


def _fmt(x: float) -> str:
    return "-" if not np.isfinite(x) else f"{x:.3g}"


def _groups(rows: list[dict[str, Any]]) -> dict[tuple[int, str], list[dict[str, Any]]]:
    groups: dict[tuple[int, str], list[dict[str, Any]]] = defaultdict(list)
    for r in rows:
        groups[(int(r.get("point", 0)), str(r["controller"]))].append(r)
    return groups


def saturation_rows(rows: list[dict[str, Any]]) -> list[list[str]]:
    """The saturation table's rows (:data:`SATURATION_HEADER`), one per (sweep point,
    controller)."""
    out = []
    for (_, controller), every in sorted(_groups(rows).items()):
        rs = [r for r in _ran(every) if r.get("saturation_legs_s") is not None]
        hit = sum(1 for r in rs if (r.get("saturation_time_s") or 0) > 0)
        frac = [100 * r["saturation_fraction"] for r in rs
                if r.get("saturation_fraction") is not None]
        legs = np.array([[np.nan if x is None else x for x in r["saturation_legs_fraction"]]
                         for r in rs], dtype=float).reshape(-1, 6)
        if legs.size and np.nansum(legs) > 0:
            leg = int(np.argmax(np.nanmean(legs, axis=0)))  # (the largest mean time)
            leg_cells = [str(leg), intervals.quantile_cells(list(100 * legs[:, leg]), [0.5])[0]]
        else:
            leg_cells = ["-", "-"]
        sat_rms = [r["tracking_saturated_rms_mm"] for r in rs
                   if r.get("tracking_saturated_rms_mm") is not None]
        sat_max = [r["tracking_saturated_max_mm"] for r in rs
                   if r.get("tracking_saturated_max_mm") is not None]
        out.append([
            format_sweep(sweep_values(every[0])), controller, str(len(every)),
            f"{hit}/{len(rs)}, {stats.format_rate(hit, len(rs))}" if rs else "-",
            intervals.quantile_cells(frac, [0.5])[0] if frac else "-",
            _fmt(max(frac)) if frac else "-", *leg_cells,
            intervals.quantile_cells(sat_rms, [0.5])[0] if sat_rms else "-",
            _fmt(max(sat_max)) if sat_max else "-"])
    return out


def _errors(rows: list[dict[str, Any]]) -> dict[int, float]:
    """RMS position error [mm] of each trial that ran to its end, by trial index."""
    return {int(r["trial"]): float(r["tracking_rms_position_mm"]) for r in _ran(rows)
            if r.get("tracking_rms_position_mm") is not None}


def _paired(a: dict[int, float], b: dict[int, float]) -> tuple[np.ndarray, np.ndarray]:
    trials = sorted(set(a) & set(b))
    return (np.array([a[k] for k in trials], dtype=float),
            np.array([b[k] for k in trials], dtype=float))


def _by_mass(rows: list[dict[str, Any]]) -> dict[float, dict[str, list[dict[str, Any]]]]:
    """The rows by payload mass [kg], then by controller (the other swept keys, if any,
    must be fixed: one table per value of them is not built)."""
    out: dict[float, dict[str, list[dict[str, Any]]]] = defaultdict(lambda: defaultdict(list))
    for r in rows:
        out[float(r[MASS_KEY])][str(r["controller"])].append(r)
    return out


def stop_lines(rows: list[dict[str, Any]]) -> list[str]:
    """Where each controller stops tracking (module docstring), as Markdown lines."""
    masses = _by_mass(rows)
    keys = sorted(masses)
    controllers = sorted({c for m in masses.values() for c in m})
    header = ["controller", *[f"{m:g} kg" for m in keys], "stops tracking at"]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for c in controllers:
        base_rows = masses[keys[0]].get(c, [])
        base = _errors(base_rows)
        base_med = float(np.median(list(base.values()))) if base else float("nan")
        tests: list[stats.TestResult | None] = []
        cells: list[list[str]] = []
        failing: list[bool] = []
        for m in keys:
            every = masses[m].get(c, [])
            errs = _errors(every)
            failing.append(len(every) - len(_ran(every)) > len(every) / 2 if every else False)
            if m == keys[0] or not errs:
                tests.append(None)
            else:
                tests.append(stats.wilcoxon_signed_rank(*_paired(errs, base)))
            vals = list(errs.values())
            med = intervals.quantile_cells(vals, [0.5])[0] if vals else "-"
            cells.append([med, f"{len(every) - len(_ran(every))}/{len(every)} failed"
                          if len(_ran(every)) < len(every) else ""])
        adjusted = stats.holm([t.p_value if t is not None else float("nan") for t in tests])
        stop = ""
        for k, m in enumerate(keys):
            t = tests[k]
            if t is not None:
                cells[k].append(f"{t.difference:+.3g} [{t.low:.3g}, {t.high:.3g}] "
                                f"p {exact.format_p(adjusted[k])}")
            if stop:
                continue
            if failing[k]:
                stop = f"{m:g} kg (most trials fail)"
            elif (t is not None and adjusted[k] < ALPHA and t.difference > 0
                  and not t.interval_disagrees and t.difference >= base_med):
                stop = (f"{m:g} kg (error {t.difference:+.3g} mm, "
                        f"x{(base_med + t.difference) / base_med:.2g})")
        stop = stop or "not within the sweep"
        lines.append("| " + " | ".join([c, *["; ".join(x for x in cell if x) for cell in cells],
                                        stop]) + " |")
    return lines


def best_lines(rows: list[dict[str, Any]]) -> list[str]:
    """Who tracks best at each payload (module docstring), as Markdown lines."""
    masses = _by_mass(rows)
    lines = ["| payload | lowest median (RMS mm) | against | median difference mm "
             "[95 % interval] | Holm p | verdict |", "|---|---|---|---|---|---|"]
    for m in sorted(masses):
        errs = {c: _errors(rs) for c, rs in masses[m].items()}
        # a controller most of whose trials failed is not compared (its survivors are not
        # its trials): it is listed as failing
        failing = sorted(c for c, rs in masses[m].items() if len(errs[c]) <= len(rs) / 2)
        meds = {c: float(np.median(list(e.values()))) for c, e in errs.items()
                if e and c not in failing}
        fails = ", ".join(f"{c} ({len(masses[m][c]) - len(errs[c])}/{len(masses[m][c])} "
                          "failed)" for c in failing)
        if fails:
            lines.append(f"| {m:g} kg | - | most trials fail: {fails} | | | |")
        if not meds:
            continue
        best = min(meds, key=lambda c: meds[c])
        others = [c for c in sorted(meds) if c != best]
        tests = [stats.wilcoxon_signed_rank(*_paired(errs[c], errs[best])) for c in others]
        adjusted = stats.holm([t.p_value for t in tests])
        if not others:
            lines.append(f"| {m:g} kg | {best} ({meds[best]:.3g}) | - | | | |")
        # the lowest median need not be the lowest in the pairs: said where another is
        lower = [c for c, t in zip(others, tests, strict=True) if t.difference < 0]
        head = f"{best} ({meds[best]:.3g})" + (
            f"; lower in the pairs: {', '.join(lower)}" if lower else "")
        for c, t, p in zip(others, tests, adjusted, strict=True):
            clear = p < ALPHA and not t.interval_disagrees
            verdict = ("best tracks better" if clear and t.difference > 0
                       else f"{c} tracks better in the pairs" if clear and t.difference < 0
                       else "no significant difference" if p >= ALPHA else "mixed")
            lines.append(f"| {m:g} kg | {head} | {c} ({meds[c]:.3g}) | "
                         f"{t.difference:+.3g} [{t.low:.3g}, {t.high:.3g}] | "
                         f"{exact.format_p(p)} | {verdict} |")
    return lines


def saturation_section(rows: list[dict[str, Any]]) -> list[str]:
    """The Markdown lines of the saturation sections (none without per-leg saturation)."""
    if not has_saturation(rows):
        return []
    header = SATURATION_HEADER
    lines = ["Saturation (the drives' force limits; *at a limit*: trials in which a drive "
             "reached its force limit, of those run to their end (a failed trial is in "
             "*trials*, not here), with its Wilson interval; *at limit %*: fraction of "
             "the run any drive spent there; *most saturated leg*: the leg with the largest "
             "mean time at its limit (and its median); *error saturated*: position error from the "
             "reference at the end of the control periods in which a drive was at its "
             "limit, over the trials that saturated; medians with their 95 % intervals):",
             "", "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(r) + " |" for r in saturation_rows(rows)]
    lines.append("")
    if any(MASS_KEY in r for r in rows) and len({r.get(MASS_KEY) for r in rows}) > 1:
        lines += ["Where each controller stops tracking (median RMS position error [mm] "
                  "with its 95 % interval per payload; from the second payload on, its "
                  "median paired change from the lightest payload [mm] with its interval "
                  "and Wilcoxon's signed-rank p, Holm-adjusted over the controller's "
                  "payloads; *stops tracking*: the first payload where most trials fail, "
                  "or where the error is significantly larger and at least doubled):", ""]
        lines += [*stop_lines(rows), ""]
        lines += ["Who tracks best at each payload (the lowest median RMS position error, "
                  "against each other controller: median paired difference other - lowest "
                  "[mm] with its 95 % interval, Wilcoxon's signed-rank p Holm-adjusted over "
                  "the comparisons of the payload; a controller lower than it in the pairs "
                  "is named beside it; trials that failed left out):", ""]
        lines += [*best_lines(rows), ""]
    return lines
