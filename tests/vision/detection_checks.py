"""A check shared by the vision tests: two detections are the same."""

from __future__ import annotations

from typing import Any

import numpy as np


def same_detection(a: Any, b: Any) -> None:
    """Assert that two detections (compiled and numpy paths) agree: the same edges and
    point counts, normals to 1e-12, residuals and points to 1e-9, NaN where NaN."""
    assert np.array_equal(a.edge_visible, b.edge_visible)
    assert np.array_equal(a.n_points, b.n_points)
    m = a.edge_visible
    assert np.allclose(a.normals[m], b.normals[m], rtol=0, atol=1e-12)
    assert np.all(np.isnan(a.normals[~m])) and np.all(np.isnan(b.normals[~m]))
    assert np.allclose(a.residual[m], b.residual[m], rtol=0, atol=1e-9)
    assert np.array_equal(np.isnan(a.points), np.isnan(b.points))
    assert np.allclose(a.points, b.points, rtol=0, atol=1e-9, equal_nan=True)
