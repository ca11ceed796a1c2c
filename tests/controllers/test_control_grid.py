"""The one control grid of the tracking controllers (:mod:`controllers.control_grid`)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from controllers.control_grid import GRID_TOLERANCE, chunks, grid_step, grid_times


@pytest.mark.parametrize("duration", [0.0, 0.02, 0.5, 0.51, 1.0, 2.345, 7.2])
def test_the_grid_reaches_a_period_past_the_references_end(duration: float) -> None:
    """``k dt`` from 0, every instant a step of the grid, the last one at least a period
    past the end (where a computed-torque law switches to the reference at rest) and the
    one before it not (no instant more than needed)."""
    dt = 0.02
    t = grid_times(duration, dt)
    assert t[0] == 0.0
    assert np.array_equal(t, dt * np.arange(len(t)))
    assert t[-1] >= duration + dt - 1e-12
    assert t[-2] < duration + dt - 1e-12
    assert [grid_step(float(x), dt) for x in t] == list(range(len(t)))


def test_an_instant_is_on_the_grid_within_the_tolerance_only() -> None:
    dt = 0.02
    assert grid_step(3 * dt + 0.5 * GRID_TOLERANCE, dt) == 3
    assert grid_step(3 * dt - 0.5 * GRID_TOLERANCE, dt) == 3
    assert grid_step(3 * dt + 10 * GRID_TOLERANCE, dt) == -1
    assert grid_step(0.5 * dt, dt) == -1
    assert grid_step(-dt, dt) == -1  # before the reference's start


def test_chunks_group_by_key_in_order_and_cut_at_the_size() -> None:
    keys = ["a", "b", "a", "a", "b", "a", "c"]
    assert chunks(keys, 2) == [[0, 2], [3, 5], [1, 4], [6]]
    assert chunks(keys, None) == [[0, 2, 3, 5], [1, 4], [6]]
    assert chunks([], 3) == []
    n = 21
    got = chunks([k % 2 for k in range(n)], 4)
    assert sorted(i for c in got for i in c) == list(range(n))
    assert max(len(c) for c in got) == 4
    assert len(got) == math.ceil(11 / 4) + math.ceil(10 / 4)
