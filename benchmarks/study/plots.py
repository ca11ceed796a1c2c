"""The report's figures (PNG, matplotlib's Agg backend): error versus time of a recorded
trial, sweeps along one axis, convergence maps over two axes, and the distribution of the
final errors per controller."""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.study.metrics import Summary
from benchmarks.study.results import TRIALS_DIR
from benchmarks.study.stats import wilson_intervals
from hexapod.outputs import PNG_METADATA, inside

#: Sweep points whose recorded trial gets an error-versus-time figure, at most.
MAX_TIME_SERIES = 4


def pyplot() -> Any:
    """matplotlib.pyplot on the Agg backend (imported on first use)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(plt: Any, fig: Any, out_dir: Path, name: str) -> str:
    """Save a figure as ``out_dir/name`` (checked to stay inside, marked as the project's)
    and return its Markdown link target (``./`` before a name with ``:``, which a
    Markdown reader would take for a URL scheme)."""
    try:
        fig.savefig(inside(out_dir, name), dpi=90, metadata=PNG_METADATA)
    finally:
        plt.close(fig)
    return f"./{name}" if ":" in name else name


def representative(points: list[int]) -> list[int]:
    """At most :data:`MAX_TIME_SERIES` sweep points, spread from the first to the last."""
    if len(points) <= MAX_TIME_SERIES:
        return points
    idx = np.linspace(0, len(points) - 1, MAX_TIME_SERIES).round().astype(int)
    return [points[i] for i in sorted(set(idx.tolist()))]


def time_series(out_dir: Path, scenario: str, point: int) -> str | None:
    """Error norm and position error versus time of the recorded trial 0 of each controller."""
    files = sorted((out_dir / TRIALS_DIR).glob(f"{scenario}__p{point}__*__00000.npz"))
    if not files:
        return None
    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.5))
    for f in files:
        with np.load(f) as rec:
            label = str(rec["controller"])
            err = np.asarray(rec["error_norm"], float)
            t = np.asarray(rec["t"], float)
            ok = np.isfinite(err) & (err > 0)
            axes[0].semilogy(t[ok], err[ok], label=label)
            axes[1].semilogy(t, np.maximum(np.asarray(rec["position_error"]) * 1e3, 1e-6),
                             label=label)
    axes[0].set_title("feature error norm (trial 0)")
    axes[0].set_xlabel("time [s]")
    axes[1].set_title("position error [mm] (trial 0)")
    axes[1].set_xlabel("time [s]")
    for ax in axes:
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    name = f"{scenario}_p{point}_timeseries.png"
    return save_figure(plt, fig, out_dir, name)


def _label(s: Summary) -> str:
    return f"{s.controller} ({s.backend})" if s.backend != "sim" else s.controller


def sweeps(out_dir: Path, scenario: str, summaries: list[Summary]) -> list[str]:
    """Convergence rate and median/max final error versus the swept axis (one axis only;
    two axes get :func:`heat_maps`)."""
    axes_keys = sorted({k for s in summaries for k in s.sweep
                        if len({x.sweep.get(k) for x in summaries}) > 1})
    if len(axes_keys) != 1:
        return []
    key = axes_keys[0]
    plt = pyplot()
    fig, (a0, a1) = plt.subplots(1, 2, figsize=(10, 3.5))
    by_ctrl: dict[str, list[Summary]] = defaultdict(list)
    for s in summaries:
        by_ctrl[_label(s)].append(s)
    for ctrl, ss in by_ctrl.items():
        ss = sorted(ss, key=lambda s: s.sweep.get(key, 0))
        x = [s.sweep.get(key) for s in ss]
        a0.plot(x, [100 * s.convergence_rate for s in ss], "o-", label=ctrl)
        line, = a1.semilogy(x, [max(s.position_median_mm, 1e-6) for s in ss], "o-",
                            label=f"{ctrl} median")
        a1.semilogy(x, [max(s.position_max_mm, 1e-6) for s in ss], "x--",
                    color=line.get_color(), label=f"{ctrl} max")
    a0.set_ylabel("convergence [%]")
    a1.set_ylabel("final position error [mm]")
    for ax in (a0, a1):
        ax.set_xlabel(key)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    name = f"{scenario}_sweep_{key}.png"
    return [save_figure(plt, fig, out_dir, name)]


def heat_maps(out_dir: Path, scenario: str, summaries: list[Summary]) -> str | None:
    """Convergence rate and median final position error over two swept axes: a row of
    panels per metric, a column per controller, the values written in the cells."""
    keys = sorted({k for s in summaries for k in s.sweep
                   if len({x.sweep.get(k) for x in summaries}) > 1})
    if len(keys) != 2:
        return None
    y_key, x_key = keys
    xs = sorted({s.sweep[x_key] for s in summaries})
    ys = sorted({s.sweep[y_key] for s in summaries})
    by_ctrl: dict[str, dict[tuple[Any, Any], Summary]] = defaultdict(dict)
    for s in summaries:
        by_ctrl[_label(s)][(s.sweep[y_key], s.sweep[x_key])] = s
    ctrls = list(by_ctrl)
    plt = pyplot()
    from matplotlib.colors import LogNorm

    fig, axes = plt.subplots(2, len(ctrls), figsize=(4.2 * len(ctrls) + 1, 8.5), squeeze=False)
    errors = np.array([s.position_median_mm for s in summaries], float)
    finite = errors[np.isfinite(errors) & (errors > 0)]
    lo = max(float(finite.min()), 1e-4) if finite.size else 1e-3
    hi = max(float(finite.max()), lo * 10) if finite.size else 1.0
    norm = LogNorm(vmin=lo, vmax=hi)
    for c, ctrl in enumerate(ctrls):
        rate = np.full((len(ys), len(xs)), np.nan)
        err = np.full((len(ys), len(xs)), np.nan)
        for (yv, xv), s in by_ctrl[ctrl].items():
            rate[ys.index(yv), xs.index(xv)] = 100 * s.convergence_rate
            err[ys.index(yv), xs.index(xv)] = s.position_median_mm
        for r, (data, title) in enumerate(((rate, "converged [%]"),
                                           (err, "median final error [mm]"))):
            ax = axes[r][c]
            if r == 0:
                im = ax.imshow(data, origin="lower", cmap="viridis", vmin=0, vmax=100,
                               aspect="auto")
            else:
                im = ax.imshow(np.clip(np.nan_to_num(data, nan=hi), lo, hi), origin="lower",
                               cmap="magma_r", norm=norm, aspect="auto")
            for i in range(len(ys)):
                for j in range(len(xs)):
                    v = data[i, j]
                    text = "-" if not np.isfinite(v) else (f"{v:.0f}" if r == 0 else
                                                          f"{v:.2g}")
                    if r == 0:
                        dark = np.isfinite(v) and v < 60
                    else:
                        dark = np.isfinite(v) and v > 0 and (
                            np.log(max(v, lo)) - np.log(lo)) > 0.6 * (np.log(hi) - np.log(lo))
                    ax.text(j, i, text, ha="center", va="center", fontsize=6,
                            color="white" if dark else "black")
            ax.set_xticks(range(len(xs)), [f"{v:g}" for v in xs], fontsize=7, rotation=45)
            ax.set_yticks(range(len(ys)), [f"{v:g}" for v in ys], fontsize=7)
            ax.set_xlabel(x_key)
            ax.set_ylabel(y_key)
            ax.set_title(f"{ctrl}: {title}", fontsize=9)
            fig.colorbar(im, ax=ax, fraction=0.046)
    fig.tight_layout()
    name = f"{scenario}_map.png"
    return save_figure(plt, fig, out_dir, name)


def error_cdf(out_dir: Path, scenario: str, rows: list[dict[str, Any]]) -> str | None:
    """Success against tolerance: the fraction of the trials whose final position error
    is within each tolerance [mm] (log scale; the empirical CDF of the errors), a curve
    per controller (and backend) with its pointwise 95 % Wilson band; trials that crashed
    count as never within any tolerance."""
    by_ctrl: dict[str, list[float]] = defaultdict(list)
    totals: dict[str, int] = defaultdict(int)
    for r in rows:
        label = r["controller"] + (f" ({r['backend']})" if r.get("backend", "sim") != "sim"
                                   else "")
        totals[label] += 1
        e = r.get("final_position_error_mm")
        if e is not None and np.isfinite(e):
            by_ctrl[label].append(max(float(e), 1e-9))
    if not by_ctrl:
        return None
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.5, 4))
    for label in sorted(by_ctrl):
        e = np.sort(by_ctrl[label])
        k = np.arange(1, len(e) + 1)
        line, = ax.step(e, k / totals[label], where="post",
                        label=f"{label} ({totals[label]} trials)")
        low, high = wilson_intervals(k, totals[label])
        ax.fill_between(e, low, high, step="post", alpha=0.2,
                        color=line.get_color(), linewidth=0)
    ax.set_xscale("log")
    ax.set_ylim(0, 1.01)
    ax.set_xlabel("tolerance on the final position error [mm]")
    ax.set_ylabel("fraction of trials within")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    name = f"{scenario}_error_cdf.png"
    return save_figure(plt, fig, out_dir, name)
