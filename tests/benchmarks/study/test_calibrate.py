"""hexapod-bench calibrate, and studies that control with calibrated base points."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from benchmarks.cli import main as cli_main
from benchmarks.study.calibration import load_calibrated_base_points
from benchmarks.study.runner import read_results
from hexapod.exceptions import ConfigFileError
from hexapod.geometry import deltalab
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


def test_an_image_scenario_calibrates_from_its_rendered_images(tmp_path: Path) -> None:
    """``[sensor] kind = "image"``: the calibration reads rendered images (their edges'
    bias makes millimetres of the poorly conditioned legs), where it used to take the
    exact normals of the noise model ``none`` and report a perfect calibration;
    ``[calibration] noise_deg`` still asks for the noise model (exact at 0)."""
    errors = {}
    for name, extra in (("images", ""), ("model", "[calibration]\nnoise_deg = 0.0\n")):
        path = tmp_path / f"{name}.toml"
        path.write_text('name = "cal-images"\nseed = 4\ntrials = 2\ncontrollers = '
                        '["leg-edge"]\n[sensor]\nkind = "image"\n[noise]\nmodel = "none"'
                        f'\n[task]\nmax_steps = 60\n{extra}')
        out = tmp_path / name
        assert cli_main(["calibrate", str(path), "--out", str(out)]) == 0
        errors[name] = json.loads((out / "calibration.json").read_text())["max_error_mm"]
    assert errors["model"] < 1e-6
    assert 0.1 < errors["images"] < 50.0


@pytest.mark.slow
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
    # in metres: named at load with the file and key (each trial was refused without them)
    points = deltalab().base_points + np.array([0.0, 0.0, 0.9])  # metres, camera frame
    bad.write_text("base_points_camera_mm = [" + ", ".join(
        "[" + ", ".join(f"{x:.6f}" for x in p) + "]" for p in points) + "]\n")
    with pytest.raises(ConfigFileError, match=r"key 'base_points_camera_mm': the six points "
                                              r"are at most 0\.4864 mm apart: given in "
                                              r"metres\?") as info:
        load_calibrated_base_points(bad)
    assert str(bad) in str(info.value)
    scen = _scenario(tmp_path)
    assert cli_main(["run", str(scen), "--out", str(tmp_path / "x"), "--calibration",
                     str(tmp_path / "missing.toml")]) == 2


@pytest.mark.slow
def test_viz_replays_a_recorded_trial_to_html(tmp_path: Path) -> None:
    scen = _scenario(tmp_path)
    out = tmp_path / "run"
    assert cli_main(["run", str(scen), "--out", str(out), "--no-progress", "--record", "1"]) == 0
    html = tmp_path / "trial0.html"
    assert cli_main(["viz", str(out), "--trial", "0", "--html", str(html)]) == 0
    assert html.stat().st_size > 10_000 and html.with_suffix(".png").exists()
    assert cli_main(["viz", str(out), "--trial", "7", "--html", str(html)]) == 2


def test_calibrate_from_a_user_observation_file(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
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
    # the simulated calibration's options: refused, not dropped without a word
    capsys.readouterr()
    assert cli_main(["calibrate", str(_scenario(tmp_path)), "--out", str(tmp_path / "o7"),
                     "--observations", str(obs), "--repeat", "7", "--configurations",
                     "random:5"]) == 2
    err = " ".join(capsys.readouterr().err.split())
    assert "--configurations random:5, --repeat 7: options of the simulated calibration" \
        in err and not (tmp_path / "o7").exists()
    broken = tmp_path / "broken.json"
    broken.write_text(obs.read_text().replace('"lengths_mm"', '"length_mm"'))
    assert cli_main(["calibrate", str(_scenario(tmp_path)), "--out", str(out),
                     "--observations", str(broken)]) == 2
    # a leg seen in one configuration: the failure names the user's file, nothing written
    import json

    doc = json.loads(obs.read_text())
    few = tmp_path / "few.json"
    vis = np.array(doc["edge_visible"], dtype=bool)
    vis[1:, 4, :] = False  # leg 4 seen in the first configuration only
    doc["edge_visible"] = vis.tolist()
    few.write_text(json.dumps(doc))
    out2 = tmp_path / "out2"
    assert cli_main(["calibrate", str(_scenario(tmp_path)), "--out", str(out2),
                     "--observations", str(few)]) == 2
    err = " ".join(capsys.readouterr().err.split())
    assert f"{few}: " in err and "leg 4" in err and "seen in 1 configuration(s)" in err
    assert not out2.exists()
    # lengths in metres where mm are meant: unused by the calibration, but said
    doc = json.loads(obs.read_text())
    doc["lengths_mm"] = (np.asarray(doc["lengths_mm"]) / 1000).tolist()
    metres = tmp_path / "metres.json"
    metres.write_text(json.dumps(doc))
    assert cli_main(["calibrate", str(_scenario(tmp_path)), "--out", str(tmp_path / "o3"),
                     "--observations", str(metres)]) == 0
    err = " ".join(capsys.readouterr().err.split())
    assert f"warning: {metres}: 180 leg length(s) outside the robot's stroke" in err


def _mixed_signs(folder: Path) -> tuple[Path, dict, np.ndarray, np.ndarray]:
    """Exact observations of 30 random configurations (front camera) written with each
    normal's sign drawn at random: the file, its content, the normals as drawn and the
    signs."""
    from hexapod import deltalab
    from vision.calibration import collect_observations

    data = collect_observations(deltalab(), front_camera(), "random:30", None, 5)
    doc = json.loads(json.dumps(data.to_dict()))
    normals = np.asarray(doc["normals"], dtype=float)
    signs = np.random.default_rng(3).choice([-1.0, 1.0], size=normals.shape[:3])
    doc["normals"] = (normals * signs[..., None]).tolist()
    mixed = folder / "mixed.json"
    mixed.write_text(json.dumps(doc))
    return mixed, doc, normals, signs


def test_edge_normals_of_either_sign_calibrate_alike_and_another_frame_is_said(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A line fitted in an image has a normal of either sign; the calibration needs
    ``n . A = -r``. Random signs gave base points 444 mm off with exit 0, said only as
    'far from nominal'; normals in the base frame (points a metre off, with the right
    file's fit figures) are told apart from nothing but a wrong camera pose: said so."""
    import json

    from hexapod import deltalab

    cam = front_camera()
    truth = cam.camera_from_base.apply(deltalab().base_points)
    mixed, doc, normals, signs = _mixed_signs(tmp_path)
    out = tmp_path / "out"
    assert cli_main(["calibrate", str(_scenario(tmp_path)), "--out", str(out),
                     "--observations", str(mixed)]) == 0
    np.testing.assert_allclose(load_calibrated_base_points(out / "calibrated.toml"), truth,
                               atol=1e-8)
    flipped = int(np.sum((signs < 0) & np.asarray(doc["edge_visible"], bool)))
    assert json.loads((out / "calibration.json").read_text())["normals_flipped"] == flipped
    assert f"note: {flipped} edge normal(s) of {mixed} oriented" in " ".join(
        capsys.readouterr().err.split())
    doc["normals"] = (-normals).tolist()  # every sign reversed: a consistent mirror image
    every = tmp_path / "every.json"
    every.write_text(json.dumps(doc))
    assert cli_main(["calibrate", str(_scenario(tmp_path)), "--out", str(tmp_path / "o1"),
                     "--observations", str(every)]) == 0
    np.testing.assert_allclose(load_calibrated_base_points(tmp_path / "o1" /
                                                           "calibrated.toml"), truth, atol=1e-8)
    capsys.readouterr()
    R = cam.camera_from_base.rotation  # normals given in the base frame instead
    doc["normals"] = np.einsum("ji,nlej->nlei", R, normals).tolist()
    base = tmp_path / "base.json"
    base.write_text(json.dumps(doc))
    assert cli_main(["calibrate", str(_scenario(tmp_path)), "--out", str(tmp_path / "o2"),
                     "--observations", str(base)]) == 0  # (a wrong camera pose looks alike)
    err = " ".join(capsys.readouterr().err.split())
    assert "(all six: the camera file's pose is not this setup's, or the observations' " \
        "normals are not in this camera's frame)" in err, err
    # a file whose edges agree with no base point: said, whatever orienting could do
    random = np.random.default_rng(4).normal(size=normals.shape)
    doc["normals"] = (random / np.linalg.norm(random, axis=-1, keepdims=True)).tolist()
    noise = tmp_path / "noise.json"
    noise.write_text(json.dumps(doc))
    assert cli_main(["calibrate", str(_scenario(tmp_path)), "--out", str(tmp_path / "o3"),
                     "--observations", str(noise)]) == 0
    err = " ".join(capsys.readouterr().err.split())
    assert "the observations do not agree with one base point per leg" in err, err


def test_an_omnidirectional_file_of_reversed_signs_is_reversed_back(tmp_path: Path) -> None:
    """The omnidirectional camera sees all around: a file with every sign reversed agrees
    as well as the right one, its base points mirrored through the camera centre (half a
    metre off). The one nearer the nominal points is taken: it was the mirror, exit 0."""
    from hexapod import deltalab
    from vision.calibration import collect_observations
    from vision.cameras import omni_camera

    cam = omni_camera(deltalab())
    data = collect_observations(deltalab(), cam, "random:30", None, 5)
    truth = cam.camera_from_base.apply(deltalab().base_points)
    doc = json.loads(json.dumps(data.to_dict()))
    scenario = tmp_path / "omni.toml"
    scenario.write_text('name = "omni-cal"\nseed = 4\ntrials = 2\ncontrollers = '
                        '["leg-edge"]\n[camera]\npreset = "omni"\n[noise]\nmodel = "none"\n'
                        '[task]\nmax_steps = 60\n')
    for name, sign in (("kept", 1.0), ("reversed", -1.0)):
        doc["normals"] = (sign * np.asarray(data.to_dict()["normals"], dtype=float)).tolist()
        obs = tmp_path / f"{name}.json"
        obs.write_text(json.dumps(doc))
        out = tmp_path / name
        assert cli_main(["calibrate", str(scenario), "--out", str(out),
                         "--observations", str(obs)]) == 0
        np.testing.assert_allclose(load_calibrated_base_points(out / "calibrated.toml"),
                                   truth, atol=1e-8)
        flipped = json.loads((out / "calibration.json").read_text())["normals_flipped"]
        assert flipped == (0 if sign > 0 else int(data.edge_visible.sum()))


@pytest.mark.slow
def test_ill_conditioned_calibration_is_refused_or_marked(tmp_path: Path,
                                                         caplog: pytest.LogCaptureFixture
                                                         ) -> None:
    """30 mm legs seen by the front camera: leg 4's system has a singular-value ratio of
    about 1e-3 (hard limit 1.5e-3): every trial is refused, naming the leg and the ratio,
    and nothing is servoed. With the reference robot and a warning threshold above its
    weakest leg (0.0144), the trials run and are marked."""
    from hexapod import deltalab

    deltalab().replace(leg_radius=0.030).to_toml(tmp_path / "legs30.toml")
    study = tmp_path / "legs30.toml.study"
    common = ('seed = 7\ntrials = 3\ncontrollers = ["leg-edge"]\n[noise]\nmodel = "rotation"\n'
              'amplitude_deg = 0.05\n[task]\nmax_steps = 30\nfixed_duration = true\n')
    study.write_text('name = "legs30"\n' + common + '[robot]\ngeometry = "legs30.toml"\n'
                     '[calibration]\nmethod = "linear"\nsolver = "lstsq"\n')
    out = tmp_path / "refused"
    # every trial failed (refused by its calibration): the run exits 1
    assert cli_main(["run", str(study), "--out", str(out), "--no-progress"]) == 1
    rows = read_results(out)
    assert len(rows) == 3
    for r in rows:
        assert r["failure"].startswith("CalibrationError: calibration: leg 4: ill-conditioned "
                                       "(singular-value ratio 1."), r["failure"]
        assert "< 1.50e-03, the hard limit" in r["failure"]
        assert r["steps"] == 0 and r["final_position_error_mm"] is None
    report = (out / "report.md").read_text()
    assert "| 0/3 | 3/3 |" in report, "the calibration table counts the refused trials"

    warned = tmp_path / "warned.toml"
    warned.write_text('name = "warned"\n' + common + '[calibration]\nmethod = "linear"\n'
                      'solver = "lstsq"\nwarn_singular_ratio = 0.02\n')
    out = tmp_path / "warned"
    with caplog.at_level("WARNING", logger="vision.calibration"):
        assert cli_main(["run", str(warned), "--out", str(out), "--no-progress"]) == 0
    assert any("is ill-conditioned (singular-value ratio 1.4" in m for m in caplog.messages)
    rows = read_results(out)
    assert all(r["failure"] is None or r["failure"].startswith("not conv") for r in rows)
    assert all(r["calibration_ill_conditioned_legs"] >= 1 for r in rows)
    assert all(0.014 < r["calibration_min_singular_ratio"] < 0.02 for r in rows)
    assert "| 3/3 | 0/3 |" in (out / "report.md").read_text()


def test_a_consistent_file_is_kept_whatever_the_nominal_camera_pose() -> None:
    """A good file compared with a nominal pose that is far off (a pose rotated half a
    turn, shifted a metre, or the camera's position typed for its translation) was turned
    into its mirror image, 991 mm off: a file whose equations agree and whose points lie
    in front of the camera keeps its signs."""
    from benchmarks.study.calibration import _with_signs
    from hexapod import deltalab
    from vision.calibration import collect_observations
    from vision.calibration.fit import calibrate

    g = deltalab()
    cam = front_camera(g)
    data = collect_observations(g, cam, "random:30", None, 5)
    truth = cam.camera_from_base.apply(g.base_points)

    def solve(d: object) -> object:
        return calibrate(d, g.leg_radius, g.base_points, method="lstsq")

    half_turn = truth * np.array([1.0, -1.0, -1.0])  # about the camera's x axis
    for nominal in (truth, half_turn, truth + np.array([0.0, 0.0, 1.0]), -truth):
        res, used = _with_signs(data, solve, nominal, g.leg_radius, True)
        np.testing.assert_allclose(res.base_points, truth, atol=1e-8)
        assert np.array_equal(np.asarray(used.normals), np.asarray(data.normals))


def test_a_calibration_that_fits_the_robot_poorly_is_warned_of(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Three noisy configurations fit the base to 7 mm RMS (points tens of mm off) and
    were written without a word; thirty fit to 2 mm: no warning."""
    from hexapod import deltalab
    from vision.calibration import collect_observations
    from vision.calibration.collect import rotation_noise

    cam = front_camera()
    for configurations, warned in (("random:3", True), ("random:30", False)):
        obs = tmp_path / f"{configurations[7:]}.json"
        collect_observations(deltalab(), cam, configurations, rotation_noise(0.05), 5).save(obs)
        assert cli_main(["calibrate", str(_scenario(tmp_path)), "--out",
                         str(tmp_path / obs.stem), "--observations", str(obs)]) == 0
        err = " ".join(capsys.readouterr().err.split())
        assert ("the calibrated base points fit the robot's base only to" in err) is warned, err
        assert "--correct-scale" not in err
    # legs 10 % thicker than the robot file says: the fit is poor and the scale says why
    thick = deltalab().replace(leg_radius=1.1 * deltalab().leg_radius)
    obs = tmp_path / "thick.json"
    collect_observations(thick, cam, "random:30", None, 5).save(obs)
    assert cli_main(["calibrate", str(_scenario(tmp_path)), "--out", str(tmp_path / "thick"),
                     "--observations", str(obs)]) == 0
    err = " ".join(capsys.readouterr().err.split())
    assert "fit the robot's base only to" in err and "times the robot's size: a leg radius " \
        "off by as much? (--correct-scale divides it out)" in err


def test_calibrate_warns_of_a_camera_pose_in_metres_as_run_does(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``calibrate`` gives the setup warnings of ``run``'s pre-flight first: a camera file
    whose translation is in metres (it failed "leg 0: seen in 0 configuration(s)",
    naming neither the file nor the key)."""
    import tomllib

    import tomli_w

    cam_file = tmp_path / "my-camera.toml"
    front_camera(deltalab()).to_toml(cam_file)
    table = tomllib.loads(cam_file.read_text())
    pose = table["camera_from_base"]
    key = next(k for k in pose if k.startswith("translation"))
    pose[key] = [x * 1e-3 for x in pose[key]]  # metres where millimetres are meant
    cam_file.write_text(tomli_w.dumps(table))
    scen = tmp_path / "s.toml"
    scen.write_text('name = "s"\nseed = 4\ntrials = 2\ncontrollers = ["leg-edge"]\n'
                    '[camera]\nfile = "my-camera.toml"\n[noise]\nmodel = "none"\n')
    cli_main(["calibrate", str(scen), "--out", str(tmp_path / "cal")])
    err = capsys.readouterr().err
    assert "hexapod-bench: warning: s: the camera's centre is" in err, err
    assert f"given in metres? The camera's translation is in millimetres; check " \
           f"[camera_from_base] in {cam_file}" in err, err


def test_a_calibration_file_over_a_linear_scenario_says_it_replaces_it(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``run quick-linear.toml --calibration FILE``: the file replaced the scenario's
    ``method = "linear"`` without a word, and the warning then advised that method; the
    warning is printed and kept in run.json's warnings."""
    out = tmp_path / "cal"
    assert cli_main(["calibrate", str(_scenario(tmp_path)), "--out", str(out)]) == 0
    linear = tmp_path / "linear.toml"
    linear.write_text(_scenario(tmp_path).read_text() + '[calibration]\nmethod = "linear"\n')
    capsys.readouterr()
    run = tmp_path / "run"
    assert cli_main(["run", str(linear), "--calibration", str(out / "calibrated.toml"),
                     "--trials", "1", "--out", str(run), "--no-progress"]) == 0
    said = "replaces scenario cal's [calibration] method = \"linear\""
    assert said in " ".join(capsys.readouterr().err.split())
    assert any(said in w for w in json.loads((run / "run.json").read_text())["warnings"])

def test_an_ill_conditioned_leg_of_a_file_is_warned_of_once(
        tmp_path: Path, capsys: pytest.CaptureFixture[str],
        caplog: pytest.LogCaptureFixture) -> None:
    """A file of mixed signs is solved three times (as given, then oriented twice): each
    solve logged each ill-conditioned leg, beside the command's own line on stdout (four
    messages a leg on two streams); now one line a leg, on stderr."""
    mixed = _mixed_signs(tmp_path)[0]
    with caplog.at_level("WARNING"):
        assert cli_main(["calibrate", str(_scenario(tmp_path)), "--out", str(tmp_path / "o"),
                         "--observations", str(mixed), "--warn-ratio", "0.02"]) == 0
    captured = capsys.readouterr()
    legs = json.loads((tmp_path / "o" / "calibration.json").read_text())[
        "result"]["linear"]["ill_conditioned_legs"]
    assert legs, "the case needs an ill-conditioned leg"
    for leg in legs:
        said = (captured.out + captured.err + caplog.text).count(f"leg {leg} is ill-conditioned")
        assert said == 1 and f"leg {leg} is ill-conditioned" in captured.err
