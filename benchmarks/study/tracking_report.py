"""The report's section on trajectory tasks: the tracking metrics of every controller at
every sweep point (:mod:`benchmarks.sim.tracking`), and the tracking error against time
of the recorded trial. In the dynamic world the table also gives the drives' forces (the
peak over every physics step, the RMS over the control instants, the time at a force
limit) and a second figure their forces against time."""

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
#: Columns added in the dynamic world (rows with drive figures).
FORCE_HEADER = ["peak N (median)", "peak N (worst)", "RMS N (median)", "at limit s (median)",
                "at limit s (worst)"]


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


def _dynamic(rows: list[dict[str, Any]]) -> bool:
    """Whether the rows carry the dynamic world's drive figures."""
    return any(r.get("max_leg_force_n") is not None for r in rows)


def tracking_header(rows: list[dict[str, Any]]) -> list[str]:
    """The columns of the table of ``rows`` (the force columns in the dynamic world)."""
    return HEADER + (FORCE_HEADER if _dynamic(rows) else [])


def _force_cells(rs: list[dict[str, Any]]) -> list[str]:
    """Peak force [N] (median and worst trial), RMS force [N] (median) and time at a force
    limit [s] (median and worst) of one (sweep point, controller) group."""
    peak = [r.get("max_leg_force_n") for r in rs]
    sat = [r.get("saturation_time_s") for r in rs]
    return [_fmt(_stat(peak, "median")), _fmt(_stat(peak, "max")),
            _fmt(_stat([r.get("rms_leg_force_n") for r in rs], "median")),
            _fmt(_stat(sat, "median")), _fmt(_stat(sat, "max"))]


def tracking_rows(rows: list[dict[str, Any]]) -> list[list[str]]:
    """The table rows: one per (sweep point, controller) of the trajectory trials (with
    :data:`FORCE_HEADER`'s cells in the dynamic world)."""
    groups: dict[tuple[int, str], list[dict[str, Any]]] = defaultdict(list)
    for r in rows:
        if r.get("tracking_rms_position_mm") is not None:
            groups[(int(r.get("point", 0)), str(r["controller"]))].append(r)
    forces = _dynamic([r for rs in groups.values() for r in rs])
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
            f"{len(settled)}/{len(rs)}", _fmt(_stat(settled, "median")),
            *(_force_cells(rs) if forces else [])])
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


def forces_figure(out_dir: Path, scenario: str, point: int) -> Any:
    """The drives' forces against time of the recorded trial 0 of every controller at one
    sweep point, one panel per controller (six legs, the force limits dashed when a force
    exceeds half of them); None
    without a recorded trial with forces (the kinematic world)."""
    traces = []
    for f in sorted((out_dir / TRIALS_DIR).glob(f"{scenario}__p{point}__*__00000.npz")):
        with np.load(f) as rec:
            if "leg_forces" in rec:
                traces.append((str(rec["controller"]), np.asarray(rec["t"], float),
                               np.asarray(rec["leg_forces"], float),
                               np.asarray(rec["force_limit"], float)))
    if not traces:
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(traces), figsize=(3.6 * len(traces) + 1, 3.3),
                             squeeze=False, sharey=True)
    for ax, (controller, t, forces, limit) in zip(axes[0], traces, strict=True):
        for leg in range(forces.shape[1]):
            ax.plot(t, forces[:, leg], lw=0.9, label=f"leg {leg}")
        lim = float(np.min(limit))
        if np.abs(forces).max() > 0.5 * lim:  # the limits drawn when the forces near them
            for sign in (1.0, -1.0):
                ax.axhline(sign * lim, color="k", ls="--", lw=0.7)
            ax.set_title(f"{controller}: drive forces [N]", fontsize=9)
        else:
            ax.set_title(f"{controller}: drive forces [N] (limit {lim:g})", fontsize=9)
        ax.set_xlabel("time [s]")
        ax.grid(True, alpha=0.3)
    axes[0][0].legend(fontsize=6, ncol=2)
    fig.subplots_adjust(left=0.06, right=0.98, bottom=0.15, top=0.9, wspace=0.12)
    return fig


def forces_plot(out_dir: Path, scenario: str, point: int) -> str | None:
    """:func:`forces_figure` saved beside the tracking-error plot; its file name."""
    fig = forces_figure(out_dir, scenario, point)
    if fig is None:
        return None
    import matplotlib.pyplot as plt

    name = f"{scenario}_p{point}_forces.png"
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
             "reference's end until the error stays within them"
             + ("; *peak N*: largest drive force over every physics step; *RMS N*: drive "
                "forces at the control instants, all legs; *at limit*: time any drive spent "
                "at its force limit" if _dynamic(rows) else "") + "):", ""]
    header = tracking_header(rows)
    lines += ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(r) + " |" for r in table]
    lines.append("")
    for p in points:
        img = tracking_plot(out_dir, scenario, p)
        if img:
            sweep = next((format_sweep(sweep_values(r)) for r in rows
                          if int(r.get("point", 0)) == p), "")
            lines += [f"Tracking error versus time (sweep: {sweep}):", "",
                      f"![tracking error]({img})", ""]
            forces = forces_plot(out_dir, scenario, p)
            if forces:
                lines += [f"Drive forces versus time (sweep: {sweep}):", "",
                          f"![drive forces]({forces})", ""]
    return lines
