"""hexapod-bench calibrate, and studies that control with calibrated base points."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from benchmarks.calibrate import load_calibrated_base_points
from benchmarks.cli import main as cli_main
from benchmarks.runner import read_results
from hexapod.exceptions import ConfigFileError
from vision.cameras import front_camera


def _scenario(tmp_path: Path, noise: str = 'model = "none"') -> Path:
    path = tmp_path / "cal.toml"
    path.write_text('name = "cal"\nseed = 4\ntrials = 2\ncontrollers = ["leg-edge"]\n'
                    f'[noise]\n{noise}\n[task]\nmax_steps = 60\n')
    return path


def test_noiseless_calibration_recovers_the_base_points(tmp_path: Path) -> None:
    out = tmp_path / "out"
    assert cli_main(["calibrate", str(_scenario(tmp_path)), "--out", str(out),
                     "--repeat", "2"]) == 0
    doc = json.loads((out / "calibration.json").read_text())
    assert doc["max_error_mm"] < 1e-6
    assert doc["repetitions"] == 2 and len(doc["points"]) == 1
    points = load_calibrated_base_points(out / "calibrated.toml")
    cam = front_camera()
    from hexapod import deltalab

    truth = cam.camera_from_base.apply(deltalab().base_points)
    np.testing.assert_allclose(points, truth, atol=1e-8)


def test_noisy_calibration_sweeps_and_reports_errors(tmp_path: Path) -> None:
    scen = _scenario(tmp_path, 'model = "rotation"\namplitude_deg = [0.01, 0.1]')
    out = tmp_path / "out"
    assert cli_main(["calibrate", str(scen), "--out", str(out), "--repeat", "3",
                     "--solver", "irls"]) == 0
    doc = json.loads((out / "calibration.json").read_text())
    small, large = (p["median_error_mm"] for p in doc["points"])
    assert 0 < small < large, "more noise, larger calibration error"
    assert doc["max_error_mm"] >= max(p["max_error_mm"] for p in doc["points"]) - 1e-12


def test_run_with_a_calibration_file(tmp_path: Path) -> None:
    cal = tmp_path / "cal"
    scen = _scenario(tmp_path)
    assert cli_main(["calibrate", str(scen), "--out", str(cal)]) == 0
    out = tmp_path / "run"
    assert cli_main(["run", str(scen), "--out", str(out), "--no-progress", "--calibration",
                     str(cal / "calibrated.toml")]) == 0
    rows = read_results(out)
    assert all(r["calibration_max_error_mm"] < 1e-6 for r in rows)


def test_bad_calibration_file(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text("base_points_camera_mm = [[1.0, 2.0, 3.0]]\n")
    with pytest.raises(ConfigFileError, match="shape"):
        load_calibrated_base_points(bad)
    bad.write_text("base_point_camera_mm = []\n")
    with pytest.raises(ConfigFileError, match="base_points_camera_mm"):
        load_calibrated_base_points(bad)
    scen = _scenario(tmp_path)
    assert cli_main(["run", str(scen), "--out", str(tmp_path / "x"), "--calibration",
                     str(tmp_path / "missing.toml")]) == 2


def test_viz_replays_a_recorded_trial_to_html(tmp_path: Path) -> None:
    scen = _scenario(tmp_path)
    out = tmp_path / "run"
    assert cli_main(["run", str(scen), "--out", str(out), "--no-progress", "--record", "1"]) == 0
    html = tmp_path / "trial0.html"
    assert cli_main(["viz", str(out), "--trial", "0", "--html", str(html)]) == 0
    assert html.stat().st_size > 10_000 and html.with_suffix(".png").exists()
    assert cli_main(["viz", str(out), "--trial", "7", "--html", str(html)]) == 2


def test_calibrate_from_a_user_observation_file(tmp_path: Path) -> None:
    from hexapod import deltalab
    from vision.calibration import collect_observations

    cam = front_camera()
    data = collect_observations(deltalab(), cam, "random:30", None, 5)
    obs = tmp_path / "observations.json"
    data.save(obs)
    out = tmp_path / "out"
    assert cli_main(["calibrate", str(_scenario(tmp_path)), "--out", str(out),
                     "--observations", str(obs)]) == 0
    points = load_calibrated_base_points(out / "calibrated.toml")
    truth = cam.camera_from_base.apply(deltalab().base_points)
    np.testing.assert_allclose(points, truth, atol=1e-8)
    broken = tmp_path / "broken.json"
    broken.write_text(obs.read_text().replace('"lengths_mm"', '"length_mm"'))
    assert cli_main(["calibrate", str(_scenario(tmp_path)), "--out", str(out),
                     "--observations", str(broken)]) == 2
