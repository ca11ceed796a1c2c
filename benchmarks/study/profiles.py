"""Dolan-Moré performance profiles of the controllers of a run.

E. D. Dolan and J. J. Moré, "Benchmarking optimization software with performance
profiles", Mathematical Programming 91(2), 2002. For a cost ``t[p, s]`` of controller
``s`` on problem ``p`` (here a trial: one start/goal pair of one sweep point, which
every controller of a run meets), the ratio ``r[p, s] = t[p, s] / min_s t[p, s]``
compares ``s`` with the best controller on that trial, and the profile
``rho_s(tau) = #{p : r[p, s] <= tau} / #problems`` is the fraction of trials on which
``s`` is within a factor ``tau`` of the best. ``rho_s(1)`` is how often ``s`` is the
best; ``rho_s`` at large ``tau`` is how often it succeeds at all (a failure has an
infinite ratio). The curve highest on the left wins most often, the one highest on
the right is the most robust.
"""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

#: Costs below this are raised to it (a final error of 1e-13 mm is as good as 0).
FLOOR = {"steps": 1.0, "final_position_error_mm": 1e-6}
STYLES = ("-", "--", ":", "-.")


def ratios(costs: np.ndarray) -> np.ndarray:
    """Performance ratios of a (problems x controllers) cost array.

    ``inf`` or ``nan`` costs are failures (ratio ``inf``); a problem where every
    controller failed has every ratio ``inf``.
    """
    t = np.where(np.isfinite(costs), costs, np.inf).astype(float)
    best = t.min(axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        r = t / best
    r[~np.isfinite(t)] = np.inf
    r[~np.isfinite(best[:, 0])] = np.inf
    return r


def profile(r: np.ndarray, taus: np.ndarray) -> np.ndarray:
    """``rho[s, i]``: fraction of problems with ``r[p, s] <= taus[i]``."""
    if r.shape[0] == 0:
        return np.zeros((r.shape[1], taus.size))
    return np.stack([(r[:, [s]] <= taus[None, :]).mean(axis=0) for s in range(r.shape[1])])


def cost_table(rows: list[dict[str, Any]], metric: str
               ) -> tuple[list[str], np.ndarray]:
    """Controllers and a (trials x controllers) cost array on the trials every
    controller ran. ``steps``: steps to converge, a failure when not converged;
    ``final_position_error_mm``: the final error, a failure when missing (crash)."""
    by_key: dict[tuple[str, int, str, int], dict[str, float]] = defaultdict(dict)
    ctrls: list[str] = []
    floor = FLOOR.get(metric, 0.0)
    for r in rows:
        label = r["controller"] + (f" ({r['backend']})" if r.get("backend", "sim") != "sim"
                                   else "")
        if label not in ctrls:
            ctrls.append(label)
        v = r.get(metric)
        if metric == "steps" and not r.get("converged"):
            v = None
        cost = float("inf") if v is None or not np.isfinite(v) else max(float(v), floor)
        by_key[(r["scenario"], int(r.get("point", 0)), "", int(r["trial"]))][label] = cost
    ctrls.sort()
    full = [v for v in by_key.values() if len(v) == len(ctrls)]
    costs = np.array([[v[c] for c in ctrls] for v in full], float).reshape(-1, len(ctrls))
    return ctrls, costs


def plot_profiles(out_dir: Path, scenario: str, rows: list[dict[str, Any]]) -> str | None:
    """PNG of the profiles of steps to converge and of the final position error of a
    scenario's controllers (None with fewer than two controllers)."""
    panels = []
    for metric, title in (("steps", "steps to converge (failure: not converged)"),
                          ("final_position_error_mm", "final position error")):
        ctrls, costs = cost_table(rows, metric)
        if len(ctrls) < 2 or costs.shape[0] == 0:
            return None
        panels.append((title, ctrls, ratios(costs)))
    from benchmarks.study.plots import (
        LABELLED_TITLED_PANELS,
        figure,
        plain_log_labels,
        save_figure,
    )

    fig = figure((11, 3.8))
    axes = fig.subplots(1, 2)
    for ax, (title, ctrls, r) in zip(axes, panels, strict=True):
        finite = r[np.isfinite(r)]
        top = max(2.0, float(finite.max()) * 1.05) if finite.size else 2.0
        taus = np.unique(np.concatenate([np.geomspace(1, top, 400), finite, [1.0]]))
        rho = profile(r, taus)
        for s, c in enumerate(ctrls):  # line styles keep coinciding curves visible
            ax.step(taus, rho[s], where="post", label=c, linestyle=STYLES[s % len(STYLES)],
                    linewidth=2.2 - 0.3 * (s % 4))
        ax.set_xscale("log", base=2)
        plain_log_labels(ax.xaxis, base=2)
        ax.set_xlim(1, top)
        ax.set_ylim(0, 1.02)
        ax.set_xlabel("tau (ratio to the best controller on the trial)")
        ax.set_ylabel("fraction of trials within tau")
        ax.set_title(f"{title}, {r.shape[0]} trials", fontsize=9, y=1.0)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7, loc="lower right")
    return save_figure(fig, out_dir, f"{scenario}_profiles.png", LABELLED_TITLED_PANELS)


def profile_note(n_ctrls: int) -> str:
    """The report's sentence above the figure."""
    return (f"Performance profiles (Dolan and Moré, Math. Programming 2002) of the {n_ctrls} "
            "controllers, every trial of every sweep point a problem: the fraction of "
            "trials on which a controller is within a factor tau of the best one on that "
            "trial. At tau = 1: how often it is the best; on the right: how often it "
            "succeeds at all.")
