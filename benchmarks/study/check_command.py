"""``hexapod-bench check FILE``: load a scenario, a robot (geometry) or a camera file,
validate it and print what a user needs to trust it (:mod:`benchmarks.study.setup_check`);
``run`` performs the same checks before its first trial (:func:`preflight`)."""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.exceptions import BenchmarkError
from benchmarks.study.fixed_task_check import fixed_task_problems
from benchmarks.study.setup_check import Problem, SetupReport, Where, check_setup
from hexapod.geometry import HexapodGeometry
from hexapod.outputs import check_replace, write_output

#: Exit code of ``check`` when the setup cannot run.
CANNOT_RUN = 1


@dataclass
class Setup:
    """What ``check`` examines: a robot, a camera, a task box, and where they come from.

    Attributes:
        kind: ``"scenario"``, ``"robot"`` or ``"camera"``.
        geometry: The robot.
        camera: The camera.
        task: ``(max_translation_mm, max_angle_deg, margin_mm)``.
        where: How to name the keys to change.
        needs_camera: Controllers that need the camera (empty: none does); None for a
            robot or camera file alone (a vision study needs it).
        controllers: Labels of all the controllers of a scenario.
        drives_note: How a scenario's ``[drives]`` changes the robot file's drives.
        notes: Lines saying what was assumed (the preset used for the missing part).
        problems: Problems found while loading (a fixed task's unreachable goal).
    """

    kind: str
    geometry: HexapodGeometry
    camera: Any
    task: tuple[float, float, float]
    where: Where
    needs_camera: list[str] | None
    notes: list[str]
    problems: list[Problem]
    controllers: tuple[str, ...] = ()
    drives_note: str | None = None


def _default_task() -> tuple[float, float, float]:
    from benchmarks.study.scenario_model import TaskConfig

    t = TaskConfig()
    return (t.max_translation_mm, t.max_angle_deg, t.margin_mm)


def scenario_setup(sc: Any) -> Setup:
    """The setup of a loaded scenario (its robot, camera, task box and controllers)."""
    import controllers  # noqa: F401 - registers the built-ins
    from benchmarks.sim import load_camera, load_geometry
    from controllers.registry import registry
    from vision.cameras.files.opencv import is_opencv_file

    g = load_geometry(sc)
    cam = load_camera(sc, g)
    where = Where(
        strokes=(f"stroke_mm in {sc.robot_geometry}" if sc.robot_geometry
                 else "[robot] preset (give [robot] geometry = your robot file)"),
        points=(f"base_points_mm / platform_points_mm in {sc.robot_geometry}"
                if sc.robot_geometry else "[robot] geometry"),
        camera=(f"[camera] pose or [camera.camera_from_base] in {sc.source} (the "
                f"calibration file {sc.camera_file} holds no pose)"
                if sc.camera_file and is_opencv_file(sc.camera_file)
                else f"[camera_from_base] in {sc.camera_file}" if sc.camera_file
                else f"[camera] preset '{sc.camera_preset}' in {sc.source} (or [camera] "
                     "file = a camera file)"),
        task=f"[task] max_translation_mm / max_angle_deg / margin_mm in {sc.source}",
        intrinsics=(f"the camera matrix in {sc.camera_file}"
                    if sc.camera_file and is_opencv_file(sc.camera_file)
                    else f"fx_px / fy_px in {sc.camera_file}" if sc.camera_file
                    else f"[camera] preset '{sc.camera_preset}' in {sc.source}"))
    needs = []
    for spec in sc.controllers:
        features = getattr(registry.create(spec.name, **spec.options), "features",
                           frozenset({"lengths"}))
        if set(features) - {"lengths"}:
            needs.append(spec.label)
    problems: list[Problem] = _model_problems(sc, g)
    if sc.task.kind == "fixed":
        problems += fixed_task_problems(g, sc.task.start_mm, sc.task.goal_mm, camera=cam,
                                        needs_camera=needs,
                                        controllers=len(sc.controllers),
                                        where_camera=where.camera)
    task = (sc.task.max_translation_mm, sc.task.max_angle_deg, sc.task.margin_mm)
    swept = sc.sweep_axes.get("drives.velocity_bandwidth_hz")
    bandwidth = sc.drives.velocity_bandwidth_hz
    note = (f"the velocity loops swept by [drives] velocity_bandwidth_hz in {sc.source}: "
            + ", ".join(f"{v:g}" for v in swept) + " Hz (shown: the first)" if swept
            else f"the velocity loops set to {bandwidth:g} Hz by [drives] in {sc.source}"
            if bandwidth > 0 else None)
    notes = []
    if getattr(sc, "model_data", None) is not None:
        m = sc.model_data
        notes.append(f"controllers' model: [inertia] and [drives] of {sc.robot_model} "
                     f"('{m.name}': platform {m.inertia.platform_mass:g} kg, force limit "
                     f"{float(m.drives.force_limit.max()):g} N); the world's truth is the "
                     "robot's, below")
    return Setup("scenario", g, cam, task, where, needs, notes, problems,
                 tuple(spec.label for spec in sc.controllers), note)


def _model_problems(sc: Any, g: Any) -> list[Problem]:
    """``[robot] model``: a warning when the file describes another robot (its points
    or strokes differ from the robot's by more than 1 mm: only its ``[inertia]`` and
    ``[drives]`` are used, and a file made for another robot was taken silently)."""
    m = getattr(sc, "model_data", None)
    if m is None:
        return []
    gap = max(float(np.abs(m.base_points - g.base_points).max()),
              float(np.abs(m.platform_points - g.platform_points).max()),
              float(np.abs(np.subtract(m.stroke, g.stroke)).max()))
    if gap <= 1e-3:
        return []
    return [Problem("warning", (
        f"robot.model: {sc.robot_model} describes another robot ('{m.name}': its points or "
        f"strokes differ from the robot's by up to {gap * 1e3:.1f} mm); the controllers take "
        "only its [inertia] and [drives] (platform "
        f"{m.inertia.platform_mass:g} kg, force limit {float(m.drives.force_limit.max()):g} "
        "N): a file for another robot?"))]


def load_scenario_file(text: str) -> Any | None:
    """The scenario ``text`` names (a built-in name or a scenario file), None for a robot
    or camera file.

    Raises:
        ScenarioError, ConfigFileError: The file is invalid (naming the key).
    """
    from benchmarks.study.scenario import builtin_scenarios, load_scenario
    from hexapod.config import load_toml
    from vision.cameras.files.opencv import OPENCV_EXTENSIONS

    path = Path(text)
    if text in builtin_scenarios() or not path.exists():
        return load_scenario(text)  # a built-in, or its did-you-mean error
    if path.suffix.lower() in OPENCV_EXTENSIONS:
        return None
    table = load_toml(path)
    return load_scenario(path) if file_kind(table) == "scenario" else None


def file_kind(table: dict[str, Any]) -> str | None:
    """What a TOML file is: ``"scenario"``, ``"robot"``, ``"camera"`` or ``"calibration"``
    (``calibrate``'s output), by its keys. A scenario has ``controllers``; otherwise each
    key that is one of a kind's own keys, or close to one (a typo: ``base_point_mm``),
    counts for that kind (``name`` and ``description`` for none), and the kind with the
    most wins; None when none does."""
    from benchmarks.study.scenario import SCENARIO_KEYS
    from hexapod.config import suggest
    from vision.cameras.files.project import CAMERA_KEYS, OPENCV_TABLE_KEYS

    if "controllers" in table:
        return "scenario"
    if "base_points_camera_mm" in table:
        return "calibration"
    shared = {"name", "description"}
    kinds = {"scenario": set(SCENARIO_KEYS) - shared,
             "robot": set(HexapodGeometry.FILE_KEYS) - shared,
             "camera": (set(CAMERA_KEYS) | set(OPENCV_TABLE_KEYS)) - shared}
    scores = dict.fromkeys(kinds, 0)
    for key in set(table) - shared:
        for kind, keys in kinds.items():
            scores[kind] += key in keys or suggest(key, keys) is not None
    ranked = sorted(scores.items(), key=lambda kv: -kv[1])
    if ranked[0][1] == 0 or ranked[0][1] == ranked[1][1]:
        return "scenario" if "name" in table and not ranked[0][1] else None
    return ranked[0][0]


def load_setup(text: str) -> Setup:
    """A setup from a built-in scenario name or a file (scenario, robot or camera).

    Raises:
        ScenarioError, ConfigFileError, GeometryError, CameraError: The file is invalid
            (naming the key).
        BenchmarkError: A file that is none of the three.
    """
    from hexapod.config import load_toml
    from vision.cameras import camera_preset, load_camera
    from vision.cameras.files.opencv import OPENCV_EXTENSIONS

    sc = load_scenario_file(text)
    if sc is not None:  # its controllers resolved as a run resolves them
        from benchmarks.study.scenario_checks import check_controllers

        return scenario_setup(check_controllers(sc)[0])
    path = Path(text)
    if path.suffix.lower() in OPENCV_EXTENSIONS:
        table: dict[str, Any] = {"opencv": str(path)}
    else:
        table = load_toml(path)
    kind = file_kind(table)
    if kind == "robot":
        g = HexapodGeometry.from_toml(path)
        cam = camera_preset("front", g)
        return Setup("robot", g, cam, _default_task(), Where(
            strokes=f"stroke_mm in {path}",
            points=f"base_points_mm / platform_points_mm in {path}",
            camera="the camera's placement (the front preset placed for this robot here)",
            task="[task] of a scenario"), None,
            ["camera: the front preset, placed for this robot (a scenario names yours)"],
            _weight_problems(g, path))
    if path.suffix.lower() in OPENCV_EXTENSIONS:
        return calibration_setup(path)
    if kind == "calibration":  # calibrate's output: read (checked), then said
        from benchmarks.study.calibration import read_calibrated_file

        made_with = read_calibrated_file(path)[1]
        source = table.get("source")
        raise BenchmarkError(
            f"{path}: a base-point calibration (hexapod-bench calibrate"
            + (f", from {source}" if isinstance(source, str) else "")
            + (f"; made with the robot {made_with['robot']} and the camera "
               f"{made_with['camera']}" if made_with else "")
            + "), readable; it is not a setup to check: give it to `hexapod-bench run "
            "--calibration FILE` or `servo --calibration FILE`, or name it in a scenario's "
            "[calibration] method = \"file\", file = \"...\" (docs/calibration.md)")
    if kind == "camera":
        from hexapod.geometry import deltalab

        cam = load_camera(path)
        return Setup("camera", deltalab(), cam, _default_task(), Where(
            strokes="[robot] of a scenario", points="[robot] of a scenario",
            camera=f"[camera_from_base] in {path}", task="[task] of a scenario",
            intrinsics=f"fx_px / fy_px in {path}"), None,
            ["robot: the deltalab preset (a scenario names yours)"], [])
    if not table:
        raise BenchmarkError(f"{path}: the file is empty (a scenario, a robot file or a "
                             "camera file: docs/scenarios.md, docs/robot-files.md)")
    raise BenchmarkError(f"{path}: cannot tell what this file is: a scenario has "
                         "'controllers', a robot file 'base_points_mm', a camera file "
                         "'fx_px' (or 'opencv') and [camera_from_base] (docs/robot-files.md)")


def _weight_problems(g: HexapodGeometry, path: Path) -> list[Problem]:
    """A robot file checked alone: a warning when its drives cannot hold its own platform
    still at home (what a scenario's check says of the dynamic world; alone it said
    nothing, e.g. of a platform_mass in grams)."""
    from benchmarks.study.payload_check import static_forces_at_home

    forces = static_forces_at_home(g)
    limit = np.asarray(g.drives.force_limit, float)
    if forces is None or not (np.abs(forces) > limit).any():
        return []
    leg = int(np.argmax(np.abs(forces) - limit))
    return [Problem("warning", f"in the dynamic world the robot's own weight needs "
                    f"{abs(forces[leg]):.0f} N on leg {leg} to hold it still at home, its "
                    f"drives' force limit is {limit[leg]:g} N: check [inertia]'s masses (kg) "
                    f"and [drives] force_limit (N) in {path}", "robot")]


#: The preset whose placement a calibration file's camera gets in ``check``, by kind.
CALIBRATION_POSE = {"perspective": "front", "fisheye": "fisheye"}


def calibration_setup(path: Path) -> Setup:
    """The setup of a calibration file checked alone (OpenCV, ROS ``camera_info``,
    Kalibr): such a file holds no pose, so its camera is placed where the preset of its
    kind sits for the deltalab robot (``front`` for a perspective camera, ``fisheye``,
    else ``omni``), and the keys to change are those of the scenario that names it."""
    from hexapod.geometry import deltalab
    from vision.cameras import camera_preset, load_camera

    g = deltalab()
    kind = load_camera(path).kind
    preset = CALIBRATION_POSE.get(kind, "omni")
    cam = load_camera(path, camera_from_base=camera_preset(preset, g).camera_from_base)
    t_mm = np.round(cam.camera_from_base.inverse().translation * 1e3, 1) + 0.0  # no -0.0
    where = Where(strokes="[robot] of a scenario", points="[robot] of a scenario",
                  camera=(f'the camera\'s pose in the scenario that names {path} ([camera] '
                          f'pose = "{preset}" or [camera.camera_from_base]; the file holds '
                          "no pose)"),
                  task="[task] of a scenario", intrinsics=f"the camera matrix in {path}")
    notes = ["robot: the deltalab preset (a scenario names yours)",
             f"camera pose: a calibration file holds none; placed where the '{preset}' "
             f"preset sits for this robot (projection centre at ({t_mm[0]:.1f}, "
             f"{t_mm[1]:.1f}, {t_mm[2]:.1f}) mm in the base frame); a scenario gives "
             f'yours: [camera] file = "{path.name}" with pose = "..." or '
             "[camera.camera_from_base]"]
    return Setup("camera", g, cam, _default_task(), where, None, notes, [])


def examine(setup: Setup) -> SetupReport:
    """Measure a setup (:func:`check_setup`) and add the problems found while loading."""
    partial = bool(setup.needs_camera) and len(setup.needs_camera or ()) < len(
        setup.controllers)
    needs = setup.needs_camera is None or (bool(setup.needs_camera) and not partial)
    report = check_setup(setup.geometry, setup.camera, *setup.task, needs_camera=needs,
                         where=setup.where)
    if partial:  # the camera's problems spoil the controllers that need it, not the study
        who = ", ".join(setup.needs_camera or ())
        report.problems = [
            Problem(p.severity, f"{p.text} (the trials of {who} would fail; the other "
                                "controllers do not need the camera)" if p.fails else
                    f"{p.text} (it concerns {who}; the other controllers do not need the "
                    "camera)", p.topic, p.fails)
            if p.topic == "camera" else p for p in report.problems]
    report.problems[:0] = setup.problems
    return report


def check_picture(path: Path, overwrite: bool = False) -> None:
    """Refuse a ``--picture`` name that is not .png/.jpg, or a user's file (without
    ``overwrite``), before any work.

    Raises:
        BenchmarkError: Another suffix.
        OutputError: A file hexapod-bench did not write.
    """
    if path.suffix.lower() not in (".png", ".jpg", ".jpeg"):
        raise BenchmarkError(f"--picture {path}: use a .png or .jpg name")
    check_replace(path, overwrite, kind="PNG" if path.suffix.lower() == ".png" else "JPEG")


def write_picture(setup: Setup, report: SetupReport, path: Path,
                  overwrite: bool = False) -> Path:
    """An image of the robot at home seen by the camera (the project's renderer), each
    edge drawn in one colour over its whole length, green when the camera sees it
    (``report.home_visible``) and red when not (a partly hidden edge is drawn across
    what hides it), only where the lens images it, legs numbered; PNG or JPEG by the
    suffix, marked as the project's (:func:`hexapod.outputs.write_output`).

    Raises:
        OutputError: ``path`` is a user's file (without ``overwrite``).
    """
    import cv2

    from hexapod.workspace import home_pose
    from vision.legs import limb_points, observe_legs
    from vision.render import render_legs

    home = home_pose(setup.geometry)
    img = cv2.cvtColor(render_legs(setup.camera, setup.geometry, *home, rng=0),
                       cv2.COLOR_GRAY2BGR)
    obs = observe_legs(setup.camera, setup.geometry, *home)
    # each edge as a polyline of its projected points (a curve through a distorting lens
    # or an omnidirectional camera)
    s = np.linspace(0.0, 1.0, 33)
    points = limb_points(obs.base_points, obs.directions, obs.radius, obs.lengths,
                         obs.normals, s)
    pixels, imaged = setup.camera.project(points)
    usable = np.asarray(imaged, bool) & np.all(np.isfinite(pixels), axis=-1)
    for i in range(6):
        for j in range(2):
            colour = (0, 200, 0) if report.home_visible[i, j] else (0, 0, 230)
            # the runs of points the lens images (beyond a lens's fold the pixels are
            # none of the image's: a camera at the base origin drew lines through its
            # centre, and numpy warned of the cast)
            for run in np.split(np.arange(len(s)), np.flatnonzero(np.diff(usable[i, j])) + 1):
                if len(run) >= 2 and usable[i, j, run[0]]:
                    cv2.polylines(img, [np.round(pixels[i, j, run]).astype(np.int32)],
                                  False, colour, 2, cv2.LINE_AA)
        ends = report.home_pixels[i, :, 0]
        if np.all(np.isfinite(ends)):
            x, y = (round(float(c)) for c in ends.mean(axis=0))
            cv2.putText(img, str(i), (x + 6, y + 6), cv2.FONT_HERSHEY_SIMPLEX, 0.7,
                        (255, 120, 0), 2, cv2.LINE_AA)
    ok, data = cv2.imencode(".jpg" if path.suffix.lower() in (".jpg", ".jpeg") else ".png",
                            img)
    if not ok:
        raise BenchmarkError(f"--picture: cannot encode {path}")
    return write_output(path, data.tobytes(), overwrite)


def cmd_check(args: argparse.Namespace) -> int:
    """Check a scenario, robot or camera file; exit 1 when the setup cannot run.

    A scenario goes through ``run``'s own pre-flight (:func:`benchmarks.study.preflight.
    preflight`): the same refusals in the same words (a file error: exit 2, as ``run``;
    a setup where every trial would fail: the details, then ``run``'s refusal, exit 1).
    """
    import sys

    from benchmarks.study.payload_check import describe_payload
    from benchmarks.study.preflight import preflight, refusal
    from benchmarks.study.trajectory_check import describe_trajectory

    overwrite = getattr(args, "overwrite", False)
    if args.picture:
        check_picture(Path(args.picture), overwrite)
    sc = load_scenario_file(args.file)
    refused = None
    extra: list[str] = []
    warned = 0
    if sc is not None:
        pre = preflight([sc])
        warned = len(pre.warnings)
        for text in pre.warnings:
            print(f"warning: {text}", file=sys.stderr)
        check = pre.checks[0]
        setup, report = check.setup, check.report
        extra = describe_trajectory(check.trajectory, check.scenario)
        extra += describe_payload(check.payload, check.scenario)
        refused = refusal(check)
    else:
        setup = load_setup(args.file)
        report = examine(setup)
    from benchmarks.study.check_text import describe

    for line in describe(setup, report, args.file, extra, warned):
        print(line)
    if args.picture:
        print(f"picture of the robot at home seen by the camera: "
              f"{write_picture(setup, report, Path(args.picture), overwrite)}")
    if refused is not None:  # run's refusal, word for word
        print(f"hexapod-bench: error: {refused}", file=sys.stderr)
    return 0 if report.can_run else CANNOT_RUN
