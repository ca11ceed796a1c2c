"""The compiled leg-edge kernel gives the same commands as the numpy oracle."""

from __future__ import annotations

import numpy as np
import pytest

from controllers.base import ControllerContext, Goal, Observation, registry
from hexapod import HexapodGeometry, sample_poses
from tests.controllers.numpy_law import numpy_law
from vision.cameras import front_camera, omni_camera
from vision.legs import observe_legs


@pytest.mark.parametrize("make_camera", [front_camera, omni_camera])
def test_compiled_kernel_equals_numpy(make_camera: object, other_geometry: HexapodGeometry,
                                      rng: np.random.Generator) -> None:
    g = other_geometry
    cam = make_camera(g)  # type: ignore[operator]
    R, t = sample_poses(g, 12, rng=rng, max_translation=0.05, max_angle=0.15)
    obs_all = observe_legs(cam, g, R, t, occlusion=False)
    goal = Goal(normals=obs_all.normals[0], lines=None if obs_all.lines is None
                else obs_all.lines[0], directions=obs_all.directions[0],
                lengths=obs_all.lengths[0], rotation=R[0], translation=t[0],
                edge_visible=np.ones((6, 2), dtype=bool))
    ctx = ControllerContext(cam.camera_from_base.apply(g.base_points) + 1e-3, g, cam, 0.02,
                            goal)
    fast = registry.create("leg-edge")
    slow = numpy_law("leg-edge")
    fast.reset(ctx)
    slow.reset(ctx)
    for k in range(1, 12):
        obs = Observation(k * 0.02, obs_all.lengths[k], obs_all.normals[k],
                          None if obs_all.lines is None else obs_all.lines[k],
                          obs_all.directions[k])
        a, b = fast.step(obs), slow.step(obs)
        assert a.ok and b.ok
        np.testing.assert_allclose(a.velocities, b.velocities, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(a.error, b.error, rtol=1e-12, atol=1e-15)
        assert a.rank == b.rank == 6
        np.testing.assert_allclose(a.condition, b.condition, rtol=1e-8)
