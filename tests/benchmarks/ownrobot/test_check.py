"""``hexapod-bench check``: what a user needs to trust a robot, a camera or a scenario."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from benchmarks.cli import main
from benchmarks.study.setup_check import axis_reach, check_setup, edge_interaction_ratio
from hexapod.geometry import deltalab
from hexapod.kinematics import inverse_kinematics
from hexapod.workspace import home_pose
from tests.benchmarks.ownrobot.robots import BLIND_CAMERA, own_robot, write_study
from vision.cameras import front_camera
from vision.legs import observe_legs


def _check(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    code = main(["check", *args])
    cap = capsys.readouterr()
    return code, cap.out + cap.err


def test_check_a_robot_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "robot.toml"
    own_robot().to_toml(path)
    picture = tmp_path / "view.png"
    code, out = _check([str(path), "--picture", str(picture)], capsys)
    assert code == 0, out
    assert f"{path}: a robot file" in out
    assert "camera: the front preset, placed for this robot" in out
    assert ("Robot 'own': base radius 350.0 mm, platform radius 200.0 mm, stroke 380-540 mm"
            in out)
    # a symmetric robot: every leg at mid-stroke at home
    assert "leg lengths at home [mm]: 0: 460.0, 1: 460.0, 2: 460.0, 3: 460.0, 4: 460.0, " \
           "5: 460.0" in out
    assert "at home it sees 12 of 12 leg edges" in out
    assert "No problem found." in out and "The setup can run." in out
    image = cv2.imread(str(picture))
    assert image.shape == (780, 1024, 3)
    green = (image[..., 1] > 150) & (image[..., 0] < 80) & (image[..., 2] < 80)
    assert green.sum() > 2000  # the seen edges are drawn


def test_home_pixels_agree_with_opencv() -> None:
    """The base ends of the two edges of each leg straddle the image of A_i (OpenCV)."""
    g = own_robot()
    cam = front_camera(g)
    report = check_setup(g, cam)
    T = cam.camera_from_base
    rvec, _ = cv2.Rodrigues(T.rotation)
    px, _ = cv2.projectPoints(g.base_points, rvec, T.translation, cam.K, None)
    mid = report.home_pixels[:, :, 0].mean(axis=1)
    radius_px = cam.K[0, 0] * g.leg_radius / np.min(T.apply(g.base_points)[:, 2])
    assert np.max(np.linalg.norm(mid - px[:, 0], axis=1)) < radius_px


def test_workspace_figures_are_those_of_the_strokes() -> None:
    g = own_robot()
    cam = front_camera(g)
    assert check_setup(g, cam, 0.0, 0.0, 0.0).fraction == 1.0  # home only
    small = check_setup(g, cam, 60.0, 10.0, 5.0).fraction
    large = check_setup(g, cam, 150.0, 25.0, 5.0).fraction
    assert 0.0 < large < small < 1.0
    # the reach along each axis puts one leg at a stroke limit (inverse kinematics)
    t_reach, r_reach = axis_reach(g)
    R0, t0 = home_pose(g)
    dirs = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]])
    for d, s in zip(dirs, t_reach, strict=True):
        q = inverse_kinematics(g, R0, t0 + s * d)
        gap = min(np.min(np.abs(q - g.q_min)), np.min(np.abs(q - g.q_max)))
        assert gap < 1e-6 and np.all(q >= g.q_min - 1e-9) and np.all(q <= g.q_max + 1e-9)
        q_beyond = inverse_kinematics(g, R0, t0 + (s + 1e-4) * d)
        assert np.any(q_beyond < g.q_min) or np.any(q_beyond > g.q_max)
    assert np.all(r_reach > np.deg2rad(10))


def test_edge_interaction_rank_needs_several_legs() -> None:
    g = deltalab()
    obs = observe_legs(front_camera(g), g, *home_pose(g))
    ratio, cond = edge_interaction_ratio(obs)
    assert ratio > 1e-3 and cond == pytest.approx(1 / ratio)
    mask = np.zeros((6, 2), bool)
    mask[0] = True  # one leg: two rank-one rows, rank 2 < 6
    one = type(obs)(**{**obs.__dict__, "edge_visible": mask})
    assert edge_interaction_ratio(one)[0] < 1e-9


def test_check_a_blind_camera_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "camera.toml"
    path.write_text(BLIND_CAMERA)
    picture = tmp_path / "blind.png"
    code, out = _check([str(path), "--picture", str(picture)], capsys)
    assert code == 1, out
    assert "robot: the deltalab preset" in out
    assert "at home it sees 0 of 12 leg edges" in out
    assert ("error: the camera sees no leg edge at the home pose: the robot is behind the "
            "camera (its base joints are 2000 mm or more behind the image plane") in out
    assert f"change [camera_from_base] in {path}" in out
    assert "The setup cannot run" in out
    image = cv2.imread(str(picture))
    assert not ((image[..., 1] > 150) & (image[..., 0] < 80)).any()  # nothing seen


def test_check_a_scenario_with_an_empty_workspace(tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    own_robot(stroke=(0.100, 0.150)).to_toml(tmp_path / "robot.toml")
    study = write_study(tmp_path)
    code, out = _check([str(study)], capsys)
    assert code == 1
    assert "0.0 % of 2000 random poses keep every leg inside its stroke" in out
    assert "error: empty workspace, no home pose: even with the platform lowered onto the " \
           "base the legs measure" in out
    assert f"change stroke_mm in {tmp_path / 'robot.toml'}" in out


@pytest.mark.parametrize(("box", "severity", "code"), [
    ("max_translation_mm = 200.0\nmax_angle_deg = 30.0", "warning: small workspace", 0),
    ("max_translation_mm = 400.0\nmax_angle_deg = 40.0", "error: empty workspace: none of", 1),
])
def test_check_a_task_box_too_large(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                    box: str, severity: str, code: int) -> None:
    own_robot().to_toml(tmp_path / "robot.toml")
    study = write_study(tmp_path)
    study.write_text(study.read_text().replace("[task]\n", f"[task]\n{box}\n"))
    got, out = _check([str(study)], capsys)
    assert got == code, out
    assert severity in out
    assert f"[task] max_translation_mm / max_angle_deg / margin_mm in {study}" in out


def test_check_refuses_a_file_it_cannot_read(tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "what.toml"
    path.write_text("colour = 'blue'\n")
    code, out = _check([str(path)], capsys)
    assert code == 2 and "cannot tell what this file is" in out
    code, out = _check(["quik"], capsys)
    assert code == 2 and "(did you mean 'quick'?)" in out


def test_check_states_the_dynamics_and_where_they_come_from(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The masses and drives a dynamic study will use, from the robot file's tables
    (named) or the stated assumptions, and a scenario's sweep of the drives."""
    from dataclasses import replace

    robot = own_robot()
    drives = replace(robot.drives, velocity_bandwidth=np.array([8.0, 8, 8, 8, 8, 12]),
                     force_limit=np.full(6, 150.0))
    path = tmp_path / "robot.toml"
    replace(robot, drives=drives).to_toml(path)
    code, out = _check([str(path)], capsys)
    assert code == 0, out
    assert f"[inertia] in {path}" in out and f"[drives] in {path}" in out
    assert ("velocity mode, force limit 150 N, velocity loop [8, 8, 8, 8, 8, 12] Hz"
            in out), out
    code, out = _check(["mpc-drives"], capsys)
    assert code == 0, out
    assert "assumed: no [drives] table" in out
    assert "swept by [drives] velocity_bandwidth_hz" in out and "5, 10, 20, 50 Hz" in out


def test_check_says_what_a_calibration_file_is_for(tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """``calibrate``'s ``calibrated.toml`` given to ``check``: read (a broken one refused
    naming its key), then said where it goes, not read as a camera file."""
    rows = ",\n".join("  [" + ", ".join(f"{v:.3f}" for v in p) + "]"
                      for p in deltalab().base_points * 1e3 + [0, 0, 500])
    cal = tmp_path / "calibrated.toml"
    cal.write_text('# written by hexapod-vs (hexapod-bench calibrate)\n'
                   'source = "quick (repetition 0, sweep point 0, extremal)"\n'
                   f"base_points_camera_mm = [\n{rows}\n]\n")
    assert main(["check", str(cal)]) == 2
    err = " ".join(capsys.readouterr().err.split())
    assert f"{cal}: a base-point calibration (hexapod-bench calibrate, from quick" in err
    assert "run --calibration FILE" in err and "key 'source'" not in err
    cal.write_text('base_points_camera_mm = [[1.0, 2.0, 3.0]]\n')  # one point of six
    assert main(["check", str(cal)]) == 2
    assert "base_points_camera_mm" in capsys.readouterr().err


def test_a_fixed_task_whose_start_the_camera_cannot_resolve_is_refused() -> None:
    """A fixed task starting where the camera sees 3 edges (a singular edge interaction):
    check said the setup could run and every leg-edge trial then refused to move. The
    start and goal are examined: an error when every controller steers by the image, a
    warning naming them otherwise, nothing for a camera that sees them."""
    from benchmarks.study.fixed_task_check import fixed_task_problems
    from hexapod.kinematics import Transform
    from vision.cameras.perspective import PerspectiveCamera

    g = deltalab()
    R0, t0 = home_pose(g)[:2]
    home_mm = inverse_kinematics(g, R0, t0) * 1e3
    good = front_camera(g)
    T = good.camera_from_base
    close = PerspectiveCamera(good.K, good.width, good.height,
                              Transform(T.rotation, np.array([*T.translation[:2], 0.25])))
    assert int(np.asarray(observe_legs(close, g, R0, t0).edge_visible).sum()) == 3
    alone = fixed_task_problems(g, home_mm, home_mm + 5.0, camera=close,
                                needs_camera=["leg-edge"], controllers=1)
    starts = [p for p in alone if p.text.startswith("task.start_mm")]
    assert starts and starts[0].severity == "error", alone
    assert "sees 3 leg edge(s) at the task's start" in starts[0].text
    assert "leg-edge cannot steer by the image there" in starts[0].text
    mixed = fixed_task_problems(g, home_mm, home_mm + 5.0, camera=close,
                                needs_camera=["leg-edge"], controllers=2)
    assert all(p.severity == "warning" for p in mixed) and mixed
    assert "the other controllers do not need the camera" in mixed[0].text
    assert fixed_task_problems(g, home_mm, home_mm + 5.0, camera=good,
                               needs_camera=["leg-edge"], controllers=1) == []


def test_slips_a_user_makes_in_a_robot_file_are_warned_of(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Two platform rows swapped (legs crossing), a leg radius or a speed in metres, a
    stroke in metres: check said 'No problem found' for the first three and printed a
    home pose that did not exist for the last."""
    from dataclasses import replace

    good = own_robot()
    good.to_toml(tmp_path / "good.toml")
    code, text = _check([str(tmp_path / "good.toml")], capsys)
    assert code == 0 and "meet at home" not in text and "given in m" not in text, text
    points = good.platform_points.copy()
    points[[0, 3]] = points[[3, 0]]
    cases = {
        "crossed": (replace(good, platform_points=points), "legs 0 and 3 meet at home"),
        "radius": (replace(good, leg_radius=2e-5), "leg radius 0.02 mm: given in metres?"),
        "speed": (replace(good, max_speed=4e-5), "leg speed limit 0.04 mm/s: given in m/s?"),
    }
    for name, (robot, text_expected) in cases.items():
        robot.to_toml(tmp_path / f"{name}.toml")
        code, text = _check([str(tmp_path / f"{name}.toml")], capsys)
        assert code == 0 and f"warning: {text_expected}" in text, (name, text)
    own_robot(stroke=(0.00038, 0.00054)).to_toml(tmp_path / "metres.toml")
    code, text = _check([str(tmp_path / "metres.toml")], capsys)
    assert code == 1, text
    assert "home pose: none" in text and "leg lengths at home" not in text, text
    assert "given in metres? stroke_mm is in millimetres" in text
    assert "small workspace" not in text  # (the error says it)
    # no camera warning about a home pose there is not (it warned of the edges' condition
    # number there, "a pose in radians where degrees are meant gives this")
    assert "observe the platform's pose poorly" not in text
    assert not any("warning" in line and "camera" in line for line in text.splitlines()), text


def test_a_focal_length_in_millimetres_and_a_poorly_observed_pose_are_warned_of() -> None:
    """fx = 4.8 (millimetres where pixels are meant: the legs a few pixels long) and a
    camera seeing the pose poorly (condition number 47,000 where the built-in cameras
    give 22 to 67: a pose in radians gave 1505) both passed as 'No problem found'."""
    from hexapod.kinematics import Transform
    from vision.cameras.perspective import PerspectiveCamera

    g = deltalab()
    good = front_camera(g)
    T = good.camera_from_base
    tiny = PerspectiveCamera(good.K * np.array([[4.8 / good.fx], [4.8 / good.fy], [1.0]]),
                             good.width, good.height, T)
    close = PerspectiveCamera(good.K, good.width, good.height,
                              Transform(T.rotation, np.array([*T.translation[:2], 0.30])))
    texts = {name: [p.text for p in check_setup(g, cam).problems if p.severity == "warning"]
             for name, cam in (("good", good), ("tiny", tiny), ("close", close))}
    assert not any("focal length" in t or "poorly" in t for t in texts["good"]), texts
    assert any(t.startswith("focal length 4.8 px: given in millimetres?")
               and t.endswith("check fx_px / fy_px in the camera file")  # (its field)
               for t in texts["tiny"]), texts["tiny"]
    assert any("observe the platform's pose poorly" in t for t in texts["close"]), texts


def test_a_camera_translation_in_metres_is_warned_of() -> None:
    """A camera file's ``translation_mm`` given in metres (0.22, 0.33 where 220, 333 mm
    are meant) put the camera 0.4 mm from the base frame's origin and passed with a
    warning about radians; an omnidirectional camera exactly at the origin is not
    warned of (no translation at all is deliberate)."""
    from hexapod.kinematics import Transform
    from vision.cameras.perspective import PerspectiveCamera

    g = deltalab()
    good = front_camera(g)
    T = good.camera_from_base
    metres = PerspectiveCamera(good.K, good.width, good.height,
                               Transform(T.rotation, T.translation * 1e-3))
    at_origin = PerspectiveCamera(good.K, good.width, good.height,
                                  Transform(T.rotation, np.zeros(3)))
    texts = {name: [p.text for p in check_setup(g, cam).problems if p.severity == "warning"]
             for name, cam in (("good", good), ("metres", metres), ("origin", at_origin))}
    norm = np.linalg.norm(T.translation)  # [m]: the warning's figure in mm is this
    assert any(t.startswith(f"the camera's centre is {norm:.3g} mm from the base frame's "
                            "origin") and "given in metres?" in t
               for t in texts["metres"]), texts["metres"]
    assert not any("base frame's origin" in t for t in texts["good"] + texts["origin"]), texts
