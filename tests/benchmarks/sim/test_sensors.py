"""The camera's batch of edges seen by a camera (benchmarks/sim/sensors.py), as the
simulator and the servo session build it."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from benchmarks.sim.sensors import GeometricSensor, reads_features, seen_edges
from benchmarks.sim.world import load_camera, load_geometry, make_trials
from benchmarks.study.scenario import parse_scenario
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


@pytest.mark.parametrize("noise", [{"model": "rotation", "amplitude_deg": 0.05},
                                   {"model": "rotation", "amplitude_deg": 0.05,
                                    "dropout_probability": 0.2}])
def test_a_controller_of_the_encoders_gets_the_visibility_without_features(
        noise: dict[str, Any]) -> None:
    """A loop whose controller reads no camera feature (:func:`reads_features`) measures
    the visibility the features' measurement gives, draws no noise and gives no features;
    where the noise changes the visibility (dropout), the features are measured anyway."""
    from controllers.registry import registry

    sc = parse_scenario({"name": "s", "seed": 4, "trials": 3, "controllers": ["joint-space"],
                         "camera": {"preset": "front"}, "noise": noise})
    g = load_geometry(sc)
    setups = [s for s in make_trials(sc, [0, 1, 2], g, load_camera(sc, g))
              if not isinstance(s, Exception)]
    assert len(setups) == 3
    R = np.array([s.start_rotation for s in setups])
    t = np.array([s.start_translation for s in setups])
    rows = np.arange(3)
    full, lean = (GeometricSensor.of_trials(sc, setups) for _ in range(2))
    lean.features = reads_features(registry.create("computed-torque"))
    assert reads_features(registry.create("leg-edge")) and not lean.features
    state = [rng.bit_generator.state for rng in lean.generators.rngs]
    a, b = full.observe(rows, R, t), lean.observe(rows, R, t)
    np.testing.assert_array_equal(a.edge_visible, b.edge_visible)
    np.testing.assert_array_equal(a.direction_visible, b.direction_visible)
    if "dropout_probability" in noise:
        assert b.normals is not None
        np.testing.assert_array_equal(a.normals, b.normals)
    else:
        assert b.normals is None and b.lines is None and b.directions is None
        assert [rng.bit_generator.state for rng in lean.generators.rngs] == state


def test_only_a_declared_encoders_only_controller_goes_without_features() -> None:
    """The base class's default ``features`` is no declaration: a plugin (a subclass or a
    foreign object) that never set it may read every field; one that declares only
    ``lengths`` does not, through the tracking wrapper too."""
    from controllers.base import Controller
    from controllers.batch import ForeignController
    from controllers.registry import registry
    from controllers.tracking import TrackingController

    class Silent(Controller):
        name = "silent"

    class Encoders(Controller):
        name = "encoders"
        features = frozenset({"lengths"})

    class Foreign:
        name = "foreign"

        def reset(self, context: Any) -> None: ...

        def step(self, observation: Any) -> Any: ...

    class ForeignEncoders(Foreign):
        features = frozenset({"lengths"})

    assert reads_features(Silent()) and reads_features(ForeignController(Foreign))
    assert not reads_features(Encoders())
    assert not reads_features(ForeignController(ForeignEncoders))
    assert reads_features(TrackingController(ForeignController(Foreign)))
    assert not reads_features(TrackingController(registry.create("computed-torque")))
    assert reads_features(TrackingController(registry.create("leg-edge-ctc")))
