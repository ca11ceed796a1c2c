"""The study of the final error from rendered images (benchmarks.perf.image_floor)."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.perf import image_floor
from benchmarks.study.scenario import load_scenario
from hexapod.fk import forward_kinematics
from hexapod.geometry import deltalab
from vision.cameras import front_camera
from vision.image_sensor import ImageSensor
from vision.legs import observe_legs
from vision.render import Renderer


def _pose_dependent_bias(sensor: ImageSensor, rotation: np.ndarray,
                         translations: np.ndarray) -> float:
    """RMS over the edges of the standard deviation, over the poses, of the offset of
    each detected edge from the true one at its middle [px]."""
    cam = sensor.true_camera
    offsets = []
    for t in translations:
        obs = observe_legs(cam, sensor.geometry, rotation, t)
        m = sensor.measure(rotation, t, predicted_normals=obs.normals)
        assert m.edge_visible.all()
        mid = sensor.detector.predicted_segments(
            sensor.predict(rotation, t).with_normals(obs.normals)).mean(axis=2)
        off = []
        for n in (m.normals, obs.normals):
            line = n @ np.linalg.inv(cam.K)
            line /= np.linalg.norm(line[..., :2], axis=-1, keepdims=True)
            off.append(np.sum(line[..., :2] * mid, -1) + line[..., 2])
        offsets.append(off[0] - off[1])
    return float(np.sqrt(np.mean(np.var(np.array(offsets), axis=0))))


def test_exact_rendering_has_a_smaller_pose_dependent_bias_than_the_fallback() -> None:
    """Noise-free images of the seed-002 goal slid sideways over 2 mm (a few pixels of
    edge motion): the detected edges' offset from the truth varies less from pose to
    pose with the exact-coverage renderer than with OpenCV's anti-aliased polygons (the
    fallback the floor study compares against)."""
    g = deltalab()
    cam = front_camera(g)
    sol = forward_kinematics(g, np.array([375.0, 375.0, 475.0, 375.0, 375.0, 475.0]) * 1e-3)
    translations = sol.translation + np.outer(np.linspace(0.0, 2e-3, 11), [0.0, 1.0, 0.0])
    exact = ImageSensor(cam, cam, g, 0, blur_px=0.8, noise_std=0.0)
    fallback = ImageSensor(cam, cam, g, 0, blur_px=0.8, noise_std=0.0)
    fallback.renderer = Renderer(cam, g, fallback.renderer.style, 0, use_compiled=False)
    assert exact.renderer.exact and not fallback.renderer.exact
    assert (_pose_dependent_bias(exact, sol.rotation, translations)
            < _pose_dependent_bias(fallback, sol.rotation, translations))


def test_exact_features_reach_the_goal_despite_the_calibration_error() -> None:
    sc = load_scenario("andreff2006-images")
    row = image_floor.run_variant(sc, "exact-both", [c.label for c in sc.controllers].index(
        "leg-edge"), trials=1)
    assert row.converged == 1 and row.tail_converged == 1
    assert row.rot_max_deg < 1e-6 and row.pos_max_mm < 1e-6
    assert "| 1/1 | 1/1 |" in image_floor.format_rows([row])


def test_bad_arguments(capsys: pytest.CaptureFixture[str]) -> None:
    for argv, fragment in ((["--variants", "shiped"], "unknown ['shiped']"),
                           (["--controller", "leg-edgy"], "'leg-edgy' is not in"),
                           (["--trials", "0"], "--trials must be >= 1")):
        with pytest.raises(SystemExit):
            image_floor.main(argv)
        assert fragment in capsys.readouterr().err
