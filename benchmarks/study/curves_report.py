"""The report's censored-data and tolerance sections: time to converge (Kaplan-Meier
medians, log-rank tests, the curves) and success against the tolerance (a table at a
few tolerances; the curve is :func:`benchmarks.study.plots.error_cdf`)."""

from __future__ import annotations

import itertools
import math
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.study import stats, survival
from benchmarks.study.exact import format_p
from benchmarks.study.metrics import format_sweep
from benchmarks.study.plots import LABELLED_TITLED_PANELS, figure, save_figure


def _md_table(header: list[str], rows: list[list[str]]) -> str:
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    return "\n".join(out + ["| " + " | ".join(r) + " |" for r in rows])


def _steps(x: float, cap: float) -> str:
    if x == np.inf:
        return f"> {cap:.0f}" if np.isfinite(cap) else "> run"
    return "-" if np.isnan(x) else f"{x:.0f}"


def _by_point(rows: list[dict[str, Any]]) -> dict[int, dict[str, list[dict[str, Any]]]]:
    out: dict[int, dict[str, list[dict[str, Any]]]] = defaultdict(lambda: defaultdict(list))
    for r in rows:
        label = r["controller"] + (f" ({r['backend']})" if r.get("backend", "sim") != "sim"
                                   else "")
        out[int(r.get("point", 0))][label].append(r)
    return out


def time_to_converge_section(out_dir: Path, scenario: str, rows: list[dict[str, Any]],
                             sweeps: dict[int, dict[str, Any]], plot_points: list[int]
                             ) -> list[str]:
    """``Time to converge`` (markdown lines): per sweep point and controller the
    Kaplan-Meier median steps with its interval; between the controllers of a point the
    log-rank test, Holm-corrected over the section; the curves of ``plot_points``."""
    groups = _by_point([r for r in rows if "converged" in r and "steps" in r])
    if not groups:
        return []
    table, tests = [], []
    kms: dict[int, dict[str, survival.TimeToConverge]] = defaultdict(dict)
    for p in sorted(groups):
        run = stats.run_length([r for rs in groups[p].values() for r in rs])
        for label, rs in sorted(groups[p].items()):
            km = kms[p][label] = survival.time_to_converge(rs, run=run)
            table.append([format_sweep(sweeps.get(p, {})), label, str(km.trials),
                          str(km.converged), f"{_steps(km.median, km.cap)} "
                          f"[{_steps(km.low, km.cap)}, {_steps(km.high, km.cap)}]"])
        for a, b in itertools.combinations(sorted(groups[p]), 2):
            tests.append((p, a, b, survival.logrank_p(groups[p][a], groups[p][b], run)))
    lines = ["### Time to converge", "",
             "Steps to converge as censored data: a trial that did not converge (failed "
             "ones included) is known only to need more than the run's steps. Kaplan-Meier "
             "median with its 95 % interval (log-log band); `> N`: beyond the N steps run "
             "(half the trials, or the interval's end, did not converge within the run).",
             "", _md_table(["sweep", "controller", "trials", "converged",
                            "median steps [95 % CI]"], table), ""]
    if tests:
        adjusted = stats.holm([t[3] for t in tests])
        lines += ["Log-rank tests of the steps to converge between controllers (Holm's "
                  "correction over the table; the trials are paired, which the log-rank "
                  "test ignores: `hexapod-bench compare` has the paired sign test):", "",
                  _md_table(["sweep", "a", "b", "log-rank p", "Holm p"],
                            [[format_sweep(sweeps.get(p, {})), a, b, format_p(pv),
                              format_p(ph)] for (p, a, b, pv), ph
                             in zip(tests, adjusted, strict=True)]), ""]
    img = _km_plot(out_dir, scenario, kms, [p for p in plot_points if p in groups], sweeps)
    if img:
        lines += ["Fraction of the trials converged against steps (1 - Kaplan-Meier "
                  "survival), per controller:", "", f"![time to converge]({img})", ""]
    return lines


def _km_plot(out_dir: Path, scenario: str,
             kms: dict[int, dict[str, survival.TimeToConverge]], points: list[int],
             sweeps: dict[int, dict[str, Any]]) -> str | None:
    if not points:
        return None
    fig = figure((5 * len(points), 3.6))
    axes = fig.subplots(1, len(points), squeeze=False)
    for ax, p in zip(axes[0], points, strict=True):
        drawn = 0
        for label, km in sorted(kms[p].items()):
            if km.steps.size:
                x, y = np.r_[0, km.steps], np.r_[0, km.converged_fraction]
            elif km.trials and math.isfinite(km.cap):  # none converged: zero to the end
                x, y = np.array([0.0, km.cap]), np.zeros(2)
            else:
                continue
            ax.step(x, y, where="post", label=f"{label} ({km.converged}/{km.trials})")
            drawn += 1
        ax.set_ylim(0, 1.01)
        ax.set_xlabel("steps")
        ax.set_ylabel("fraction converged")
        ax.set_title(format_sweep(sweeps.get(p, {})), fontsize=8, y=1.0)
        ax.grid(True, alpha=0.3)
        if drawn:
            ax.legend(fontsize=7)
        else:  # (no trial, or none converged in a run of unknown length)
            ax.text(0.5, 0.5, "no curve to draw", transform=ax.transAxes,
                    ha="center", va="center", fontsize=8)
    return save_figure(fig, out_dir, f"{scenario}_time_to_converge.png",
                       LABELLED_TITLED_PANELS)


def tolerance_section(rows: list[dict[str, Any]], sweeps: dict[int, dict[str, Any]]
                      ) -> list[str]:
    """``Success against tolerance`` (markdown lines): per sweep point and controller the
    fraction of the trials whose final position error is within each of
    :data:`benchmarks.study.survival.TOLERANCES_MM`, with its Wilson interval."""
    groups = _by_point([r for r in rows if "final_position_error_mm" in r])
    if not groups:
        return []
    table = []
    for p in sorted(groups):
        for label, rs in sorted(groups[p].items()):
            frac, _, _ = survival.tolerance_curve(rs, np.array(survival.TOLERANCES_MM))
            cells = [stats.format_rate(round(f * len(rs)), len(rs)) for f in frac]
            table.append([format_sweep(sweeps.get(p, {})), label, *cells])
    return ["### Success against tolerance", "",
            "Fraction of the trials whose final position error is within each tolerance "
            "(failed trials count as not within), with Wilson intervals: a verdict does not "
            "hang on one cutoff near the medians. The curve over every tolerance is the "
            "figure of the final errors below.", "",
            _md_table(["sweep", "controller",
                       *(f"<= {t:g} mm" for t in survival.TOLERANCES_MM)], table), ""]
