"""Figures drawn by forked processes on the idle cores (:func:`drawers.drawing_aside`):
the same bytes as drawn here, drawn here when no core is idle or another thread runs, and
a failed drawing named with its exit code."""

from __future__ import annotations

import os
import threading
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from matplotlib.artist import Artist

from benchmarks.exceptions import ResultsError
from benchmarks.study import drawers, plots, tracking_figures


def _log_curves(point: int) -> list[plots.Curves]:
    t = np.linspace(0, 5, 200)
    return [(n, [(t, np.exp(-t * (k + 1)) * 10.0 ** point), (t, t * (k + point + 1))])
            for k, n in enumerate(["a", "b"])]


def _figures(out: Path) -> dict[int, str]:
    """Three points of a two-panel line figure (one figure redrawn: the first one's
    drawer has its own copy), then the error CDF of some rows."""
    names = plots.line_figures(
        out, [0, 1, 2], _log_curves,
        lambda cs: plots.draw_time_panels(cs, ("error", "position [mm]"), log=True),
        lambda p: f"p{p}.png", plots.TWO_LOG_PANELS)
    rows = [{"controller": c, "final_position_error_mm": e}
            for c in "ab" for e in (0.01, 0.2, 3.0, float("nan"))]
    plots.error_cdf(out, "s", rows)
    return names


def _recording_writers(monkeypatch: pytest.MonkeyPatch) -> None:
    """Record the process that draws each file (in a file: a forked drawer's memory is
    its own)."""
    draw = plots.draw_figure

    def recorded(fig: Any, path: Path, layout: Any) -> None:
        draw(fig, path, layout)
        path.with_suffix(".pid").write_text(str(os.getpid()))

    monkeypatch.setattr(plots, "draw_figure", recorded)
    monkeypatch.setattr(tracking_figures, "draw_figure", recorded)


def _idle(monkeypatch: pytest.MonkeyPatch, cores: int, running: int,
          one_thread: bool = True) -> None:
    """A machine of ``cores`` cores with ``running`` runnable tasks, this process
    included (and this process's only thread: pytest-xdist's are not this test's)."""
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: set(range(cores)), raising=False)
    monkeypatch.setattr(drawers, "runnable_tasks", lambda: running)
    if one_thread:
        monkeypatch.setattr(threading, "active_count", lambda: 1)


def _writers(out: Path) -> dict[str, int]:
    return {f.stem: int(f.read_text()) for f in sorted(out.glob("*.pid"))}


def test_figures_drawn_aside_are_the_bytes_drawn_here(tmp_path: Path,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """Within drawing_aside the first figure is drawn by a forked process (and the next
    ones while a drawer is free, else here), the rest of the report going on; every file
    is the bytes drawn here, the line figure refilled after a fork included."""
    _recording_writers(monkeypatch)
    here, aside = tmp_path / "here", tmp_path / "aside"
    here.mkdir(), aside.mkdir()
    _figures(here)
    _idle(monkeypatch, cores=3, running=1)
    with drawers.drawing_aside(aside):
        names = _figures(aside)
    assert names == {0: "p0.png", 1: "p1.png", 2: "p2.png"}
    pngs = sorted(f.name for f in here.glob("*.png"))
    assert pngs == ["p0.png", "p1.png", "p2.png", "s_error_cdf.png"]
    for name in pngs:
        assert (aside / name).read_bytes() == (here / name).read_bytes(), name
    assert set(_writers(here).values()) == {os.getpid()}
    assert _writers(aside)["p0"] != os.getpid()


def test_figures_are_drawn_here_with_another_thread_or_no_idle_core(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A fork copies the calling thread only (a lock another thread holds would stay
    locked in the child), and a drawer on a busy machine would only take this process's
    core: every figure is drawn by this process, before save_figure returns. The idle
    cores are those no runnable task (this process one of them) takes, all but one at
    most."""
    _recording_writers(monkeypatch)
    _idle(monkeypatch, cores=2, running=1, one_thread=False)
    done = threading.Event()
    other = threading.Thread(target=done.wait)
    other.start()
    try:
        with drawers.drawing_aside(tmp_path):
            _figures(tmp_path)
            assert set(_writers(tmp_path).values()) == {os.getpid()}
    finally:
        done.set()
        other.join()
    assert drawers.idle_cores() == 1
    for cores, running in ((1, 1), (2, 2), (4, 5)):
        _idle(monkeypatch, cores, running)
        assert drawers.idle_cores() == 0
        busy = tmp_path / f"busy{cores}"
        busy.mkdir()
        with drawers.drawing_aside(busy):
            plots.error_cdf(busy, "s", [{"controller": "a", "final_position_error_mm": 0.1}])
            assert _writers(busy) == {"s_error_cdf": os.getpid()}


class _Broken(Artist):
    def draw(self, renderer: Any) -> None:
        raise RuntimeError("this artist cannot be drawn")


def test_a_figure_that_fails_in_its_drawer_names_itself(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capfd: pytest.CaptureFixture[str]
        ) -> None:
    """The drawer's traceback goes to stderr, the others are waited for, and leaving
    drawing_aside raises a ResultsError with the figure's name and exit code."""
    _idle(monkeypatch, cores=2, running=1)
    fig = plots.figure((3, 2))
    fig.subplots().add_artist(_Broken())
    with (pytest.raises(ResultsError, match=r"broken\.png \(exit code 1\)"),
          drawers.drawing_aside(tmp_path)):
        plots.save_figure(fig, tmp_path, "broken.png", plots.ONE_LABELLED_PANEL)
        _figures(tmp_path)
    assert "this artist cannot be drawn" in capfd.readouterr().err
    assert (tmp_path / "p2.png").is_file() and (tmp_path / "s_error_cdf.png").is_file()



def test_a_group_of_figures_goes_to_one_drawer(tmp_path: Path,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    """The forces figures of every sweep point go to one drawer when it is free (the
    figure made and drawn there once, refilled for the next points): the bytes drawn
    here, every file written by that one process."""
    _recording_writers(monkeypatch)
    t = np.linspace(0, 2, 120)
    for out in (tmp_path / "here", tmp_path / "aside"):
        (out / "trials").mkdir(parents=True)
        for point, scale in enumerate((2.0, 9.0, 3.0)):
            np.savez(out / "trials" / f"s__p{point}__ctc__00000.npz", controller="ctc", t=t,
                     leg_forces=scale * np.sin(np.outer(t, np.arange(1, 7))),
                     force_limit=np.full(6, 10.0))
    assert tracking_figures.forces_plots(tmp_path / "here", "s", [0, 1, 2]) == {
        p: f"s_p{p}_forces.png" for p in range(3)}
    _idle(monkeypatch, cores=2, running=1)
    with drawers.drawing_aside(tmp_path / "aside"):
        tracking_figures.forces_plots(tmp_path / "aside", "s", [0, 1, 2])
    for p in range(3):
        name = f"s_p{p}_forces.png"
        assert (tmp_path / "aside" / name).read_bytes() == (tmp_path / "here" / name
                                                            ).read_bytes(), name
    writers = set(_writers(tmp_path / "aside").values())
    assert len(writers) == 1 and os.getpid() not in writers


def test_a_failed_group_names_its_files(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                        capfd: pytest.CaptureFixture[str]) -> None:
    """A line figure that cannot be drawn at its second point fails its drawer: the
    error names every file of the group (the drawer's traceback, printed, names the
    point)."""
    def curves(point: int) -> list[plots.Curves]:
        t = np.linspace(0, 1, 10)
        return [("a", [(t, t), (t, t if point == 0 else t[:5])])]  # point 1: x, y disagree

    _idle(monkeypatch, cores=2, running=1)
    with (pytest.raises(ResultsError, match=r"p0\.png, p1\.png \(exit code 1\)"),
          drawers.drawing_aside(tmp_path)):
        plots.line_figures(tmp_path, [0, 1], curves,
                           lambda cs: plots.draw_time_panels(cs, ("x", "y"), log=False),
                           lambda p: f"p{p}.png", plots.TWO_LINEAR_PANELS)
    assert "cannot be broadcast" in capfd.readouterr().err
    assert (tmp_path / "p0.png").is_file() and not (tmp_path / "p1.png").exists()


def _interrupted() -> None:
    """A drawing job that a terminal's Ctrl-C reaches (the whole foreground group)."""
    import os
    import signal
    import time

    os.kill(os.getpid(), signal.SIGINT)
    time.sleep(0.05)


def test_a_ctrl_c_is_the_commands_not_a_drawers() -> None:
    """A drawer died of the terminal's SIGINT with a KeyboardInterrupt traceback printed
    over the command's own lines; it ignores SIGINT now (the command ends the drawers)."""
    import multiprocessing

    child = multiprocessing.get_context("fork").Process(target=drawers._alone,
                                                        args=(_interrupted, ()))
    child.start()
    child.join(10)
    assert child.exitcode == 0
