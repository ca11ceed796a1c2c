"""Scenarios through the lens models: the built-in fisheye-close scenario and
``[camera] file =`` naming a calibration file (Kalibr, ROS, OpenCV) with a pose."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from benchmarks.exceptions import ScenarioError
from benchmarks.sim.world import estimated_camera
from benchmarks.study.scenario import builtin_scenarios, load_scenario
from hexapod import deltalab
from vision.cameras import (
    DoubleSphereCamera,
    FisheyeCamera,
    PerspectiveCamera,
    camera_preset,
    fisheye_camera,
    save_kalibr_camera,
)


def test_fisheye_close_is_the_fisheye_preset_modelled_and_ignored() -> None:
    sc = load_scenario(builtin_scenarios()["fisheye-close"])
    cam = sc.camera_data
    assert isinstance(cam, FisheyeCamera)
    ref = fisheye_camera(deltalab())
    assert np.allclose(cam.K, ref.K) and np.array_equal(cam.distortion, ref.distortion)
    assert np.allclose(cam.camera_from_base.as_matrix(), ref.camera_from_base.as_matrix(),
                       atol=1e-9)
    assert sc.sweep_axes["calibration_error.distortion_percent"] == [0.0, 100.0]
    assert estimated_camera(cam, 0.0) is cam
    ignored = estimated_camera(cam, 100.0)
    assert type(ignored) is PerspectiveCamera and np.array_equal(ignored.K, cam.K)


def test_camera_file_takes_a_kalibr_chain_with_a_pose(tmp_path: Path) -> None:
    ds = DoubleSphereCamera(fisheye_camera().K, 1024, 780, distortion=(-0.1, 0.55))
    save_kalibr_camera(ds, tmp_path / "camchain.yaml")
    study = tmp_path / "s.toml"
    study.write_text('name = "ds"\ncontrollers = ["leg-edge"]\n[camera]\n'
                     'file = "camchain.yaml"\npose = "fisheye"\n')
    cam = load_scenario(study).camera_data
    assert isinstance(cam, DoubleSphereCamera) and cam.distortion.tolist() == [-0.1, 0.55]
    assert np.allclose(cam.camera_from_base.as_matrix(),
                       camera_preset("fisheye", deltalab()).camera_from_base.as_matrix())
    # a camera TOML file gives its own pose: no pose key with it
    fisheye_camera().to_toml(tmp_path / "cam.toml")
    study.write_text('name = "x"\ncontrollers = ["leg-edge"]\n[camera]\n'
                     'file = "cam.toml"\npose = "front"\n')
    with pytest.raises(ScenarioError, match="only with 'opencv' or a calibration 'file'") as e:
        load_scenario(study)
    assert e.value.key == "camera.pose"


def test_a_fisheye_lens_is_modelled_or_ignored_not_in_part(tmp_path: Path) -> None:
    fisheye_camera().to_toml(tmp_path / "cam.toml")
    study = tmp_path / "s.toml"
    study.write_text('name = "x"\ncontrollers = ["leg-edge"]\n[camera]\nfile = "cam.toml"\n'
                     "[calibration_error]\ndistortion_percent = [0.0, 50.0]\n")
    with pytest.raises(ScenarioError, match="not in part") as info:
        load_scenario(study)
    assert info.value.key == "calibration_error.distortion_percent"


def test_a_partial_lens_error_of_a_fisheye_preset_is_refused_naming_the_key() -> None:
    """A preset's lens was not checked: check passed, and the run failed with no file or
    key (leaving a directory that refused the mended study)."""
    from benchmarks.study.scenario import parse_scenario

    with pytest.raises(ScenarioError) as info:
        parse_scenario({"name": "x", "controllers": ["leg-edge"],
                        "camera": {"preset": "fisheye"},
                        "calibration_error": {"distortion_percent": [0.0, 50.0]}}, "fe.toml")
    assert info.value.key == "calibration_error.distortion_percent"
    assert "50.0: distortion: a fisheye lens is modelled (0 %) or ignored (100 %)" in \
        str(info.value) and "fe.toml" in str(info.value)
    parse_scenario({"name": "x", "controllers": ["leg-edge"], "camera": {"preset": "front"},
                    "calibration_error": {"distortion_percent": 50.0}})  # (partly modelled)
