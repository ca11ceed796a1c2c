"""The truth of a trial: its world (true robot, camera, encoder offsets), drawn from the
scenario's calibration-error model and the trial's seed, its start and goal poses, and
the nominal parameters the controllers are told."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from benchmarks.sim.inputs import SimScenario
from hexapod import HexapodGeometry, Transform, forward_kinematics_batch
from hexapod.dynamics.payload import Payload, model_payload, with_payload
from hexapod.geometry import preset as geometry_preset
from hexapod.kinematics import inverse_kinematics
from hexapod.se3 import exp_so3
from hexapod.workspace import sample_poses_many
from vision.cameras import Camera, camera_preset


def load_geometry(scenario: SimScenario) -> HexapodGeometry:
    """The nominal geometry of a scenario (the data read when it was loaded, if any), with
    the scenario's ``[drives]`` changes."""
    if scenario.geometry_data is not None:
        geometry: HexapodGeometry = scenario.geometry_data
    elif scenario.robot_geometry is not None:
        geometry = HexapodGeometry.from_toml(scenario.robot_geometry)
    else:
        geometry = geometry_preset(scenario.robot_preset or "deltalab")
    bandwidth = scenario.drives.velocity_bandwidth_hz
    if bandwidth > 0:
        drives = replace(geometry.drives, velocity_bandwidth=np.full(6, float(bandwidth)))
        geometry = replace(geometry, drives=drives)
    return geometry


def load_camera(scenario: SimScenario, geometry: HexapodGeometry) -> Camera:
    """The nominal camera of a scenario (the data read when it was loaded, if any)."""
    if scenario.camera_data is not None:
        return scenario.camera_data  # type: ignore[no-any-return]
    if scenario.camera_file is not None:
        from vision.cameras import load_camera as _load

        return _load(scenario.camera_file)
    return camera_preset(scenario.camera_preset or "front", geometry)


@dataclass
class World:
    """The truth of one trial (never shown to the controller).

    Attributes:
        geometry: True geometry.
        camera: True camera (intrinsics and pose).
        joint_offsets: (6,) encoder offsets [m]: measured = true + offset.
    """

    geometry: HexapodGeometry
    camera: Camera
    joint_offsets: np.ndarray


@dataclass
class TrialSetup:
    """Everything one trial needs, drawn from its seed.

    Attributes:
        trial: Trial index.
        world: The truth.
        nominal_geometry, estimated_camera: What the user believes the robot and the
            camera are.
        base_points: (6, 3) estimated base points in the camera frame [m].
        start_rotation, start_translation, goal_rotation, goal_translation: True start
            and goal poses (base frame) [-, m].
        start_lengths: (6,) true start leg lengths [m].
        shared: True when the world is the nominal one (trials can be batched).
        calibration: Calibration summary when the scenario calibrates first.
    """

    trial: int
    world: World
    nominal_geometry: HexapodGeometry
    estimated_camera: Camera
    base_points: np.ndarray
    start_rotation: np.ndarray
    start_translation: np.ndarray
    goal_rotation: np.ndarray
    goal_translation: np.ndarray
    start_lengths: np.ndarray
    shared: bool
    calibration: dict[str, float] = field(default_factory=dict)


def trial_rng(seed: int, trial: int, stream: int) -> np.random.Generator:
    """The random stream ``stream`` of trial ``trial`` (0: world, 1: sensor, 2: goal image,
    3: calibration, 4: inertial parameters)."""
    return np.random.default_rng([int(seed), int(trial), int(stream)])


def _perturb_camera(camera: Camera, z_rot: np.ndarray, z_pos: np.ndarray, z_k: np.ndarray,
                    ce: Any) -> Camera:
    T = camera.camera_from_base
    dR = exp_so3(np.deg2rad(ce.camera_pose_deg) * z_rot)
    dp = 1e-3 * ce.camera_pose_mm * z_pos
    new_T = Transform(dR @ T.rotation, dR @ T.translation + dp)
    K = camera.K.copy()
    s = 1e-2 * ce.intrinsics_percent
    K[0, 0] *= 1 + s * z_k[0]
    K[1, 1] *= 1 + s * z_k[1]
    K[0, 2] *= 1 + s * z_k[2]
    K[1, 2] *= 1 + s * z_k[3]
    return camera.replace(K=K, camera_from_base=new_T)


#: A calibration run per trial: ``(world, rng) -> (estimated base points (6, 3) [m],
#: summary)``.
Calibrate = Callable[[World, np.random.Generator], tuple[np.ndarray, dict[str, float]]]


def make_trial(sc: SimScenario, trial: int, nominal: HexapodGeometry, camera: Camera
               ) -> TrialSetup:
    """Draw the truth, start and goal of one trial from ``(seed, trial)``.

    The standard-normal draws are made in a fixed order whatever the scenario's
    error magnitudes, so trials are paired across the points of a sweep.
    """
    out = make_trials(sc, [trial], nominal, camera)[0]
    if isinstance(out, BaseException):
        raise out
    return out


def make_trials(sc: SimScenario, trials: list[int], nominal: HexapodGeometry, camera: Camera,
                calibrate: Calibrate | None = None) -> list[TrialSetup | Exception]:
    """:func:`make_trial` for many trials, the same to the last bit, their random poses
    drawn in one batch (:func:`hexapod.workspace.sample_poses_many`); per trial its setup
    or the exception that :func:`make_trial` raises for it (that trial's failure)."""
    ce = sc.calibration_error.at_scale()
    shared = ce.nominal_world()  # no error: every trial shares the nominal world
    drawn: list[tuple[np.random.Generator, World, Any, bool] | Exception] = []
    for trial in trials:
        try:
            drawn.append(_draw_world(sc, trial, nominal, camera, ce, shared))
        except Exception as exc:  # that trial's failure
            drawn.append(exc)
    ok = [k for k, d in enumerate(drawn) if not isinstance(d, Exception)]
    poses: dict[int, Any] = {}
    task = sc.task
    if task.kind != "fixed" and ok:
        many = sample_poses_many(
            [drawn[k][1].geometry for k in ok],  # type: ignore[index]
            2, [drawn[k][0] for k in ok],  # type: ignore[index]
            max_translation=1e-3 * task.max_translation_mm,
            max_angle=np.deg2rad(task.max_angle_deg), margin=1e-3 * task.margin_mm)
        poses = dict(zip(ok, many, strict=True))
    base_points = camera.camera_from_base.apply(nominal.base_points)
    model = nominal  # the controllers' model: [robot] model's inertia and drives, if given
    model_data = getattr(sc, "model_data", None)  # a study's [robot] model, if any
    if model_data is not None:
        model = nominal.replace(inertia=model_data.inertia, drives=model_data.drives)
    payload = sc.payload.body(sc.source) if sc.payload is not None else None
    if payload is not None and not payload.empty:  # (no payload: not a bit changes)
        drawn = _loaded(drawn, payload)
        model = model.replace(inertia=with_payload(
            model.inertia, model_payload(payload, ce.payload_mass_percent)))
    start_lengths = _start_lengths(drawn, poses)
    # the same for every trial of the point: the user's camera, a fixed task's poses per robot
    user_camera = estimated_camera(camera, ce.distortion_percent)
    fixed: dict[int, Any] = {}
    out: list[TrialSetup | Exception] = []
    for k, trial in enumerate(trials):
        d = drawn[k]
        if isinstance(d, Exception):
            out.append(d)
            continue
        _, world, _, shared = d
        try:
            if task.kind == "fixed":
                key = id(world.geometry)
                if key not in fixed:  # (a failure is each trial's: not kept)
                    fixed[key] = _fixed_poses(sc, world.geometry)
                pose = tuple(a.copy() for a in fixed[key])  # (each trial its arrays)
            else:
                pose = poses[k]
                if isinstance(pose, Exception):
                    raise pose
            (R_s, R_g), (t_s, t_g) = pose
            if task.kind == "trajectory":  # a closed curve ends where it started
                from benchmarks.sim.reference import trajectory_end

                R_g, t_g = trajectory_end(task, R_s, t_s, R_g, t_g)
            q_s = (start_lengths[k] if k in start_lengths
                   else inverse_kinematics(world.geometry, R_s, t_s))
            points = base_points.copy()
            calibration: dict[str, float] = {}
            if calibrate is not None:
                points, calibration = calibrate(world, trial_rng(sc.seed, trial, 3))
            out.append(TrialSetup(trial, world, model, user_camera, points,
                                  R_s, t_s, R_g, t_g, q_s, shared, calibration))
        except Exception as exc:  # that trial's failure
            out.append(exc)
    return out


def _loaded(drawn: list[Any], payload: Payload) -> list[Any]:
    """The drawn worlds with ``payload`` fixed to their true platforms (a robot shared by
    several worlds stays shared: loaded once)."""
    loaded: dict[int, HexapodGeometry] = {}
    out: list[Any] = []
    for d in drawn:
        if isinstance(d, Exception):
            out.append(d)
            continue
        rng, world, ce, shared = d
        g = world.geometry
        if id(g) not in loaded:
            loaded[id(g)] = g.replace(inertia=with_payload(g.inertia, payload))
        out.append((rng, replace(world, geometry=loaded[id(g)]), ce, shared))
    return out


def _start_lengths(drawn: list[Any], poses: dict[int, Any]) -> dict[int, np.ndarray]:
    """The true start leg lengths of the trials with random poses."""
    ks = [k for k, pose in poses.items() if not isinstance(pose, Exception)]
    q = inverse_kinematics_by_robot([drawn[k][1].geometry for k in ks],
                                    np.array([poses[k][0][0] for k in ks]),
                                    np.array([poses[k][1][0] for k in ks]))
    return dict(zip(ks, q, strict=True))


def inverse_kinematics_by_robot(geometries: list[HexapodGeometry], rotations: np.ndarray,
                                translations: np.ndarray) -> np.ndarray:
    """(n, 6) the leg lengths [m] of poses (n, 3, 3), (n, 3) [m] each in its robot, one
    call per robot (the arithmetic is elementwise: the bits of one call per pose)."""
    out = np.empty((len(geometries), 6))
    groups: dict[int, list[int]] = {}
    for k, g in enumerate(geometries):
        groups.setdefault(id(g), []).append(k)
    for ks in groups.values():
        out[ks] = inverse_kinematics(geometries[ks[0]], rotations[ks], translations[ks])
    return out


def _draw_world(sc: SimScenario, trial: int, nominal: HexapodGeometry, camera: Camera, ce: Any,
                shared: bool) -> tuple[np.random.Generator, World, Any, bool]:
    """The trial's generator (after the world's draws), its world, the scaled
    calibration error ``ce`` and whether the world is the nominal one (``shared``)."""
    rng = trial_rng(sc.seed, trial, 0)
    # 53 standard normals in one call: the same stream as one call per block
    z = rng.standard_normal(53)
    z_base = z[0:18].reshape(6, 3)
    z_plat = z[18:36].reshape(6, 3)
    z_off, z_rot, z_pos, z_k, z_r = z[36:42], z[42:45], z[45:48], z[48:52], z[52]
    if shared:
        true_geometry, true_camera, offsets = nominal, camera, np.zeros(6)
    else:
        true_geometry = nominal.replace(
            base_points=nominal.base_points + 1e-3 * ce.base_points_mm * z_base,
            platform_points=nominal.platform_points + 1e-3 * ce.platform_points_mm * z_plat,
            leg_radius=nominal.leg_radius * (1 + 1e-2 * ce.leg_radius_percent * z_r),
        )
        true_camera = _perturb_camera(camera, z_rot, z_pos, z_k, ce)
        offsets = 1e-3 * ce.joint_offsets_mm * z_off
        if ce.mass_percent or ce.inertia_percent:  # its own stream: the draws above stay
            true_geometry = true_geometry.replace(inertia=perturbed_inertia(
                true_geometry.inertia, ce.mass_percent, ce.inertia_percent,
                trial_rng(sc.seed, trial, 4)))
        if ce.model_mass_error_percent or ce.model_inertia_error_percent:
            true_geometry = true_geometry.replace(inertia=model_error_inertia(
                true_geometry.inertia, ce.model_mass_error_percent,
                ce.model_inertia_error_percent))
        if (ce.model_friction_error_percent or ce.model_rotor_inertia_error_percent
                or ce.model_drive_bandwidth_error_percent):
            true_geometry = true_geometry.replace(drives=model_error_drives(
                true_geometry.drives, ce.model_friction_error_percent,
                ce.model_rotor_inertia_error_percent, ce.model_drive_bandwidth_error_percent))
    return rng, World(true_geometry, true_camera, offsets), ce, shared


def perturbed_inertia(inertia: Any, mass_percent: float, inertia_percent: float,
                      rng: np.random.Generator) -> Any:
    """A true robot's inertial parameters around the robot file's: each body's mass
    (platform, leg body, leg rod) times ``exp(s_m z)`` and its rotational inertia times
    ``exp(s_i z')``, ``s`` the relative standard deviations [%] / 100 (positive factors:
    a tensor stays positive definite and within the triangle inequality). Six standard
    normals drawn from ``rng``, in a fixed order, whatever the magnitudes."""
    z = rng.standard_normal(6)
    return _scaled_inertia(inertia, np.exp(1e-2 * mass_percent * z[:3]),
                           np.exp(1e-2 * inertia_percent * z[3:]))


def model_error_inertia(inertia: Any, mass_error_percent: float,
                        inertia_error_percent: float) -> Any:
    """The true robot's inertial parameters when the model (``inertia``, the robot
    file's) is off by the given errors [%]: every body's mass divided by
    ``1 + e_m / 100`` and its rotational inertia by ``1 + e_i / 100`` (the model is the
    truth times those factors)."""
    fm = 1.0 / (1.0 + 1e-2 * mass_error_percent)
    fi = 1.0 / (1.0 + 1e-2 * inertia_error_percent)
    return _scaled_inertia(inertia, (fm, fm, fm), (fi, fi, fi))


def _scaled_inertia(inertia: Any, mass: Any, rotational: Any) -> Any:
    """``inertia`` with the platform's, leg body's and leg rod's masses times ``mass[0..2]``
    and their rotational inertias times ``rotational[0..2]``."""
    return inertia.replace(
        platform_mass=inertia.platform_mass * mass[0], body_mass=inertia.body_mass * mass[1],
        rod_mass=inertia.rod_mass * mass[2],
        platform_inertia=np.asarray(inertia.platform_inertia) * rotational[0],
        body_inertia=np.asarray(inertia.body_inertia) * rotational[1],
        rod_inertia=np.asarray(inertia.rod_inertia) * rotational[2])


def model_error_drives(drives: Any, friction_error_percent: float,
                       rotor_inertia_error_percent: float,
                       bandwidth_error_percent: float) -> Any:
    """The true robot's drives when the model (``drives``) is off by the given errors [%]
    (as :func:`model_error_inertia`): friction, rotor inertia and velocity bandwidth
    divided by ``1 + e / 100``.

    Raises:
        DriveError: The true drives are impossible (a Coulomb friction at or above the
            force limit), naming the leg.
    """
    ff = 1.0 / (1.0 + 1e-2 * friction_error_percent)
    fr = 1.0 / (1.0 + 1e-2 * rotor_inertia_error_percent)
    fb = 1.0 / (1.0 + 1e-2 * bandwidth_error_percent)
    return drives.replace(
        viscous=np.asarray(drives.viscous) * ff, coulomb=np.asarray(drives.coulomb) * ff,
        rotor_inertia=np.asarray(drives.rotor_inertia) * fr,
        velocity_bandwidth=np.asarray(drives.velocity_bandwidth) * fb)


def _fixed_poses(sc: SimScenario, geometry: HexapodGeometry
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Start and goal poses (2, 3, 3), (2, 3) of a fixed task (its leg lengths)."""
    task = sc.task
    q_start = np.asarray(task.start_mm, float) * 1e-3
    q_goal = np.asarray(task.goal_mm, float) * 1e-3
    sol = forward_kinematics_batch(geometry, np.stack([q_start, q_goal]))
    if not np.all(sol.converged):
        raise ValueError(f"{sc.source}: task start/goal leg lengths have no pose")
    return sol.rotations, sol.translations


def estimated_camera(camera: Camera, distortion_percent: float) -> Camera:
    """The camera model the user has: the nominal camera, whose lens distortion is
    missed by ``distortion_percent`` [%] (100: a model without distortion)."""
    if distortion_percent == 0.0 or not getattr(camera, "is_distorted", False):
        return camera
    return camera.lens_scaled(1.0 - 1e-2 * distortion_percent)
