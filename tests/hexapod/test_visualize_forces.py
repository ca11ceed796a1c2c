"""Leg forces in the viewer (records of the dynamic world): colours per drive force, the
replayed animation colours every rod, the curves gain a force panel, bad shapes refused."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hexapod.exceptions import RecordError
from hexapod.geometry import deltalab
from hexapod.model import LEG_ROD_COLOR
from hexapod.visualize import load_trial, plot_trial, replay_html, save_trial, synthetic_record
from hexapod.visualize.forces import PULL_COLOR, PUSH_COLOR, SATURATED_COLOR, force_colours


def test_force_colours_run_from_rest_to_push_pull_and_saturation() -> None:
    limits = np.full(6, 200.0)
    c = force_colours(np.array([0.0, 100.0, -100.0, 200.0, -250.0, np.nan]), limits)
    np.testing.assert_allclose(c[0], LEG_ROD_COLOR)
    np.testing.assert_allclose(c[1], 0.5 * (LEG_ROD_COLOR + PUSH_COLOR))
    np.testing.assert_allclose(c[2], 0.5 * (LEG_ROD_COLOR + PULL_COLOR))
    np.testing.assert_allclose(c[3], SATURATED_COLOR)
    np.testing.assert_allclose(c[4], SATURATED_COLOR)
    np.testing.assert_allclose(c[5], LEG_ROD_COLOR)  # a NaN force draws as no force
    assert force_colours(np.zeros((7, 6)), limits).shape == (7, 6, 4)


def _with_forces(record):
    T = record.frames
    forces = 150.0 * np.sin(np.linspace(0, 3, T))[:, None] * np.linspace(-1, 1, 6)
    return {**record.arrays, "leg_forces": forces, "force_limit": np.full(6, 120.0)}


@pytest.mark.slow
def test_a_dynamic_record_replays_with_its_forces(tmp_path: Path) -> None:
    record = synthetic_record(deltalab())
    path = save_trial(tmp_path / "dyn.npz", **_with_forces(record))
    dyn = load_trial(path)
    assert dyn["leg_forces"].shape == (record.frames, 6)
    plain_html = replay_html(record, tmp_path / "plain.html").read_text()
    dyn_html = replay_html(dyn, tmp_path / "dyn.html").read_text()
    # six rods' colours in every frame of the animation
    assert len(dyn_html) > len(plain_html) + 1000
    import matplotlib.image as mpimg

    plain_png = mpimg.imread(plot_trial(record, tmp_path / "plain.png"))
    dyn_png = mpimg.imread(plot_trial(dyn, tmp_path / "dyn.png"))
    assert dyn_png.shape[1] > 1.25 * plain_png.shape[1]  # a fourth panel: the forces


@pytest.mark.parametrize(("change", "key"), [
    ({"leg_forces": np.zeros((3, 6))}, "leg_forces"),
    ({"force_limit": np.zeros(5)}, "force_limit"),
])
def test_bad_force_arrays_are_refused_naming_the_key(tmp_path: Path, change: dict,
                                                     key: str) -> None:
    record = synthetic_record(deltalab())
    with pytest.raises(RecordError, match=key):
        save_trial(tmp_path / "bad.npz", **{**_with_forces(record), **change})
    arrays = dict(record.arrays, leg_forces=np.zeros((record.frames, 6)))
    with pytest.raises(RecordError, match="force_limit"):
        save_trial(tmp_path / "bad.npz", **arrays)
