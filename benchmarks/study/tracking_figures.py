"""The figures of the report's section on trajectory tasks
(:mod:`benchmarks.study.tracking_report`): the tracking error against time of the recorded
trial 0 of every controller and, in the dynamic world, the drives' forces, a figure of
each per sweep point. A figure is drawn once and redrawn with the next points' data
(:func:`benchmarks.study.plots.line_figures`): the image is the one a new figure gives."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.study.plots import (
    AS_IS,
    TWO_LINEAR_PANELS,
    aside_or_here,
    draw_figure,
    draw_time_panels,
    figure,
    line_figures,
    link,
    trial0_curves,
    trial0_files,
)
from hexapod.outputs import inside

#: The forces figure's layout (fractions of the figure; ``subplots_adjust``).
FORCES_LAYOUT = {"left": 0.06, "right": 0.98, "bottom": 0.15, "top": 0.9, "wspace": 0.12}
#: A controller's recorded forces: its label, the times [s], the forces [N] (period x
#: leg) and the drives' force limits [N].
Trace = tuple[str, np.ndarray, np.ndarray, np.ndarray]


def _tracking_panels(rec: Any) -> list[tuple[np.ndarray, np.ndarray]]:
    """Position [mm] and orientation [deg] errors from the reference."""
    t = np.asarray(rec["t"], float)
    return [(t, np.asarray(rec["position_error"], float) * 1e3),
            (t, np.rad2deg(np.asarray(rec["orientation_error"], float)))]


def tracking_plots(out_dir: Path, scenario: str, points: list[int]) -> dict[int, str]:
    """The position and orientation errors from the reference against time, linear
    scale, of the recorded trial 0 of every controller, a figure per sweep point (those
    with a recorded trial); the file name of each."""
    titles = ("tracking error, position [mm] (trial 0)",
              "tracking error, orientation [deg] (trial 0)")
    return line_figures(out_dir, points,
                        lambda p: trial0_curves(out_dir, scenario, p, _tracking_panels),
                        lambda curves: draw_time_panels(curves, titles, log=False),
                        lambda p: f"{scenario}_p{p}_tracking.png", TWO_LINEAR_PANELS)


def force_traces(out_dir: Path, scenario: str, point: int) -> list[Trace]:
    """The recorded forces of every controller's trial 0 at one sweep point (none in the
    kinematic world)."""
    traces = []
    for f in trial0_files(out_dir, scenario, point):
        with np.load(f) as rec:
            if "leg_forces" in rec:
                traces.append((str(rec["controller"]), np.asarray(rec["t"], float),
                               np.asarray(rec["leg_forces"], float),
                               np.asarray(rec["force_limit"], float)))
    return traces


@dataclass
class _ForcePanels:
    """A forces figure and its lines: a panel per controller, a line per leg, the dashed
    force limits when drawn."""

    fig: Any
    axes: list[Any]
    legs: list[list[Any]]
    limits: list[list[Any]]
    shape: list[tuple[str, int]]  # each panel's controller and number of legs


def _limits(ax: Any, controller: str, forces: np.ndarray, limit: np.ndarray) -> list[Any]:
    """The panel's title, and its force limits dashed when a force exceeds half of them
    (the lines drawn)."""
    lim = float(np.min(limit))
    if np.abs(forces).max() > 0.5 * lim:  # the limits drawn when the forces near them
        ax.set_title(f"{controller}: drive forces [N]", fontsize=9, y=1.0)
        return [ax.axhline(sign * lim, color="k", ls="--", lw=0.7) for sign in (1.0, -1.0)]
    ax.set_title(f"{controller}: drive forces [N] (limit {lim:g})", fontsize=9,
                 y=1.0)
    return []


def _draw_forces(traces: list[Trace]) -> _ForcePanels:
    fig = figure((3.6 * len(traces) + 1, 3.3))
    axes = list(fig.subplots(1, len(traces), squeeze=False, sharey=True)[0])
    legs, limits = [], []
    for ax, (controller, t, forces, limit) in zip(axes, traces, strict=True):
        legs.append([ax.plot(t, forces[:, leg], lw=0.9, label=f"leg {leg}")[0]
                     for leg in range(forces.shape[1])])
        limits.append(_limits(ax, controller, forces, limit))
        ax.set_xlabel("time [s]")
        ax.grid(True, alpha=0.3)
        ax.yaxis.set_label_coords(0, 0.5)  # no y label: no search of the tick labels for its place
    axes[0].legend(fontsize=6, ncol=2)
    fig.subplots_adjust(**FORCES_LAYOUT)
    return _ForcePanels(fig, axes, legs, limits, [(c, f.shape[1]) for c, _, f, _ in traces])


def _redraw_forces(panels: _ForcePanels, traces: list[Trace]) -> None:
    """Put another point's forces (the same controllers and legs) in the figure."""
    for i, (controller, t, forces, limit) in enumerate(traces):
        for leg, line in enumerate(panels.legs[i]):
            line.set_data(t, forces[:, leg])
        for line in panels.limits[i]:
            line.remove()
        panels.limits[i] = _limits(panels.axes[i], controller, forces, limit)
    for ax in panels.axes:
        ax.relim()
    for ax in panels.axes:  # the shared y axis: every panel's data first
        ax.autoscale_view()
    panels.fig.subplots_adjust(**FORCES_LAYOUT)  # undone if the last one was laid out tightly


def forces_figure(out_dir: Path, scenario: str, point: int) -> Any:
    """The drives' forces against time of the recorded trial 0 of every controller at one
    sweep point, one panel per controller (six legs, the force limits dashed when a force
    exceeds half of them); None without a recorded trial with forces (the kinematic
    world)."""
    traces = force_traces(out_dir, scenario, point)
    return _draw_forces(traces).fig if traces else None


def forces_plots(out_dir: Path, scenario: str, points: list[int]) -> dict[int, str]:
    """:func:`forces_figure` of each sweep point saved beside its tracking-error plot (one
    figure redrawn with each point's forces, drawn as
    :func:`~benchmarks.study.plots.line_figures` draws its figures); the file name of
    each."""
    traces = {p: t for p in points if (t := force_traces(out_dir, scenario, p))}
    names = {p: f"{scenario}_p{p}_forces.png" for p in traces}
    paths = {p: inside(out_dir, name) for p, name in names.items()}
    if traces:
        aside_or_here(_draw_forces_plots, (traces, paths),
                      ", ".join(path.name for path in paths.values()))
    return {p: link(name) for p, name in names.items()}


def _draw_forces_plots(traces: dict[int, list[Trace]], paths: dict[int, Path]) -> None:
    """The figures of :func:`forces_plots`."""
    panels = None
    for point, point_traces in traces.items():
        if panels is None or panels.shape != [(c, f.shape[1]) for c, _, f, _ in point_traces]:
            panels = _draw_forces(point_traces)
            draw_figure(panels.fig, paths[point], AS_IS)  # here: a drawer forked after starts warm
            continue
        _redraw_forces(panels, point_traces)
        aside_or_here(draw_figure, (panels.fig, paths[point], AS_IS), paths[point].name)
