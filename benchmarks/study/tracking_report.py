"""The report's section on trajectory tasks: the tracking metrics of every controller at
every sweep point (:mod:`benchmarks.sim.tracking`), and the tracking error against time
of the recorded trial."""

from __future__ import annotations

import logging
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.study.metrics import format_sweep, sweep_values

log = logging.getLogger(__name__)

TRIALS_DIR = "trials"
#: Columns of the tracking table.
HEADER = ["sweep", "controller", "trials", "RMS mm (median)", "RMS mm (p95)",
          "max mm (median)", "max mm (worst)", "RMS deg (median)", "settled",
          "settling s (median)"]


def _stat(values: list[Any], how: str) -> float:
    arr = np.array([v for v in values if v is not None], dtype=float)
    if arr.size == 0:
        return float("nan")
    if how == "median":
        return float(np.median(arr))
    if how == "p95":
        return float(np.percentile(arr, 95))
    return float(np.max(arr))


def _fmt(x: float) -> str:
    return "-" if not np.isfinite(x) else f"{x:.3g}"


def tracking_rows(rows: list[dict[str, Any]]) -> list[list[str]]:
    """The table rows: one per (sweep point, controller) of the trajectory trials."""
    groups: dict[tuple[int, str], list[dict[str, Any]]] = defaultdict(list)
    for r in rows:
        if r.get("tracking_rms_position_mm") is not None:
            groups[(int(r.get("point", 0)), str(r["controller"]))].append(r)
    out = []
    for (_, controller), rs in sorted(groups.items()):
        settled = [r["settling_time_s"] for r in rs if r.get("settling_time_s") is not None]
        out.append([
            format_sweep(sweep_values(rs[0])), controller, str(len(rs)),
            _fmt(_stat([r["tracking_rms_position_mm"] for r in rs], "median")),
            _fmt(_stat([r["tracking_rms_position_mm"] for r in rs], "p95")),
            _fmt(_stat([r["tracking_max_position_mm"] for r in rs], "median")),
            _fmt(_stat([r["tracking_max_position_mm"] for r in rs], "max")),
            _fmt(_stat([r["tracking_rms_orientation_deg"] for r in rs], "median")),
            f"{len(settled)}/{len(rs)}", _fmt(_stat(settled, "median"))])
    return out


def tracking_plot(out_dir: Path, scenario: str, point: int) -> str | None:
    """The position error from the reference against time, linear scale, of the recorded
    trial 0 of every controller at one sweep point."""
    files = sorted((out_dir / TRIALS_DIR).glob(f"{scenario}__p{point}__*__00000.npz"))
    if not files:
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.5))
    for f in files:
        with np.load(f) as rec:
            t = np.asarray(rec["t"], float)
            axes[0].plot(t, np.asarray(rec["position_error"], float) * 1e3,
                         label=str(rec["controller"]))
            axes[1].plot(t, np.rad2deg(np.asarray(rec["orientation_error"], float)),
                         label=str(rec["controller"]))
    axes[0].set_title("tracking error, position [mm] (trial 0)")
    axes[1].set_title("tracking error, orientation [deg] (trial 0)")
    for ax in axes:
        ax.set_xlabel("time [s]")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    name = f"{scenario}_p{point}_tracking.png"
    fig.savefig(out_dir / name, dpi=90)
    plt.close(fig)
    return name


def tracking_section(out_dir: Path, scenario: str, rows: list[dict[str, Any]],
                     points: list[int]) -> list[str]:
    """The Markdown lines of the section (none for a scenario without trajectories).

    Args:
        out_dir: The results directory (plots are written there).
        scenario: The scenario's name.
        rows: Its result rows.
        points: The sweep points to plot.
    """
    table = tracking_rows(rows)
    if not table:
        return []
    lines = ["Trajectory tracking (error of the TRUE pose from the reference while it moves; "
             "*settled*: trials within the tolerances at the end; *settling*: time from the "
             "reference's end until the error stays within them):", ""]
    lines += ["| " + " | ".join(HEADER) + " |", "|" + "---|" * len(HEADER)]
    lines += ["| " + " | ".join(r) + " |" for r in table]
    lines.append("")
    for p in points:
        img = tracking_plot(out_dir, scenario, p)
        if img:
            sweep = next((format_sweep(sweep_values(r)) for r in rows
                          if int(r.get("point", 0)) == p), "")
            lines += [f"Tracking error versus time (sweep: {sweep}):", "",
                      f"![tracking error]({img})", ""]
    return lines
