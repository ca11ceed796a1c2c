"""Tests of vision.calibration: exact recovery, order invariance, robustness to
outliers, rigid fit and scale, degenerate sets, observation files, the study."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from hexapod import ConfigFileError, HexapodGeometry, ShapeError, Transform, sample_poses
from hexapod.se3 import exp_so3, look_at
from vision.calibration import (
    CalibrationData,
    calibrate,
    calibrate_base_points,
    calibrate_in_world,
    calibration_study,
    collect_observations,
    configuration_poses,
    error_summary,
    point_errors,
    rigid_fit,
    rotation_noise,
    scale_correction,
)
from vision.cameras import front_camera, omni_camera
from vision.exceptions import CalibrationError


def front_pose() -> Transform:
    """Camera 0.7 m in front of the base centre, looking at the legs (built independently
    of the camera presets)."""
    eye = np.array([0.7, 0.0, 0.25])
    base_R_cam = look_at(eye, np.array([0.0, 0.0, 0.2]), np.array([0.0, 0.0, 1.0]))
    return Transform(base_R_cam, eye).inverse()


def omni_pose() -> Transform:
    """Camera at the base centre looking up (an omnidirectional camera's mirror frame),
    slightly rotated about its axis so that no axis is special."""
    return Transform(exp_so3(np.array([0.0, 0.0, 0.3])), np.array([0.0, 0.0, -0.01]))


POSES = {"front": front_pose, "omni": omni_pose}


@pytest.mark.parametrize("pose", ["front", "omni"])
@pytest.mark.parametrize("which", ["geometry", "other_geometry"])
def test_exact_recovery(pose: str, which: str, request: pytest.FixtureRequest) -> None:
    geo: HexapodGeometry = request.getfixturevalue(which)
    T = POSES[pose]()
    # The other robot reaches few extremal configurations: use random ones for it.
    configs = "extremal" if which == "geometry" else ("random", 30)
    data = collect_observations(geo, T, configs, rng=3)
    truth = T.apply(geo.base_points)
    for method in ("lstsq", "irls"):
        res = calibrate_base_points(data, geo.leg_radius, method=method)  # type: ignore[arg-type]
        assert point_errors(res.base_points, truth).max() < 1e-9
        assert np.nanmax(np.abs(res.residuals)) < 1e-12
        assert res.equations.tolist() == [2 * data.n_configurations] * 6
        assert not res.outliers.any()
    assert np.all(res.singular_value_ratio > 1e-3)


@pytest.mark.parametrize("camera", [front_camera, omni_camera])
def test_exact_recovery_with_camera_visibility(geometry: HexapodGeometry, camera: object
                                               ) -> None:
    """With the camera models: image bounds and occlusions hide some edges."""
    cam = camera(geometry)  # type: ignore[operator]
    data = collect_observations(geometry, cam)
    res = calibrate_base_points(data, geometry.leg_radius, method="irls")
    truth = cam.camera_from_base.apply(geometry.base_points)
    assert point_errors(res.base_points, truth).max() < 1e-9
    assert res.equations.sum() == data.edge_visible.sum()
    if camera is front_camera:
        assert not data.edge_visible.all()  # legs hide each other from the front
        assert np.isnan(res.residuals[~data.edge_visible]).all()


def test_linear_system_from_leg_edges(geometry: HexapodGeometry) -> None:
    """Every simulated normal satisfies n.A = -r and n.u = 0 (MATH 4), independently
    of the solver."""
    T = front_pose()
    R, t = configuration_poses(geometry)
    data = collect_observations(geometry, T, poses=(R, t))
    A = T.apply(geometry.base_points)
    np.testing.assert_allclose(np.einsum("kijc,ic->kij", data.normals, A), -geometry.leg_radius,
                               atol=1e-15)
    np.testing.assert_allclose(np.linalg.norm(data.normals, axis=-1), 1.0, atol=1e-15)
    assert data.n_configurations == 64
    np.testing.assert_allclose(data.lengths.min(axis=0), geometry.q_min, atol=1e-10)
    np.testing.assert_allclose(data.lengths.max(axis=0), geometry.q_max, atol=1e-10)


@pytest.mark.parametrize("method", ["lstsq", "irls"])
def test_invariant_to_configuration_order(geometry: HexapodGeometry, rng: np.random.Generator,
                                          method: str) -> None:
    data = collect_observations(geometry, front_pose(), noise=rotation_noise(0.1), rng=rng)
    order = rng.permutation(data.n_configurations)
    a = calibrate_base_points(data, geometry.leg_radius, method=method)  # type: ignore[arg-type]
    b = calibrate_base_points(data.take(order), geometry.leg_radius,
                              method=method)  # type: ignore[arg-type]
    np.testing.assert_allclose(a.base_points, b.base_points, atol=1e-12)
    np.testing.assert_allclose(a.singular_values, b.singular_values, rtol=1e-12)
    np.testing.assert_allclose(a.residuals[order], b.residuals, atol=1e-15)
    # Noise moved the estimate: the comparison is not between two exact answers.
    truth = front_pose().apply(geometry.base_points)
    assert point_errors(a.base_points, truth).max() > 1e-5


def _inject_outliers(data: CalibrationData, rng: np.random.Generator, fraction: float
                     ) -> tuple[CalibrationData, np.ndarray]:
    """Rotate a fraction of the edge normals by 3 to 10 degrees (wrong edges)."""
    mask = rng.uniform(size=data.edge_visible.shape) < fraction
    axis = rng.normal(size=(*mask.shape, 3))
    axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
    angle = np.deg2rad(rng.uniform(3.0, 10.0, size=mask.shape))
    bad = np.einsum("...ij,...j->...i", exp_so3(axis * angle[..., None]), data.normals)
    normals = np.where(mask[..., None], bad, data.normals)
    return CalibrationData(normals, data.edge_visible, data.lengths), mask


@pytest.mark.parametrize("weight", ["huber", "tukey"])
def test_robust_solver_rejects_outliers(geometry: HexapodGeometry, rng: np.random.Generator,
                                        weight: str) -> None:
    T = front_pose()
    truth = T.apply(geometry.base_points)
    clean = collect_observations(geometry, T, noise=rotation_noise(0.01), rng=rng)
    data, mask = _inject_outliers(clean, rng, 0.1)
    plain = calibrate_base_points(data, geometry.leg_radius, method="lstsq")
    robust = calibrate_base_points(data, geometry.leg_radius, method="irls",
                                   weight=weight)  # type: ignore[arg-type]
    err_plain = point_errors(plain.base_points, truth)
    err_robust = point_errors(robust.base_points, truth)
    clean_err = point_errors(calibrate_base_points(clean, geometry.leg_radius).base_points,
                             truth)
    assert err_plain.max() > 0.1  # plain least squares is broken (> 100 mm) ...
    if weight == "tukey":  # ... Tukey is as good as least squares without the outliers,
        assert err_robust.max() < max(1e-3, 2 * clean_err.max())
    else:  # ... Huber keeps a bounded pull from each outlier (see calibrate_base_points).
        assert err_robust.max() < 5e-3
    # The injected outliers are the ones flagged (and only a few clean ones).
    assert robust.outliers[mask].mean() > 0.95
    assert robust.outliers[~mask].mean() < 0.05
    if weight == "tukey":
        assert np.all(robust.weights[robust.outliers] == 0.0)
    else:
        assert np.all(robust.weights[robust.outliers] < 1.0)
    assert np.all(robust.iterations > 0)
    assert np.all(np.isfinite(robust.thresholds)) and np.all(robust.thresholds > 0)
    # A fixed threshold [m] is honoured.
    fixed = calibrate_base_points(data, geometry.leg_radius, method="irls",
                                  weight=weight, threshold=1e-4)  # type: ignore[arg-type]
    np.testing.assert_array_equal(fixed.thresholds, 1e-4)
    assert point_errors(fixed.base_points, truth).max() < (2e-3 if weight == "tukey" else 5e-3)


def test_rigid_fit_recovers_transform(geometry: HexapodGeometry, rng: np.random.Generator
                                      ) -> None:
    R = exp_so3(rng.normal(size=3))
    t = rng.normal(size=3)
    cad = geometry.base_points
    est = cad @ R.T + t
    T, s, rms = rigid_fit(est, cad)
    np.testing.assert_allclose(T.rotation, R, atol=1e-12)
    np.testing.assert_allclose(T.translation, t, atol=1e-12)
    assert s == 1.0 and rms < 1e-12
    # With a scale (Umeyama).
    T2, s2, rms2 = rigid_fit(1.7 * cad @ R.T + t, cad, with_scale=True)
    np.testing.assert_allclose(T2.rotation, R, atol=1e-12)
    np.testing.assert_allclose(T2.translation, t, atol=1e-12)
    assert s2 == pytest.approx(1.7, abs=1e-12) and rms2 < 1e-12
    # With noise: optimal (any small perturbation of the fit is worse).
    noisy = est + rng.normal(scale=1e-3, size=est.shape)
    T3, _, rms3 = rigid_fit(noisy, cad)
    assert rms3 == pytest.approx(
        np.sqrt(np.mean(np.sum((noisy - T3.apply(cad)) ** 2, axis=1))), rel=1e-12)
    for _ in range(10):
        dR = exp_so3(rng.normal(scale=1e-3, size=3))
        dt = rng.normal(scale=1e-4, size=3)
        other = cad @ (dR @ T3.rotation).T + T3.translation + dt
        assert np.sqrt(np.mean(np.sum((noisy - other) ** 2, axis=1))) > rms3
    # A reflection is never returned.
    assert np.linalg.det(T3.rotation) == pytest.approx(1.0)


def test_rigid_fit_bad_input(geometry: HexapodGeometry) -> None:
    with pytest.raises(ShapeError):
        rigid_fit(geometry.base_points[:5], geometry.base_points)
    with pytest.raises(ShapeError):
        rigid_fit(geometry.base_points[:2], geometry.base_points[:2])
    line = np.outer(np.arange(6.0), [1.0, 0.0, 0.0])
    with pytest.raises(CalibrationError, match="collinear"):
        rigid_fit(line, line)


def test_scale_correction_recovers_radius_error(geometry: HexapodGeometry) -> None:
    T = front_pose()
    truth = T.apply(geometry.base_points)
    data = collect_observations(geometry, T)
    wrong_radius = geometry.leg_radius * 1.04  # the radius we believe is 4 % too large
    res = calibrate_base_points(data, wrong_radius)
    # The estimates are scaled about the projection centre.
    np.testing.assert_allclose(res.base_points, 1.04 * truth, atol=1e-10)
    assert scale_correction(res.base_points, geometry.base_points) == pytest.approx(1.04,
                                                                                    abs=1e-10)
    full = calibrate(data, wrong_radius, geometry.base_points, correct_scale=True)
    assert point_errors(full.base_points, truth).max() < 1e-9
    assert full.radius == pytest.approx(geometry.leg_radius, abs=1e-12)
    assert full.scale == pytest.approx(1.04, abs=1e-10)
    np.testing.assert_allclose(full.camera_from_base.rotation, T.rotation, atol=1e-9)
    np.testing.assert_allclose(full.camera_from_base.translation, T.translation, atol=1e-9)
    np.testing.assert_allclose(full.fitted_base_points, truth, atol=1e-9)
    assert full.fit_rms < 1e-9
    # Without the correction the scaled points stay (and the fit shows it).
    raw = calibrate(data, wrong_radius, geometry.base_points)
    assert raw.fit_rms > 1e-3
    json.dumps(full.to_dict())


def test_a_radius_or_cad_base_in_millimetres_is_refused(geometry: HexapodGeometry) -> None:
    """A leg radius or CAD base points in millimetres made base points 1000 times off (or
    a fit 270 m off) without a word: a base estimated more than 100 times (or less than a
    hundredth of) the CAD one is refused, saying which unit to use."""
    data = collect_observations(geometry, front_pose())
    for radius, cad, ratio in ((geometry.leg_radius * 1e3, geometry.base_points, "1000"),
                               (geometry.leg_radius, geometry.base_points * 1e3, "0.001")):
        with pytest.raises(CalibrationError, match=rf"the estimated base is {ratio} times "
                                                   r"the CAD base.*millimetres for metres"):
            calibrate(data, radius, cad)


def test_error_when_directions_parallel(geometry: HexapodGeometry) -> None:
    R, t = sample_poses(geometry, 1, rng=1)
    R = np.repeat(R, 10, axis=0)
    t = np.repeat(t, 10, axis=0)
    with pytest.raises(CalibrationError, match="singular values") as exc:
        calibrate_base_points(collect_observations(geometry, front_pose(), poses=(R, t)),
                              geometry.leg_radius)
    assert exc.value.leg == 0
    assert exc.value.singular_values is not None and exc.value.singular_values[2] < 1e-12
    assert "leg 0" in str(exc.value) and "ill-conditioned" in str(exc.value)
    # Nearly parallel: poses a few nanoradians apart.
    R2 = np.einsum("kij,kjl->kil", exp_so3(np.random.default_rng(0).normal(size=(10, 3))
                                           * 1e-9), R)
    with pytest.raises(CalibrationError):
        calibrate_base_points(collect_observations(geometry, front_pose(), poses=(R2, t)),
                              geometry.leg_radius)
    # Well separated directions are fine, and their conditioning is much better.
    ok = calibrate_base_points(collect_observations(geometry, front_pose()), geometry.leg_radius)
    assert ok.singular_value_ratio.min() > 1e-2


def test_error_when_too_few_configurations(geometry: HexapodGeometry) -> None:
    data = collect_observations(geometry, front_pose())
    with pytest.raises(CalibrationError, match="1 configuration") as exc:
        calibrate_base_points(data.take([5]), geometry.leg_radius)
    assert exc.value.leg == 0 and exc.value.configurations == 1
    visible = data.edge_visible.copy()
    visible[1:, 3, :] = False  # leg 3 seen in one configuration only
    with pytest.raises(CalibrationError, match="leg 3") as exc:
        calibrate_base_points(CalibrationData(data.normals, visible, data.lengths),
                              geometry.leg_radius)
    assert exc.value.equations == 2
    visible[:, 3, :] = False
    with pytest.raises(CalibrationError, match="0 configuration"):
        calibrate_base_points(CalibrationData(data.normals, visible, data.lengths),
                              geometry.leg_radius)


def test_bad_arguments(geometry: HexapodGeometry) -> None:
    data = collect_observations(geometry, front_pose(), ("random", 5), rng=1)
    with pytest.raises(ValueError, match="method"):
        calibrate_base_points(data, 0.015, method="svd")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="weight"):
        calibrate_base_points(data, 0.015, method="irls", weight="cauchy")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="radius"):
        calibrate_base_points(data, 0.0)
    with pytest.raises(ShapeError, match="normals"):
        CalibrationData(data.normals[:, :5], data.edge_visible, data.lengths)
    with pytest.raises(ShapeError, match="lengths"):
        CalibrationData(data.normals, data.edge_visible, data.lengths[:, :3])
    with pytest.raises(ValueError, match="configurations"):
        configuration_poses(geometry, "corners")
    with pytest.raises(ValueError, match="random:N"):
        configuration_poses(geometry, "random:many")


def test_collect_observations_noise_and_random(geometry: HexapodGeometry) -> None:
    T = front_pose()
    a = collect_observations(geometry, T, "random:20", rng=4)
    b = collect_observations(geometry, T, ("random", 20), rng=4)
    np.testing.assert_array_equal(a.normals, b.normals)
    assert a.n_configurations == 20
    noisy = collect_observations(geometry, T, "random:20", noise=rotation_noise(0.5), rng=4)
    # Different draws of poses are consumed first, then noise: same poses (same lengths).
    np.testing.assert_array_equal(noisy.lengths, a.lengths)
    angle = np.rad2deg(np.arccos(np.clip(np.sum(noisy.normals * a.normals, axis=-1), -1, 1)))
    assert 0.0 < angle.max() <= 0.5 + 1e-9
    assert np.median(angle) > 0.1
    np.testing.assert_allclose(np.linalg.norm(noisy.normals, axis=-1), 1.0, atol=1e-12)
    # Any callable is a noise model.
    flipped = collect_observations(geometry, T, "random:3", noise=lambda n, g: -n, rng=4)
    np.testing.assert_allclose(flipped.normals, -collect_observations(geometry, T, "random:3",
                                                                      rng=4).normals)


@pytest.mark.parametrize("suffix", [".json", ".npz"])
def test_file_round_trip(tmp_path: Path, geometry: HexapodGeometry, suffix: str) -> None:
    data = collect_observations(geometry, front_camera(geometry), noise=rotation_noise(0.05),
                                rng=2)
    assert not data.edge_visible.all()  # hidden edges go through the file too
    path = tmp_path / f"obs{suffix}"
    data.save(path)
    back = CalibrationData.load(path)
    np.testing.assert_array_equal(back.edge_visible, data.edge_visible)
    np.testing.assert_allclose(back.normals[data.edge_visible], data.normals[data.edge_visible],
                               rtol=0, atol=1e-15)
    np.testing.assert_allclose(back.lengths, data.lengths, atol=1e-15)
    assert back.source == str(path)
    a = calibrate_base_points(data, geometry.leg_radius)
    b = calibrate_base_points(back, geometry.leg_radius)
    np.testing.assert_allclose(a.base_points, b.base_points, atol=1e-12)


def _table(geometry: HexapodGeometry) -> dict:
    data = collect_observations(geometry, front_pose(), ("random", 3), rng=1)
    return data.to_dict()


def _load(tmp_path: Path, table: object) -> CalibrationData:
    path = tmp_path / "obs.json"
    path.write_text(json.dumps(table))
    return CalibrationData.load(path)


def test_file_errors(tmp_path: Path, geometry: HexapodGeometry) -> None:
    with pytest.raises(ConfigFileError, match="file not found"):
        CalibrationData.load(tmp_path / "none.json")
    (tmp_path / "bad.json").write_text("{normals: [}")
    with pytest.raises(ConfigFileError, match="not valid JSON") as exc:
        CalibrationData.load(tmp_path / "bad.json")
    assert exc.value.path == str(tmp_path / "bad.json")
    (tmp_path / "obs.txt").write_text("")
    with pytest.raises(ConfigFileError, match="unknown file type"):
        CalibrationData.load(tmp_path / "obs.txt")
    (tmp_path / "bad.npz").write_bytes(b"not a zip")
    with pytest.raises(ConfigFileError, match="NPZ") as exc:
        CalibrationData.load(tmp_path / "bad.npz")
    assert "pickle" not in str(exc.value)  # (numpy's text invited loading it unsafely)
    t = _table(geometry)
    upper = tmp_path / "MEASURED.JSON"  # the suffix in capitals: read as JSON
    upper.write_text(json.dumps(t))
    assert CalibrationData.load(upper).n_configurations == len(t["normals"])
    t["lengths_mm"][1][2] = None  # a null length: said where
    with pytest.raises(ConfigFileError, match=r"null, NaN or inf \(at index \[1, 2\]\)"):
        _load(tmp_path, t)
    with pytest.raises(ConfigFileError, match="top level"):
        _load(tmp_path, [1, 2])

    t = _table(geometry)
    del t["lengths_mm"]
    with pytest.raises(ConfigFileError, match="missing required key") as exc:
        _load(tmp_path, t)
    assert exc.value.key == "lengths_mm"

    t = _table(geometry)
    t["normal"] = t.pop("normals")
    with pytest.raises(ConfigFileError, match="did you mean 'normals'") as exc:
        _load(tmp_path, t)
    assert exc.value.key == "normal"

    t = _table(geometry)
    t["normals"] = [row[:5] for row in t["normals"]]
    with pytest.raises(ConfigFileError, match=r"\(N, 6, 2, 3\)") as exc:
        _load(tmp_path, t)
    assert exc.value.key == "normals"

    t = _table(geometry)
    t["lengths_mm"] = t["lengths_mm"][:2]
    with pytest.raises(ConfigFileError, match="one length per leg") as exc:
        _load(tmp_path, t)
    assert exc.value.key == "lengths_mm"

    t = _table(geometry)
    t["normals"][1][4][0] = [2.0, 0.0, 0.0]
    with pytest.raises(ConfigFileError, match=r"configuration 1 leg 4 edge 0.*unit") as exc:
        _load(tmp_path, t)
    assert exc.value.key == "normals"

    t = _table(geometry)
    t["normals"][2][3][1] = None
    with pytest.raises(ConfigFileError, match="configuration 2 leg 3 edge 1 is marked visible"):
        _load(tmp_path, t)
    del t["edge_visible"]  # without the mask, a null normal is a hidden edge
    assert not _load(tmp_path, t).edge_visible[2, 3, 1]
    t["normals"][2][3][1] = [None, None, None]  # three nulls alike
    assert not _load(tmp_path, t).edge_visible[2, 3, 1]
    # one coordinate missing: refused (it was taken for an edge not seen, silently)
    t["normals"][0][5][1] = [0.8, None, -0.05]
    with pytest.raises(ConfigFileError, match=r"configuration 0 leg 5 edge 1: normal "
                       r"\[0.8, null, -0.05\] lacks a coordinate") as exc:
        _load(tmp_path, t)
    assert exc.value.key == "normals"

    t = _table(geometry)
    t["format"] = "something-else"
    with pytest.raises(ConfigFileError, match="format"):
        _load(tmp_path, t)


def test_error_summary_and_point_errors() -> None:
    truth = np.zeros((6, 3))
    est = np.zeros((2, 6, 3))
    est[0, 1] = [0.003, 0.004, 0.0]  # 5 mm, largest component 4 mm
    est[1, 5] = [0.0, 0.0, -0.001]
    np.testing.assert_allclose(point_errors(est, truth)[0, 1], 0.005)
    s = error_summary(est, truth)
    assert s["repetitions"] == 2
    assert s["max_error_mm"] == pytest.approx(5.0)
    assert s["median_error_mm"] == pytest.approx(0.0)
    assert s["per_point_max_mm"] == pytest.approx([0, 5, 0, 0, 0, 1])
    assert s["per_point_median_mm"] == pytest.approx([0, 2.5, 0, 0, 0, 0.5])
    assert s["max_component_error_mm"] == pytest.approx(4.0)
    json.dumps(s)


def test_study(geometry: HexapodGeometry) -> None:
    T = front_pose()
    exact = calibration_study(geometry, T, 0.0, 3, rng=1)
    assert exact.errors.max() < 1e-9
    low = calibration_study(geometry, T, 0.01, 30, rng=1)
    high = calibration_study(geometry, T, 0.05, 30, rng=1)
    assert 0 < low.per_point_median.max() < high.per_point_median.max()
    # Seed 001: median error on each point below 1 mm at 0.05 deg (with some slack for
    # 30 repetitions instead of 100).
    assert high.per_point_median.max() < 1.3e-3
    d = high.to_dict()
    json.dumps(d)
    assert d["repetitions"] == 30 and len(d["per_point_max_mm"]) == 6


def test_calibrate_in_world(geometry: HexapodGeometry, rng: np.random.Generator) -> None:
    cam = front_camera(geometry)
    cal = SimpleNamespace(configurations="extremal", solver="irls", noise_deg=None)
    points, summary = calibrate_in_world(geometry, cam, cal, SimpleNamespace(model="none"), rng)
    np.testing.assert_allclose(points, cam.camera_from_base.apply(geometry.base_points),
                               atol=1e-9)
    assert summary["max_error_mm"] < 1e-6 and summary["configurations"] == 64
    noisy_cal = SimpleNamespace(configurations="random:40", solver="lstsq", noise_deg=0.05)
    _, s2 = calibrate_in_world(geometry, cam, noisy_cal, SimpleNamespace(model="none"), rng)
    assert 0.01 < s2["max_error_mm"] < 20
    pixel = SimpleNamespace(model="pixel", pixel_sigma_px=0.5, points_per_edge=20,
                            outlier_fraction=0.0)
    _, s3 = calibrate_in_world(geometry, cam, cal, pixel, rng)
    assert 1e-4 < s3["max_error_mm"] < 20


def test_calibration_study_command(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from benchmarks.perf.calibration import main

    out = tmp_path / "study.json"
    assert main(["--repeats", "3", "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "seed: max 1.4 mm, median < 1 mm" in printed
    table = json.loads(out.read_text())
    assert [r["noise_deg"] for r in table["results"]] == [0.01, 0.05, 0.1]
    assert all(r["repetitions"] == 3 for r in table["results"])
    assert table["results"][0]["max_error_mm"] < table["results"][2]["max_error_mm"]


def test_image_observations_measure_the_legs_edges(geometry: HexapodGeometry) -> None:
    """Calibration observations through rendered images (0.8 px blur, no pixel noise):
    the edges found are those the geometry says are visible (a few more, partly seen),
    their normals within hundredths of a degree of the exact ones, the lengths the true
    robot's."""
    from vision.calibration import collect_image_observations
    from vision.image_sensor import ImageSensor

    cam = front_camera(geometry)
    sensor = ImageSensor(cam, cam, geometry, rng=0, blur_px=0.8, noise_std=0.0)
    img = collect_image_observations(sensor, geometry, "extremal", 0)
    exact = collect_observations(geometry, cam, "extremal", None, 0)
    both = img.edge_visible & exact.edge_visible
    assert both.sum() >= 0.95 * exact.edge_visible.sum()
    cos = np.abs(np.sum(img.normals[both] * exact.normals[both], axis=-1))
    angle = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    assert np.median(angle) < 0.02 and angle.max() < 0.2
    assert np.isnan(img.normals[~img.edge_visible]).all()
    np.testing.assert_array_equal(img.lengths, exact.lengths)
