"""The camera's batch of edges seen by a camera (benchmarks/sim/sensors.py), as the
simulator and the servo session build it."""

from __future__ import annotations

import numpy as np

from benchmarks.sim.sensors import seen_edges
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
        f = _features(camera)
        batch = seen_edges(camera, f.normals[None], f.edge_visible[None])
        assert batch.lines is not None, camera.kind
        np.testing.assert_array_equal(batch.lines[0], camera.normal_to_line(f.normals))
    omni = omni_camera()
    f = _features(omni)
    assert seen_edges(omni, f.normals[None], f.edge_visible[None]).lines is None
