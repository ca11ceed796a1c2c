"""From encoder lengths and forces to samples: refusals with the evidence."""

from __future__ import annotations

import numpy as np
import pytest

from hexapod.dynamics.identification.processing import samples
from hexapod.exceptions import IdentificationError
from hexapod.geometry import preset


def test_bad_records_are_refused() -> None:
    g = preset("deltalab")
    q = np.full((3000, 6), g.q_mid)
    with pytest.raises(IdentificationError, match="Nyquist"):
        samples(g, 1e-3, q, np.zeros_like(q), cutoff_hz=600.0)
    with pytest.raises(IdentificationError, match="too short"):
        samples(g, 1e-3, q[:100], np.zeros((100, 6)))
    with pytest.raises(IdentificationError, match=r"\(3000, 6\) and \(3000, 5\)"):
        samples(g, 1e-3, q, np.zeros((3000, 5)))
    bad = q.copy()
    bad[1234, 3] = np.inf
    with pytest.raises(IdentificationError, match=r"sample 1234: the length of leg 3 is "
                                                  r"inf \[m\]"):
        samples(g, 1e-3, bad, np.zeros_like(q))
    forces = np.zeros_like(q)
    forces[2345, 1] = np.nan
    with pytest.raises(IdentificationError, match=r"sample 2345: the force of leg 1 is nan "
                                                  r"\[N\]"):
        samples(g, 1e-3, q, forces)


def test_a_platform_at_rest_has_zero_twist_and_acceleration() -> None:
    g = preset("deltalab")
    q = np.full((3000, 6), g.q_mid)
    s = samples(g, 1e-3, q, np.ones_like(q))
    np.testing.assert_allclose(s.twist, 0, atol=1e-10)  # filter rounding
    np.testing.assert_allclose(s.acc, 0, atol=1e-8)  # the forward kinematics to 1e-12 m
    np.testing.assert_allclose(s.forces, 1.0, atol=1e-9)
    assert not s.mask().any()  # no leg moves: no equation kept
