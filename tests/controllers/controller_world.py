"""A tiny perfect world for the controller tests: true pose -> observation, exact motion.

Features are computed from the TRUE kinematics and camera (``legs_in_frame``,
``vision.legs.leg_edges``, ``camera.normal_to_line``), never from the formulas
of ``tests/controllers/interaction_oracle.py``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controllers.base import ControllerContext, Goal, Observation
from hexapod.fk import forward_kinematics
from hexapod.geometry import HexapodGeometry
from hexapod.kinematics import LegState, legs_in_frame, twist_to_frame
from hexapod.se3 import integrate_pose
from hexapod.workspace import home_pose, sample_poses
from vision.cameras import Camera, front_camera, omni_camera
from vision.legs import leg_edges


def make_camera(kind: str, geometry: HexapodGeometry) -> Camera:
    """The front perspective camera or the omnidirectional one, placed for ``geometry``."""
    return front_camera(geometry) if kind == "perspective" else omni_camera(geometry)


@dataclass
class World:
    """Robot and camera, both perfectly known.

    Attributes:
        geometry: The robot.
        camera: The camera (its ``camera_from_base`` places it).
    """

    geometry: HexapodGeometry
    camera: Camera

    @property
    def kind(self) -> str:
        return self.camera.kind

    def legs(self, R: np.ndarray, t: np.ndarray) -> LegState:
        """Legs in the camera frame for the platform pose (R, t) in the base frame."""
        return legs_in_frame(self.geometry, R, t, self.camera.camera_from_base)

    def features(self, R: np.ndarray, t: np.ndarray) -> dict[str, np.ndarray | None]:
        """True lengths, directions, edge normals and (perspective) lines."""
        legs = self.legs(R, t)
        normals, exists = leg_edges(legs.base_points, legs.directions, self.geometry.leg_radius)
        if not np.all(exists):
            raise RuntimeError("test world: camera inside a leg cylinder")
        lines = (self.camera.normal_to_line(normals)  # type: ignore[attr-defined]
                 if self.kind == "perspective" else None)
        return {"lengths": legs.lengths, "directions": legs.directions, "normals": normals,
                "lines": lines, "base_points": legs.base_points}

    def observation(self, R: np.ndarray, t: np.ndarray, time: float = 0.0) -> Observation:
        f = self.features(R, t)
        return Observation(time, f["lengths"], normals=f["normals"], lines=f["lines"],
                           directions=f["directions"])

    def goal(self, R: np.ndarray, t: np.ndarray) -> Goal:
        f = self.features(R, t)
        return Goal(normals=f["normals"], lines=f["lines"], directions=f["directions"],
                    lengths=f["lengths"], rotation=R, translation=t)

    def context(self, goal: Goal, dt: float, margin: float = 0.002) -> ControllerContext:
        A = self.camera.camera_from_base.apply(self.geometry.base_points)
        return ControllerContext(A, self.geometry, self.camera, dt, goal, stroke_margin=margin)

    def move(self, R: np.ndarray, t: np.ndarray, twist_camera: np.ndarray, dt: float
             ) -> tuple[np.ndarray, np.ndarray]:
        """Move the platform by a twist given in the camera frame, exactly (SE(3) exponential)."""
        twist_base = twist_to_frame(np.asarray(twist_camera, float),
                                    self.camera.camera_from_base.inverse())
        return integrate_pose(R, t, twist_base, dt)

    def poses(self, n: int, rng: np.random.Generator, max_translation: float = 0.04,
              max_angle: float = np.deg2rad(8.0), margin: float = 0.01
              ) -> tuple[np.ndarray, np.ndarray]:
        return sample_poses(self.geometry, n, rng=rng, max_translation=max_translation,
                            max_angle=max_angle, margin=margin)

    def home(self) -> tuple[np.ndarray, np.ndarray]:
        return home_pose(self.geometry)


@dataclass
class Run:
    """History of a closed loop.

    Attributes:
        error_norms: (k,) ``Command.error_norm`` per step.
        position_errors: (k + 1,) distance of the platform origin to the goal [m].
        lengths: (k + 1, 6) true leg lengths [m].
        velocities: (k, 6) leg velocity commands [m/s].
        commands: The commands.
        poses: (R, t) before each command.
    """

    error_norms: np.ndarray
    position_errors: np.ndarray
    lengths: np.ndarray
    velocities: np.ndarray
    commands: list
    poses: list


def closed_loop(world: World, controller, start: tuple[np.ndarray, np.ndarray],  # type: ignore[no-untyped-def]
                goal: tuple[np.ndarray, np.ndarray], dt: float, steps: int,
                hide=None, stop_below: float = 0.0, move_legs: bool = False) -> Run:
    """Perfect closed loop: observe the true pose, step, integrate the commanded twist exactly.

    Args:
        hide: Optional ``f(observation, k)`` that edits the observation (visibility).
        stop_below: Stop once the position error is below this [m].
        move_legs: Integrate the leg velocities (``q += dt q_dot``) and find the pose
            by forward kinematics, as a real robot does, instead of the twist.
    """
    R, t = start
    tg = goal[1]
    norms, perr, lens, vels, cmds = [], [np.linalg.norm(t - tg)], [world.legs(R, t).lengths], [], []
    poses = []
    for k in range(steps):
        poses.append((R, t))
        obs = world.observation(R, t, k * dt)
        if hide is not None:
            hide(obs, k)
        cmd = controller.step(obs)
        if not cmd.ok:
            raise AssertionError(f"step {k}: refused: {cmd.reason}")
        cmds.append(cmd)
        norms.append(cmd.error_norm)
        vels.append(cmd.velocities)
        if move_legs:
            q = world.legs(R, t).lengths + dt * cmd.velocities
            sol = forward_kinematics(world.geometry, q, guess=(R, t), check_stroke=False)
            R, t = sol.rotation, sol.translation
        else:
            if cmd.twist is None:
                raise AssertionError("the controller gives no twist")
            R, t = world.move(R, t, cmd.twist, dt)
        perr.append(np.linalg.norm(t - tg))
        lens.append(world.legs(R, t).lengths)
        if perr[-1] < stop_below:
            break
    return Run(np.array(norms), np.array(perr), np.array(lens), np.array(vels), cmds, poses)
