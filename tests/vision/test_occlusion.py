"""The compiled occlusion test equals the numpy one (itself checked by brute force)."""

from __future__ import annotations

import numpy as np

from hexapod import Transform, legs_in_frame, sample_poses
from hexapod.geometry import HexapodGeometry
from hexapod.se3 import look_at
from vision.legs import leg_edges, limb_points, occluded_by_legs
from vision.occlusion import occluded_by_legs_compiled


def test_compiled_occlusion_matches_numpy(geometry: HexapodGeometry,
                                          rng: np.random.Generator) -> None:
    R, t = sample_poses(geometry, 60, rng=rng, max_angle=0.3, max_translation=0.1)
    total = 0
    for eye in ([0.7, 0.0, 0.25], [0.0, 0.6, 0.1], [0.05, 0.02, 0.0]):
        Rc = look_at(np.array(eye), np.array([0.0, 0.0, 0.2]), np.array([0.0, 0.0, 1.0]))
        T = Transform(Rc.T, -Rc.T @ np.array(eye))
        legs = legs_in_frame(geometry, R, t, T)
        n, _ = leg_edges(legs.base_points, legs.directions, geometry.leg_radius)
        s = (np.arange(12) + 0.5) / 12
        P = limb_points(legs.base_points, legs.directions, geometry.leg_radius, legs.lengths,
                        n, s)
        expected = occluded_by_legs(P, legs.base_points, legs.directions, legs.lengths,
                                    geometry.leg_radius)
        got = occluded_by_legs_compiled(P, legs.base_points, legs.directions, legs.lengths,
                                        geometry.leg_radius)
        assert got.shape == expected.shape
        np.testing.assert_array_equal(got, expected)
        total += int(expected.sum())
    assert total > 100, "the poses must include occlusions for the test to mean something"
