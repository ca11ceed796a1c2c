"""The report's figure machinery: fixed margins, the fallback to a tight layout when text
reaches the image's edge, and line figures redrawn per sweep point pixel for pixel as
new figures."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from matplotlib.image import imread

from benchmarks.study import plots


def _pixels(path: Path) -> np.ndarray:
    return np.asarray(imread(path))


def _edges(img: np.ndarray) -> np.ndarray:
    return np.concatenate([img[0], img[-1], img[:, 0], img[:, -1]])


def test_margins_in_inches_become_the_figure_fractions() -> None:
    m = plots.Margins(left=1.0, right=0.5, bottom=0.4, top=0.2, gap=0.5)
    f = m.fractions(10.0, 4.0, 2)  # panels (10 - 1 - 0.5 - 0.5) / 2 = 4 in wide
    assert f == pytest.approx({"left": 0.1, "right": 0.95, "bottom": 0.1, "top": 0.95,
                               "wspace": 0.125})


def test_text_cut_by_too_small_margins_is_laid_out_again(tmp_path: Path) -> None:
    """Margins of zero cut the tick labels and titles: the figure is laid out tightly and
    saved again, nothing touches the image's edge; with the usual margins the fixed
    layout stays (the image differs from the tight one)."""
    def draw() -> object:
        fig = plots.figure((6.5, 4))
        ax = fig.subplots()
        ax.plot([0, 1e5], [0, 1])
        ax.set_ylabel("fraction of trials within")
        ax.set_title("a title")
        return fig

    name = plots.save_figure(draw(), tmp_path, "cut.png", plots.Margins(0, 0, 0, 0))
    assert name == "cut.png"
    assert not np.any(_edges(_pixels(tmp_path / "cut.png")) < 1.0)
    plots.save_figure(draw(), tmp_path, "fixed.png", plots.ONE_LABELLED_PANEL)
    plots.save_figure(draw(), tmp_path, "tight.png", plots.TIGHT)
    fixed, tight = _pixels(tmp_path / "fixed.png"), _pixels(tmp_path / "tight.png")
    assert not np.any(_edges(fixed) < 1.0)
    assert fixed.shape == tight.shape and np.any(fixed != tight)


def test_a_redrawn_line_figure_is_the_new_figure_pixel_for_pixel(tmp_path: Path) -> None:
    """Three points of log-scale curves over different ranges: the figure drawn once and
    refilled gives the images of a new figure per point; a point with other controllers
    gets a new figure."""
    rng = np.random.default_rng(2)
    t = np.linspace(0, 5, 200)

    def curves(point: int) -> list[plots.Curves]:
        names = ["a", "b"] if point < 2 else ["a", "c"]
        return [(n, [(t, np.exp(-t * (k + 1)) * 10.0 ** point + 1e-3 * rng.random(t.size))])
                for k, n in enumerate(names)]

    data = {p: curves(p) for p in range(3)}

    def draw(cs: list[plots.Curves]) -> tuple[object, list[list[object]]]:
        fig = plots.figure((5, 3))
        ax = fig.subplots()
        lines = [[ax.semilogy(*d[0], label=label)[0] for label, d in cs]]
        ax.set_title("error")
        ax.legend()
        return fig, lines

    made = []

    def counted(cs: list[plots.Curves]) -> tuple[object, list[list[object]]]:
        made.append(1)
        return draw(cs)

    reused = tmp_path / "reused"
    reused.mkdir()
    names = plots.line_figures(reused, [0, 1, 2], data.__getitem__, counted,
                               lambda p: f"p{p}.png", plots.TWO_LOG_PANELS)
    assert names == {0: "p0.png", 1: "p1.png", 2: "p2.png"} and len(made) == 2
    for p in range(3):
        fig, _ = draw(data[p])
        plots.save_figure(fig, tmp_path, f"new{p}.png", plots.TWO_LOG_PANELS)
        assert np.array_equal(_pixels(reused / f"p{p}.png"), _pixels(tmp_path / f"new{p}.png"))


def test_plain_log_labels_are_matplotlibs_without_mathtext() -> None:
    """The labels of a log axis in plain text are matplotlib's mathtext ones character for
    character (superscripts for the exponent): decades, minor ticks labelled on a narrow
    range, base 2; an unlabelled minor tick stays empty."""
    digits = "⁻⁰¹²³⁴⁵⁶⁷⁸⁹"

    def labels(lims: tuple[float, float], base: float, plain: bool) -> list[str]:
        axis = plots.figure((4, 3)).subplots().xaxis
        axis.axes.set_xscale("log", base=base)
        axis.axes.set_xlim(*lims)
        if plain:
            plots.plain_log_labels(axis, base=base)
        return [*axis.get_major_formatter().format_ticks(axis.get_majorticklocs()),
                *axis.get_minor_formatter().format_ticks(axis.get_minorticklocs())]

    def as_mathtext(text: str) -> str:
        mantissa = text.rstrip(digits)
        exponent = text[len(mantissa):].translate(str.maketrans(digits, "-0123456789"))
        return (f"$\\mathdefault{{{mantissa.replace('×', chr(92) + 'times')}^{{{exponent}}}}}$"
                if text else text)

    for lims, base in (((1e-6, 1.0), 10), ((0.15, 0.9), 10), ((1.0, 300.0), 2)):
        plain, mathtext = labels(lims, base, True), labels(lims, base, False)
        assert not any("$" in t for t in plain)
        assert [as_mathtext(t) for t in plain] == mathtext
    assert {"10⁻⁶", "10⁰"} <= set(labels((1e-6, 1.0), 10, True))
    assert "2×10⁻¹" in labels((0.15, 0.9), 10, True)
    assert "2⁸" in labels((1.0, 300.0), 2, True)
