"""Shared fixtures: the reference robot, another robot, seeded generators."""

from __future__ import annotations

import numpy as np
import pytest

from hexapod import HexapodGeometry, deltalab
from hexapod.geometry import circular_points


@pytest.fixture
def geometry() -> HexapodGeometry:
    """The reference robot of MATH.md section 9."""
    return deltalab()


@pytest.fixture
def other_geometry() -> HexapodGeometry:
    """A robot that is not the reference one: irregular joints, off-plane points."""
    rng = np.random.default_rng(1234)
    a = np.array([10, 50, 130, 170, 250, 290], dtype=float)
    b = np.array([40, 80, 160, 200, 280, 320], dtype=float)
    base = circular_points(0.31, np.deg2rad(a + rng.uniform(-3, 3, 6)))
    base[:, 2] = rng.uniform(-0.01, 0.01, 6)
    plat = circular_points(0.17, np.deg2rad(b + rng.uniform(-3, 3, 6)))
    plat[:, 2] = rng.uniform(-0.01, 0.01, 6)
    return HexapodGeometry(base, plat, (0.38, 0.56), leg_radius=0.02, name="other")


@pytest.fixture
def rng() -> np.random.Generator:
    """A seeded generator."""
    return np.random.default_rng(20261122)
