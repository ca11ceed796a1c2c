"""The tracking section's figures: one figure per kind redrawn for every sweep point
gives the image of a new figure per point, the force limits drawn or not per point."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from matplotlib.image import imread

from benchmarks.study.plots import AS_IS, save_figure
from benchmarks.study.tracking_figures import forces_figure, forces_plots, tracking_plots


def _record(folder: Path, point: int, controller: str, scale: float) -> None:
    t = np.linspace(0, 2, 120)
    forces = scale * np.sin(np.outer(t, np.arange(1, 7)))
    np.savez(folder / f"s__p{point}__{controller}__00000.npz", controller=controller, t=t,
             leg_forces=forces, force_limit=np.full(6, 10.0),
             position_error=1e-3 * scale * np.abs(np.sin(t)),
             orientation_error=1e-4 * np.abs(np.cos(t)))


@pytest.mark.slow
def test_redrawn_force_and_tracking_figures_are_new_figures(tmp_path: Path) -> None:
    """Points 0 and 2 stay far below the 10 N limits (no dashed limits, the limit in the
    title), point 1 nears them (dashed limits): each image is that of a new figure."""
    run = tmp_path / "run"
    (run / "trials").mkdir(parents=True)
    for point, scale in enumerate((2.0, 9.0, 3.0)):
        for controller in ("ctc", "joint"):
            _record(run / "trials", point, controller, scale)
    forces = forces_plots(run, "s", [0, 1, 2])
    assert forces == {p: f"s_p{p}_forces.png" for p in range(3)}
    assert tracking_plots(run, "s", [0, 1, 2]) == {p: f"s_p{p}_tracking.png" for p in range(3)}
    titles = []
    for p in range(3):
        fig = forces_figure(run, "s", p)
        titles.append(fig.axes[0].get_title())
        save_figure(fig, tmp_path, f"new{p}.png", AS_IS)
        assert np.array_equal(imread(run / forces[p]), imread(tmp_path / f"new{p}.png")), p
    assert titles == ["ctc: drive forces [N] (limit 10)", "ctc: drive forces [N]",
                      "ctc: drive forces [N] (limit 10)"]
    assert forces_plots(run, "s", [3]) == {}  # no recorded trial there
