"""Calibration of the base points from leg observations (docs/math.md section 7), in studies.

- ``[calibration] method = "linear"``: every trial calibrates in its own (true)
  world first, with the scenario's noise, and its controllers get the estimates.
- ``[calibration] method = "file"`` (or ``hexapod-bench run --calibration FILE``):
  the controllers get the base points of a file written by ``hexapod-bench
  calibrate`` (or by a user from a real calibration).
- ``hexapod-bench calibrate SCENARIO --out DIR``: repeated calibrations in the
  scenario's worlds, ``DIR/calibration.json`` (estimates, errors against the
  truth, residuals, conditioning) and ``DIR/calibrated.toml`` (the parameter file).
"""

from __future__ import annotations

import json
import logging
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w

from benchmarks.study.scenario import Scenario
from hexapod.config import check_keys, get_matrix, get_number, load_toml
from hexapod.exceptions import ConfigFileError
from hexapod.outputs import GENERATOR, TEXT_MARKER

log = logging.getLogger(__name__)

CalibrationHook = Callable[..., tuple[np.ndarray, dict[str, float]]]


def calibration_hook(sc: Scenario) -> CalibrationHook | None:
    """The per-trial calibration function of a scenario, or None when it does not calibrate."""
    if sc.calibration.method == "none":
        return None
    if sc.calibration.method == "file":
        points = (np.asarray(sc.calibration_points, float) if sc.calibration_points is not None
                  else load_calibrated_base_points(str(sc.calibration.file)))

        def from_file(world: Any, rng: np.random.Generator) -> tuple[np.ndarray,
                                                                    dict[str, float]]:
            truth = world.camera.camera_from_base.apply(world.geometry.base_points)
            err = np.linalg.norm(points - truth, axis=1) * 1e3
            return points.copy(), {"median_error_mm": float(np.median(err)),
                                   "max_error_mm": float(np.max(err)),
                                   "max_component_error_mm":
                                       float(np.max(np.abs(points - truth))) * 1e3}

        return from_file

    user: tuple[Any, Any] | None = None  # (nominal robot, the user's camera) for images
    if rendered(sc):
        from benchmarks.sim.world import estimated_camera
        from benchmarks.study.provenance import scenario_setup

        _, nominal, _, camera = scenario_setup(sc)
        user = nominal, estimated_camera(camera,
                                         sc.calibration_error.at_scale().distortion_percent)

    def calibrate(world: Any, rng: np.random.Generator) -> tuple[np.ndarray,
                                                                dict[str, float]]:
        from vision.calibration import calibrate_in_world

        data = None if user is None else image_observations(
            sc, world, user[0], user[1], sc.calibration.configurations, rng)
        return calibrate_in_world(world.geometry, world.camera, sc.calibration, sc.noise, rng,
                                  data)

    return calibrate


def rendered(sc: Scenario) -> bool:
    """The scenario's calibration observes rendered images: its sensor renders them
    (``[sensor] kind = "image"``) and its ``[calibration]`` sets no ``noise_deg`` (which
    asks for the rotation noise model instead)."""
    return sc.sensor == "image" and sc.calibration.noise_deg is None


def image_observations(sc: Scenario, world: Any, nominal: Any, user_camera: Any,
                       configurations: str, rng: np.random.Generator) -> Any:
    """The calibration observations of ``world`` through the scenario's rendered images
    (its background, blur and pixel noise), read with the user's camera model
    ``user_camera`` and the nominal robot ``nominal`` as a run's image sensor reads them
    (:func:`vision.calibration.collect.collect_image_observations`)."""
    from vision.calibration import collect_image_observations
    from vision.image_sensor import ImageSensor

    sensor = ImageSensor(world.camera, user_camera, world.geometry, rng=rng,
                         background=sc.image.background, blur_px=sc.image.blur_px,
                         noise_std=sc.image.noise_std, estimated_geometry=nominal)
    return collect_image_observations(sensor, world.geometry, configurations, rng)


def load_calibrated_base_points(path: str | Path) -> np.ndarray:
    """Base points (6, 3) in the camera frame [m] from a ``calibrated.toml`` file.

    Raises:
        ConfigFileError: Missing file, bad TOML, missing or misspelt key, bad shape.
    """
    return read_calibrated_file(path)[0]


#: The keys of a ``[made_with]`` table (:mod:`benchmarks.study.provenance`).
MADE_WITH_KEYS = ("robot", "robot_fingerprint", "camera", "camera_fingerprint")


#: The smallest distance [m] between the farthest two base points of a calibrated file
#: (closer: a file in metres where millimetres are meant).
MIN_BASE_SPREAD = 0.01


def read_calibrated_file(path: str | Path) -> tuple[np.ndarray, dict[str, str] | None]:
    """Base points (6, 3) in the camera frame [m] and the ``[made_with]`` table (None for a
    file without one) of a ``calibrated.toml`` file.

    Raises:
        ConfigFileError: Missing file, bad TOML, missing or misspelt key, bad shape,
            points closer than :data:`MIN_BASE_SPREAD` (metres for millimetres).
    """
    table = load_toml(path)
    check_keys(table, ("base_points_camera_mm", "camera_from_base", "scale", "leg_radius_mm",
                       "source", "made_with"), str(path), required=("base_points_camera_mm",))
    points = get_matrix(table, "base_points_camera_mm", (6, 3), str(path)) * 1e-3
    spread = float(np.max(np.linalg.norm(points[:, None] - points[None], axis=-1)))
    if spread < MIN_BASE_SPREAD:  # no hexapod's base joints are that close together
        raise ConfigFileError(str(path), f"the six points are at most {spread * 1e3:.4g} mm "
                              "apart: given in metres? base_points_camera_mm is in "
                              "millimetres", key="base_points_camera_mm")
    for key in ("scale", "leg_radius_mm"):  # recorded, not used: yet a value must be one
        if key in table and not get_number(table, key, str(path)) > 0:
            raise ConfigFileError(str(path), f"must be positive, got {table[key]!r}", key=key)
    recorded = table.get("made_with")
    if recorded is None:
        return points, None
    if not isinstance(recorded, dict):
        raise ConfigFileError(str(path), "expected a table [made_with]", key="made_with")
    check_keys(recorded, MADE_WITH_KEYS, str(path), prefix="made_with.",
               required=MADE_WITH_KEYS)
    for key in MADE_WITH_KEYS:
        if not isinstance(recorded[key], str):
            raise ConfigFileError(str(path), f"expected a string, got {recorded[key]!r}",
                                  key=f"made_with.{key}")
    return points, dict(recorded)


def _prepared(sc: Scenario, out: Path, overwrite: bool) -> tuple[Any, Any, dict[str, str]]:
    """A calibration's output directory checked (nothing written), then the scenario's
    nominal robot, its camera and the ``[made_with]`` table of what it is made with."""
    from benchmarks.study.outdir import check_calibration_directory
    from benchmarks.study.provenance import made_with, scenario_setup

    check_calibration_directory(out, overwrite)
    robot_name, nominal, camera_name, camera = scenario_setup(sc)
    return nominal, camera, made_with(robot_name, nominal, camera_name, camera)


def run_calibration(sc: Scenario, out: Path, configurations: str | None = None,
                    repeat: int = 1, solver: str | None = None,
                    correct_scale: bool = False, overwrite: bool = False) -> dict[str, Any]:
    """Repeat the calibration in the scenario's worlds; write calibration.json and calibrated.toml.

    Repetition k uses the world of trial k (its calibration-error draw) and the
    scenario's noise; each sweep point of the scenario is calibrated separately.

    Returns:
        The content of ``calibration.json``.

    Raises:
        OutputError: ``out`` holds other files or a calibration already (and not
            ``overwrite``); nothing is written.
    """
    from benchmarks.sim import make_trial, trial_rng
    from vision.calibration import calibrate, error_summary
    from vision.calibration.study import simulated_observations

    nominal, camera, provenance = _prepared(sc, out, overwrite)
    cal_cfg = sc.calibration
    if configurations is not None:
        cal_cfg = replace(cal_cfg, configurations=configurations)
    if solver is not None:
        cal_cfg = replace(cal_cfg, solver=solver)
    points_out = []
    first_result = None
    all_diffs = []
    for p, point in enumerate(sc.expand()):
        diffs, results = [], []
        images = rendered(replace(point, calibration=cal_cfg))
        for k in range(repeat):
            setup = make_trial(point, k, nominal, camera)
            world = setup.world
            rng = trial_rng(point.seed, k, 3)
            data = (image_observations(point, world, setup.nominal_geometry,
                                       setup.estimated_camera, cal_cfg.configurations, rng)
                    if images else simulated_observations(world.geometry, world.camera,
                                                          cal_cfg, point.noise, rng))
            res = calibrate(data, nominal.leg_radius, nominal.base_points,
                            method=cal_cfg.solver,  # type: ignore[arg-type]
                            correct_scale=correct_scale,
                            min_singular_ratio=cal_cfg.min_singular_ratio,
                            warn_singular_ratio=cal_cfg.warn_singular_ratio)
            truth = world.camera.camera_from_base.apply(world.geometry.base_points)
            diffs.append(res.base_points - truth)
            results.append(res)
        summary = error_summary(np.array(diffs), np.zeros((6, 3)))
        lin = results[0].linear
        points_out.append({
            "point": p, "sweep": point.sweep, **summary,
            "min_singular_ratio": float(min(r.linear.singular_value_ratio.min()
                                            for r in results)),
            "ill_conditioned_legs": sorted({leg for r in results
                                            for leg in r.linear.ill_conditioned_legs}),
            "residual_rms_mm": (np.median([r.linear.residual_rms for r in results], axis=0)
                                * 1e3).tolist(),
            "configurations": int(lin.configurations.max()) if np.ndim(lin.configurations)
            else int(lin.configurations),
            "first_repetition": results[0].to_dict(),
            **_far_from_nominal(results[0].base_points, nominal, camera),
        })
        all_diffs += diffs
        if first_result is None:
            first_result = results[0]
    overall = error_summary(np.array(all_diffs), np.zeros((6, 3)))
    from benchmarks.study.study_record import study_of

    doc = {
        "generator": GENERATOR,
        "scenario": sc.name,
        "study": study_of(sc),  # (what reproduce checks before it reuses the directory)
        "configurations": cal_cfg.configurations,
        "solver": cal_cfg.solver,
        "warn_singular_ratio": cal_cfg.warn_singular_ratio,
        "min_singular_ratio": cal_cfg.min_singular_ratio,
        "repetitions": repeat,
        "median_error_mm": overall["median_error_mm"],
        "max_error_mm": overall["max_error_mm"],
        "max_component_error_mm": overall["max_component_error_mm"],
        "made_with": provenance,
        "points": points_out,
    }
    out.mkdir(parents=True, exist_ok=True)
    (out / "calibration.json").write_text(json.dumps(doc, indent=1))
    if first_result is None:  # a scenario always has at least one sweep point
        raise RuntimeError("no calibration was run")
    write_calibrated_file(out / "calibrated.toml", first_result, source=f"{sc.name} "
                          f"(repetition 0, sweep point 0, {cal_cfg.configurations})",
                          made_with=provenance)
    return doc


def _lengths_outside(lengths: np.ndarray, nominal: Any) -> dict[str, Any]:
    """The observations' leg lengths outside the robot's stroke (by more than 1 mm): the
    calibration does not use them, but lengths in metres, or of another robot, say the
    file is not what it seems (``lengths_outside_stroke``: configuration, leg, mm)."""
    q = np.asarray(lengths, float)
    lo, hi = nominal.stroke
    bad = np.argwhere((q < lo - 1e-3) | (q > hi + 1e-3))
    return {"lengths_outside_stroke": [[int(k), int(i), round(float(q[k, i]) * 1e3, 3)]
                                       for k, i in bad[:20]],
            "lengths_outside_stroke_count": len(bad)}


def calibrate_from_file(sc: Scenario, observations: Path, out: Path, solver: str | None = None,
                        correct_scale: bool = False, overwrite: bool = False) -> dict[str, Any]:
    """Calibrate from observations a user measured (e.g. with a real camera).

    Args:
        sc: The scenario gives the nominal robot (leg radius, CAD base points).
        observations: A ``.json`` or ``.npz`` file of edge normals (camera frame) and
            leg lengths (see :meth:`vision.calibration.CalibrationData.from_dict`).
        out: Output directory (``calibration.json``, ``calibrated.toml``).
        solver: ``"lstsq"`` or ``"irls"`` (default: the scenario's).
        correct_scale: Divide the estimates by the measured scale.
        overwrite: Replace a calibration in ``out``, or write among other files.

    Returns:
        The content of ``calibration.json`` (no error against a truth: there is none).

    Raises:
        OutputError: ``out`` holds other files or a calibration already (and not
            ``overwrite``); nothing is written.
    """
    from benchmarks.exceptions import BenchmarkError
    from vision.calibration import CalibrationData, calibrate
    from vision.exceptions import CalibrationError

    nominal, camera, provenance = _prepared(sc, out, overwrite)
    given = CalibrationData.load(observations)

    def solve(data: Any) -> Any:
        return calibrate(data, nominal.leg_radius, nominal.base_points,
                         method=(solver or sc.calibration.solver),  # type: ignore[arg-type]
                         correct_scale=correct_scale,
                         min_singular_ratio=sc.calibration.min_singular_ratio,
                         warn_singular_ratio=sc.calibration.warn_singular_ratio,
                         warn=False)  # (each candidate's solve warned of each leg, up to
        # 4 times: the command says the kept one's legs, once)

    try:
        res, data = _with_signs(given, solve,
                                camera.camera_from_base.apply(nominal.base_points),
                                nominal.leg_radius, camera.kind == "perspective")
    except CalibrationError as exc:  # the user's measurements: say which file
        raise BenchmarkError(f"{observations}: {exc} (nothing written)") from exc
    flipped = int(np.sum(np.any(np.asarray(data.normals) != np.asarray(given.normals),
                                axis=-1) & np.asarray(given.edge_visible, bool)))
    disagree = float(np.max(res.linear.residual_rms)) > SIGN_RESIDUAL * nominal.leg_radius
    far = _far_from_nominal(res.base_points, nominal, camera)
    from vision.calibration import rigid_fit

    # how well the points fit once divided by their scale (a leg-radius error scales them)
    scaled_fit = rigid_fit(res.linear.base_points / res.scale, nominal.base_points)[2]
    out.mkdir(parents=True, exist_ok=True)
    doc = {"generator": GENERATOR, "scenario": sc.name, "observations": str(observations),
           "configurations": int(data.n_configurations),
           "solver": solver or sc.calibration.solver, "made_with": provenance,
           "normals_flipped": flipped, "equations_disagree": disagree,
           "fit_rms_scale_corrected_mm": float(scaled_fit) * 1e3,
           "result": res.to_dict(), **far,
           **_lengths_outside(data.lengths, nominal)}
    (out / "calibration.json").write_text(json.dumps(doc, indent=1))
    write_calibrated_file(out / "calibrated.toml", res, source=str(observations),
                          made_with=provenance)
    return doc


#: The largest RMS residual ``n . A + r`` of a leg's equations, in leg radii, of
#: observations taken as consistent (noisy measurements: a fraction of a millimetre; an
#: edge normal of the other sign: about two radii).
SIGN_RESIDUAL = 0.25


def _with_signs(given: Any, solve: Callable[[Any], Any], nominal_points: np.ndarray,
                leg_radius: float, perspective: bool) -> tuple[Any, Any]:
    """The calibration of a user's observations and the observations it used. The
    equation is ``n . A = -r`` (the leg's axis on the negative side of the edge's plane
    through the camera centre, ``docs/math.md`` section 4), and a line fitted in an image
    has a normal of either sign.

    The file's signs are kept when its equations agree (every leg's RMS residual under
    :data:`SIGN_RESIDUAL` radii) and, for a perspective camera, its base points lie in
    front of it: a nominal camera pose, however wrong, never turns a consistent file.
    A file whose every sign is reversed agrees too, with the points mirrored through the
    camera centre (behind a perspective camera): reversed back. A camera that sees all
    around (omnidirectional, fisheye) has no "in front": of a consistent file and its
    mirror image, the one nearer the nominal points is taken (the mirror lies twice the
    base points' distance from the camera away, half a metre on the DeltaLab). A file
    whose equations disagree (signs mixed): each normal oriented by the nominal base
    points (camera frame [m]), then by that solution's estimates; the candidate taken is
    one whose equations agree, in front, the nearest to the nominal points, else the
    file's."""
    limit = SIGN_RESIDUAL * leg_radius

    def agrees(res: Any) -> bool:
        return float(np.max(res.linear.residual_rms)) <= limit

    def in_front(res: Any) -> bool:
        return not perspective or float(np.median(res.linear.base_points[:, 2])) > 0

    def off(res: Any) -> float:  # the median distance from the nominal points [m]
        return float(np.median(np.linalg.norm(res.linear.base_points - nominal_points,
                                              axis=1)))

    first = solve(given)
    if agrees(first) and perspective and in_front(first):
        return first, given
    if agrees(first):  # every sign reversed: the mirror image through the camera centre
        reversed_ = replace(given, normals=-np.asarray(given.normals, dtype=float))
        res = solve(reversed_)
        if not agrees(res):
            return first, given
        if perspective:
            return (res, reversed_) if in_front(res) else (first, given)
        return (res, reversed_) if off(res) < off(first) else (first, given)
    candidates = []
    points = nominal_points
    for _ in range(2):
        data = _oriented(given, points)
        res = solve(data)
        candidates.append((res, data))
        points = res.linear.base_points
    good = [c for c in candidates if agrees(c[0]) and in_front(c[0])]
    if not good:
        return first, given
    return min(good, key=lambda c: off(c[0]))


def _oriented(data: Any, points: np.ndarray) -> Any:
    """``data`` with each visible edge normal ``n`` turned to ``n . A < 0`` at ``points``
    (camera frame [m])."""
    n = np.array(data.normals, dtype=float)
    side = np.einsum("nijk,ik->nij", n, np.asarray(points, dtype=float))
    flip = np.asarray(data.edge_visible, bool) & np.isfinite(side) & (side > 0)
    n[flip] *= -1.0
    return replace(data, normals=n)


def _far_from_nominal(points: np.ndarray, nominal: Any, camera: Any) -> dict[str, Any]:
    """The distances of estimated base points from the nominal ones and the legs beyond
    :data:`benchmarks.study.provenance.FAR_FROM_NOMINAL_MM`."""
    from benchmarks.study.provenance import FAR_FROM_NOMINAL_MM, distances_from_nominal

    d = distances_from_nominal(points, nominal, camera)
    return {"distance_from_nominal_mm": d.round(3).tolist(),
            "far_from_nominal_threshold_mm": FAR_FROM_NOMINAL_MM,
            "far_from_nominal_legs": [int(i) for i in np.flatnonzero(d > FAR_FROM_NOMINAL_MM)]}


def write_calibrated_file(path: Path, result: Any, source: str,
                          made_with: dict[str, str] | None = None) -> None:
    """Write the calibrated parameters (millimetres, degrees) read by ``run --calibration``.

    Args:
        path: The ``calibrated.toml`` to write.
        result: The calibration (:class:`vision.calibration.CalibrationResult`).
        source: What it was calibrated from (free text).
        made_with: The robot and camera it was made with
            (:func:`benchmarks.study.provenance.made_with`).
    """
    from hexapod.se3 import log_so3

    T = result.camera_from_base
    table = {
        "source": source,
        "base_points_camera_mm": (result.base_points * 1e3).round(6).tolist(),
        "camera_from_base": {
            "translation_mm": (T.translation * 1e3).round(6).tolist(),
            "rotation_vector_deg": np.rad2deg(log_so3(T.rotation)).round(9).tolist(),
        },
        "scale": float(result.scale),
        "leg_radius_mm": float(result.radius * 1e3),
    }
    if made_with is not None:
        table["made_with"] = dict(made_with)
    path.write_text(f"# {TEXT_MARKER} (hexapod-bench calibrate)\n" + tomli_w.dumps(table))
