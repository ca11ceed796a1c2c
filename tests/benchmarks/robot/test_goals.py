"""The servo's batch of one camera's features (benchmarks/robot/goals.py)."""

from __future__ import annotations

import numpy as np

from benchmarks.robot.goals import feature_batch
from hexapod import deltalab, legs_in_frame
from vision.cameras.presets import fisheye_camera, front_camera, omni_camera
from vision.legs import leg_edges


def _features(camera):  # type: ignore[no-untyped-def]
    geo = deltalab()
    legs = legs_in_frame(geo, np.eye(3), np.array([0.0, 0.0, geo.home_height]),
                         camera.camera_from_base)
    normals, _ = leg_edges(legs.base_points, legs.directions, geo.leg_radius)

    class Features:
        pass

    f = Features()
    f.normals = normals  # type: ignore[attr-defined]
    f.edge_visible = np.ones((6, 2), dtype=bool)  # type: ignore[attr-defined]
    return f


def test_image_lines_for_every_perspective_family_camera_as_the_simulator() -> None:
    """A fisheye (kind 'fisheye', perspective family) gets image lines like a pinhole
    camera; the unified camera gets none."""
    for camera in (front_camera(), fisheye_camera()):
        batch = feature_batch(camera, _features(camera))
        assert batch.lines is not None, camera.kind
        expected = camera.normal_to_line(_features(camera).normals)
        np.testing.assert_array_equal(batch.lines[0], expected)
    omni = omni_camera()
    assert feature_batch(omni, _features(omni)).lines is None
