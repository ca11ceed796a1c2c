"""The report's figures (PNG, matplotlib's Agg canvas): error versus time of a recorded
trial, sweeps along one axis, convergence maps over two axes, and the distribution of the
final errors per controller.

Figures are drawn on :func:`figure` (a ``matplotlib.figure.Figure`` on its own Agg
canvas: no pyplot, no global figure list to close) and written by :func:`save_figure`,
with fixed margins in inches for the figures whose labels have known sizes: a
``tight_layout`` lays out every tick label once more before the drawing does (about 40 %
of a figure's time), and the same margins do for every run. A figure whose text reaches
the edge of the image with those margins (an unusually wide tick label) is laid out again
with ``tight_layout`` and saved anew. The figures of every sweep point of one kind are
one figure redrawn with each point's data (:func:`line_figures`): its axes, ticks and
texts are made once. Titles are set at ``y=1.0``, just above the panel, where
matplotlib's automatic placement puts them too unless a tick label or an offset text is
above the panel (ours have none, but a linear axis of values below 1e-5 or from 1e6 puts
its offset, ``1e-6``, at its top left, which a long title may then touch): the automatic
placement lays out every y tick label once more to look for one. Within
:func:`benchmarks.study.drawers.drawing_aside` (a report), a figure is drawn and written by
a forked process on an idle core while this one makes the next figures.
"""

from __future__ import annotations

import logging
import re
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final, Literal

import numpy as np

from benchmarks.study import drawers
from benchmarks.study.metrics import Summary
from benchmarks.study.results import TRIALS_DIR
from benchmarks.study.stats import wilson_intervals
from hexapod.outputs import PNG_METADATA, inside

log = logging.getLogger(__name__)

#: Sweep points whose recorded trial gets an error-versus-time figure, at most.
MAX_TIME_SERIES = 4
#: Resolution of the report's PNG files [dots per inch] (the figures are drawn at it).
DPI = 90
#: ``savefig``'s options of the PNG files: the project's mark, and zlib's fastest level
#: (a third of the encoding time of its default level 6, files about 10 % larger).
PNG_OPTIONS: Final = {"dpi": DPI, "metadata": PNG_METADATA, "pil_kwargs": {"compress_level": 1}}


@dataclass(frozen=True)
class Margins:
    """Fixed margins of a figure's grid of panels [inches] (tick labels, axis labels and
    titles fit in them), and the gap between two panels of a row [inches].

    Attributes:
        left: Left of the first panel (its y tick labels and y label).
        right: Right of the last panel.
        bottom: Below the panels (x tick labels and x label).
        top: Above the panels (titles).
        gap: Between two panels of a row (the y tick labels of the right one).
    """

    left: float
    right: float
    bottom: float
    top: float
    gap: float = 0.0

    def fractions(self, width: float, height: float, columns: int) -> dict[str, float]:
        """``subplots_adjust`` keywords for a figure of ``width`` x ``height`` inches
        with ``columns`` panels per row (``wspace``: the gap over a panel's width)."""
        panel = (width - self.left - self.right - (columns - 1) * self.gap) / columns
        return {"left": self.left / width, "right": 1 - self.right / width,
                "bottom": self.bottom / height, "top": 1 - self.top / height,
                "wspace": self.gap / panel if columns > 1 else 0.2}


#: ``save_figure``'s layout for a figure the caller laid out (``subplots_adjust``).
AS_IS: Final = "as-is"
#: ``save_figure``'s layout computed from the drawn text (``tight_layout``, slower).
TIGHT: Final = "tight"
#: Two panels side by side, log y axes with titles (error versus time).
TWO_LOG_PANELS = Margins(left=0.72, right=0.15, bottom=0.59, top=0.36, gap=0.64)
#: Two panels side by side, linear y axes with titles (tracking error versus time).
TWO_LINEAR_PANELS = Margins(left=0.64, right=0.15, bottom=0.59, top=0.36, gap=0.6)
#: Two panels with y labels, no titles (the sweep figure).
TWO_LABELLED_PANELS = Margins(left=0.78, right=0.15, bottom=0.59, top=0.15, gap=0.84)
#: One panel with a y label and no title (the error CDF).
ONE_LABELLED_PANEL = Margins(left=0.72, right=0.15, bottom=0.61, top=0.17)
#: Panels with y labels and titles (time to converge, performance profiles).
LABELLED_TITLED_PANELS = Margins(left=0.72, right=0.25, bottom=0.61, top=0.36, gap=0.74)


#: Superscript digits and minus (Unicode), for :func:`plain_log_labels`.
_SUPERSCRIPT = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")
#: How matplotlib writes a log axis's label in mathtext: ``$\mathdefault{2\times10^{-3}}$``.
_MATHTEXT = re.compile(r"\$\\mathdefault\{(.*)\^\{(.*)\}\}\$")


def plain_log_labels(axis: Any, base: float = 10) -> None:
    """Label the ticks of a log axis (set after its scale: a scale sets its own labels)
    as matplotlib does (``10⁻³``, ``2×10⁻³``, ``2³``), in plain text with Unicode
    superscripts instead of mathtext, whose parser (pyparsing) and layout make a tenth
    of the Python calls of a report's drawing."""
    from matplotlib.ticker import LogFormatterSciNotation

    class Plain(LogFormatterSciNotation):
        def __call__(self, x: float, pos: int | None = None) -> str:
            text = super().__call__(x, pos)
            found = _MATHTEXT.fullmatch(text)  # none: '' (an unlabelled minor tick)
            return (found[1].replace("\\times", "×").replace("-", "−")
                    + found[2].translate(_SUPERSCRIPT)) if found else text

    axis.set_major_formatter(Plain(base))
    axis.set_minor_formatter(Plain(base))


def figure(figsize: tuple[float, float]) -> Any:
    """A new figure of ``figsize`` inches on its own Agg canvas at :data:`DPI`
    (matplotlib imported on first use; nothing to close: it goes with its last
    reference)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, dpi=DPI)
    FigureCanvasAgg(fig)
    return fig


def _columns(fig: Any) -> int:
    """Panels per row of the figure's grid (1 without a grid)."""
    for ax in fig.axes:
        spec = ax.get_subplotspec()
        if spec is not None:
            return int(spec.get_gridspec().ncols)
    return 1


def _ink_at_edges(fig: Any) -> bool:
    """Whether the drawn image has anything but the background on its outermost pixels
    (text cut by the edge: margins too small for this figure's labels)."""
    img = np.asarray(fig.canvas.buffer_rgba())
    edges = np.concatenate([img[0], img[-1], img[:, 0], img[:, -1]])
    face = (np.asarray(fig.get_facecolor()) * 255).round().astype(np.uint8)
    return bool(np.any(edges != face))


def save_figure(fig: Any, out_dir: Path, name: str,
                layout: Margins | Literal["as-is", "tight"] = TIGHT) -> str:
    """Lay out and save a figure as ``out_dir/name`` (checked to stay inside, marked as
    the project's) at :data:`DPI`; return its Markdown link target (:func:`link`).

    Args:
        fig: A figure of :func:`figure`.
        out_dir: The results directory.
        name: The file name.
        layout: :class:`Margins` (fixed, in inches; laid out again with
            ``tight_layout`` if text reaches the image's edge), :data:`AS_IS` (the
            caller's ``subplots_adjust``, the same check) or :data:`TIGHT`.
    """
    path = inside(out_dir, name)
    aside_or_here(draw_figure, (fig, path, layout), path.name)
    return link(name)


def link(name: str) -> str:
    """The Markdown link target of a figure's file: ``./`` before a name with ``:``, which
    a Markdown reader would take for a URL scheme."""
    return f"./{name}" if ":" in name else name


def aside_or_here(job: Callable[..., None], args: tuple[Any, ...], name: str) -> None:
    """``job(*args)`` (drawing the figure files ``name``, comma-separated: the name a
    failure is reported with) in a drawer of
    :func:`benchmarks.study.drawers.drawing_aside` if one is free, else here."""
    if not drawers.started(job, args, name):
        job(*args)


def draw_figure(fig: Any, path: Path, layout: Margins | Literal["as-is", "tight"]) -> None:
    """Lay out, draw and write one figure (:func:`save_figure`)."""
    if layout == TIGHT:
        fig.tight_layout()
    elif isinstance(layout, Margins):
        width, height = fig.get_size_inches()
        fig.subplots_adjust(**layout.fractions(float(width), float(height), _columns(fig)))
    fig.savefig(path, **PNG_OPTIONS)
    if layout != TIGHT and _ink_at_edges(fig):
        log.debug("%s: text at the edge with fixed margins; laid out tightly", path.name)
        fig.tight_layout()
        fig.savefig(path, **PNG_OPTIONS)


def representative(points: list[int]) -> list[int]:
    """At most :data:`MAX_TIME_SERIES` sweep points, spread from the first to the last."""
    if len(points) <= MAX_TIME_SERIES:
        return points
    idx = np.linspace(0, len(points) - 1, MAX_TIME_SERIES).round().astype(int)
    return [points[i] for i in sorted(set(idx.tolist()))]


#: One controller's curves in a figure of line panels: its label, and an ``(x, y)`` pair
#: per panel.
Curves = tuple[str, list[tuple[np.ndarray, np.ndarray]]]


def trial0_files(out_dir: Path, scenario: str, point: int) -> list[Path]:
    """The recorded trial 0 of every controller at one sweep point, sorted by name."""
    return sorted((out_dir / TRIALS_DIR).glob(f"{scenario}__p{point}__*__00000.npz"))


def line_figures(out_dir: Path, points: list[int], curves_of: Callable[[int], list[Curves]],
                 draw: Callable[[list[Curves]], tuple[Any, list[list[Any]]]],
                 name_of: Callable[[int], str], layout: Margins) -> dict[int, str]:
    """One figure of line panels per sweep point, drawn once and redrawn for the next
    points with the new data in its lines (the same controllers, so the same legend):
    the axes, ticks and texts are made once (a third of a figure's time), and the image is
    pixel for pixel the one a new figure would give (axes limits rescaled to the data).
    Every point's curves are read first; the figures are then drawn by one drawer if one
    is free (:func:`aside_or_here`), else here, each figure after the first offered to a
    drawer once this process has drawn the figure before (a drawer forked then draws
    it as fast as this process: its ticks and texts made).

    Args:
        out_dir: The results directory.
        points: The sweep points.
        curves_of: A point's curves (none: no figure for it).
        draw: A new figure of curves and its lines (per panel, in the order of the
            curves).
        name_of: A point's file name.
        layout: The figure's margins.

    Returns:
        The Markdown link target of each point's figure.
    """
    curves = {p: c for p in points if (c := curves_of(p))}
    names = {p: name_of(p) for p in curves}
    paths = {p: inside(out_dir, name) for p, name in names.items()}
    if curves:
        aside_or_here(_draw_lines, (curves, draw, paths, layout),
                      ", ".join(path.name for path in paths.values()))
    return {p: link(name) for p, name in names.items()}


def _draw_lines(curves: dict[int, list[Curves]],
                draw: Callable[[list[Curves]], tuple[Any, list[list[Any]]]],
                paths: dict[int, Path], layout: Margins) -> None:
    """The figures of :func:`line_figures`."""
    fig: Any = None
    lines: list[list[Any]] = []
    labels: list[str] = []
    for point, point_curves in curves.items():
        if fig is None or [c[0] for c in point_curves] != labels:
            fig, lines = draw(point_curves)
            labels = [c[0] for c in point_curves]
            draw_figure(fig, paths[point], layout)  # here: a drawer forked after starts warm
            continue
        for panel, panel_lines in enumerate(lines):
            for line, (_, data) in zip(panel_lines, point_curves, strict=True):
                line.set_data(*data[panel])
        for ax in fig.axes:
            ax.relim()
            ax.autoscale_view()
        aside_or_here(draw_figure, (fig, paths[point], layout), paths[point].name)


def trial0_curves(out_dir: Path, scenario: str, point: int,
                  panels: Callable[[Any], list[tuple[np.ndarray, np.ndarray]]]) -> list[Curves]:
    """The curves of every controller's recorded trial 0 at one sweep point: its label
    and ``panels(record)``, the ``(x, y)`` pair of each panel read from its ``.npz``."""
    curves = []
    for f in trial0_files(out_dir, scenario, point):
        with np.load(f) as rec:
            curves.append((str(rec["controller"]), panels(rec)))
    return curves


def draw_time_panels(curves: list[Curves], titles: tuple[str, str],
                     log: bool) -> tuple[Any, list[list[Any]]]:
    """Two panels of curves against time [s], a line per controller, titled ``titles``
    (``log``: a logarithmic y axis, grid at the minor ticks too); the figure and its lines
    per panel (for :func:`line_figures`)."""
    fig = figure((10, 3.5))
    axes = fig.subplots(1, 2)
    lines: list[list[Any]] = [[], []]
    for label, data in curves:
        for panel, (x, y) in enumerate(data):
            plot = axes[panel].semilogy if log else axes[panel].plot
            lines[panel] += plot(x, y, label=label)
    for ax, title in zip(axes, titles, strict=True):
        if log:
            plain_log_labels(ax.yaxis)
        ax.set_title(title, y=1.0)
        ax.set_xlabel("time [s]")
        ax.grid(True, which="both" if log else "major", alpha=0.3)
        ax.yaxis.set_label_coords(0, 0.5)  # no y label: no search of the tick labels for its place
        ax.legend(fontsize=7)
    return fig, lines


def _error_panels(rec: Any) -> list[tuple[np.ndarray, np.ndarray]]:
    """Error norm (its positive values) and position error [mm] (floored at 1e-6 for the
    log axis)."""
    err = np.asarray(rec["error_norm"], float)
    t = np.asarray(rec["t"], float)
    ok = np.isfinite(err) & (err > 0)
    return [(t[ok], err[ok]), (t, np.maximum(np.asarray(rec["position_error"]) * 1e3, 1e-6))]


def time_series(out_dir: Path, scenario: str, points: list[int]) -> dict[int, str]:
    """Error norm and position error versus time of the recorded trial 0 of each
    controller, a figure per sweep point (those with a recorded trial)."""
    titles = ("feature error norm (trial 0)", "position error [mm] (trial 0)")
    return line_figures(out_dir, points,
                        lambda p: trial0_curves(out_dir, scenario, p, _error_panels),
                        lambda curves: draw_time_panels(curves, titles, log=True),
                        lambda p: f"{scenario}_p{p}_timeseries.png", TWO_LOG_PANELS)


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
    fig = figure((10, 3.5))
    a0, a1 = fig.subplots(1, 2)
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
    plain_log_labels(a1.yaxis)
    a0.set_ylabel("convergence [%]")
    a1.set_ylabel("final position error [mm]")
    for ax in (a0, a1):
        ax.set_xlabel(key)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    return [save_figure(fig, out_dir, f"{scenario}_sweep_{key}.png", TWO_LABELLED_PANELS)]


def sweep_tick(value: Any) -> str:
    """A sweep value as a tick label: a number in ``g`` format, any other value (a goal
    setting, a camera kind) as its text."""
    if isinstance(value, int | float) and not isinstance(value, bool):
        return f"{value:g}"
    return str(value)


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
    from matplotlib.colors import LogNorm

    fig = figure((4.2 * len(ctrls) + 1, 8.5))
    axes = fig.subplots(2, len(ctrls), squeeze=False)
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
            ax.set_xticks(range(len(xs)), [sweep_tick(v) for v in xs], fontsize=7,
                          rotation=45)
            ax.set_yticks(range(len(ys)), [sweep_tick(v) for v in ys], fontsize=7)
            ax.set_xlabel(x_key)
            ax.set_ylabel(y_key)
            ax.set_title(f"{ctrl}: {title}", fontsize=9, y=1.0)
            fig.colorbar(im, ax=ax, fraction=0.046)
    return save_figure(fig, out_dir, f"{scenario}_map.png", TIGHT)  # colour bars: tight


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
    fig = figure((6.5, 4))
    ax = fig.subplots()
    for label in sorted(by_ctrl):
        e = np.sort(by_ctrl[label])
        k = np.arange(1, len(e) + 1)
        line, = ax.step(e, k / totals[label], where="post",
                        label=f"{label} ({totals[label]} trials)")
        low, high = wilson_intervals(k, totals[label])
        ax.fill_between(e, low, high, step="post", alpha=0.2,
                        color=line.get_color(), linewidth=0)
    ax.set_xscale("log")
    plain_log_labels(ax.xaxis)
    ax.set_ylim(0, 1.01)
    ax.set_xlabel("tolerance on the final position error [mm]")
    ax.set_ylabel("fraction of trials within")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    return save_figure(fig, out_dir, f"{scenario}_error_cdf.png", ONE_LABELLED_PANEL)
