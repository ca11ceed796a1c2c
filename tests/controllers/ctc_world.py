"""A dynamic world for the computed-torque tests: the study's dynamic integrator
(:class:`hexapod.dynamics.robots.DynamicRobots`, force-mode drives, 20 sub-steps per
period) and a camera seeing the TRUE legs (``legs_in_frame``, ``vision.legs.leg_edges``),
the encoders reading the true lengths and leg rates. The controller gets a context built
from a NOMINAL geometry and camera that may differ from the truth.

The drives have no friction (a force held over the period against a velocity-dependent
friction is not a model error the laws can cancel); their rotor inertia is kept (it is
in the nominal model).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from controllers.base import Command, Controller, ControllerContext, Goal, Observation
from hexapod import HexapodGeometry
from hexapod.dynamics.robots import DynamicRobots
from hexapod.kinematics import inverse_kinematics, legs_in_frame
from hexapod.se3 import exp_so3
from hexapod.trajectory import PoseTrajectory
from hexapod.workspace import home_pose
from vision.cameras import Camera, front_camera
from vision.legs import leg_edges

DT = 0.02
PHYSICS_STEPS = 20


def ideal_drives(g: HexapodGeometry) -> HexapodGeometry:
    """The robot with frictionless drives."""
    return dataclasses.replace(g, drives=dataclasses.replace(
        g.drives, viscous=np.zeros(6), coulomb=np.zeros(6)))


def perturbed(g: HexapodGeometry, error: float, seed: int = 0) -> HexapodGeometry:
    """``g`` with every base and platform point moved by ``error`` [m] in a random
    direction (a geometric calibration error)."""
    rng = np.random.default_rng(seed)

    def move(p: np.ndarray) -> np.ndarray:
        d = rng.normal(size=p.shape)
        return p + error * d / np.linalg.norm(d, axis=1, keepdims=True)  # type: ignore[no-any-return]

    return dataclasses.replace(g, base_points=move(g.base_points),
                               platform_points=move(g.platform_points))


@dataclass
class CtcWorld:
    """The true robot and camera, and what the controller is told.

    Attributes:
        truth: The true robot.
        camera: The true camera.
        nominal: The controller's geometry (the truth when the model is exact).
    """

    truth: HexapodGeometry
    camera: Camera
    nominal: HexapodGeometry

    @staticmethod
    def make(truth: HexapodGeometry, nominal: HexapodGeometry | None = None) -> CtcWorld:
        return CtcWorld(truth, front_camera(truth), truth if nominal is None else nominal)

    def observation(self, robot: DynamicRobots, t: float) -> Observation:
        """What the encoders and camera give of the true state."""
        R, p = robot.R[0], robot.t[0]
        legs = legs_in_frame(self.truth, R, p, self.camera.camera_from_base)
        normals, _ = leg_edges(legs.base_points, legs.directions, self.truth.leg_radius)
        rates, _ = robot.model.legs_batch(robot.R, robot.t, robot.twist)
        return Observation(t, legs.lengths, normals=normals, directions=legs.directions,
                           q_dot=rates[0].copy())

    def goal(self, R: np.ndarray, t: np.ndarray) -> Goal:
        """Taught as the study does: the features the camera sees of the TRUE robot at
        the goal; the lengths the NOMINAL inverse kinematics of the goal pose."""
        legs = legs_in_frame(self.truth, R, t, self.camera.camera_from_base)
        normals, _ = leg_edges(legs.base_points, legs.directions, self.truth.leg_radius)
        return Goal(normals=normals, directions=legs.directions,
                    lengths=inverse_kinematics(self.nominal, R, t), rotation=R,
                    translation=t)

    def context(self, goal: Goal, reference: object = None) -> ControllerContext:
        """The controller's context: nominal geometry, base points through the camera."""
        A = self.camera.camera_from_base.apply(self.nominal.base_points)
        return ControllerContext(A, self.nominal, self.camera, DT, goal, reference=reference)

    def run(self, controller: Controller, start: tuple[np.ndarray, np.ndarray], steps: int,
            edit: Callable[[Observation, int], Observation] | None = None
            ) -> tuple[np.ndarray, np.ndarray, list[Command]]:
        """Closed loop from rest at ``start``: true positions (steps + 1, 3), rotations
        (steps + 1, 3, 3) and the commands."""
        robot = DynamicRobots([self.truth], start[0][None].copy(), start[1][None].copy())
        robot.drives.mode = "force"
        rows = np.arange(1)
        ps, Rs, cmds = [robot.t[0].copy()], [robot.R[0].copy()], []
        for k in range(steps):
            obs = self.observation(robot, k * DT)
            if edit is not None:
                obs = edit(obs, k)
            cmd = controller.step(obs)
            assert cmd.reason is None, f"step {k}: {cmd.reason}"
            cmds.append(cmd)
            assert not robot.advance(rows, np.asarray(cmd.forces)[None], DT / PHYSICS_STEPS,
                                     PHYSICS_STEPS).any()
            ps.append(robot.t[0].copy())
            Rs.append(robot.R[0].copy())
        return np.array(ps), np.array(Rs), cmds


def line_reference(truth: HexapodGeometry, profile: str, angles_deg: tuple[float, float, float]
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, PoseTrajectory]:
    """A line from home, (8, -6, 6) mm and the rotation ``exp(angles_deg)`` away, at
    10 mm/s and 0.03 rad/s: ``(R0, t0, R1, t1, reference)``."""
    R0, t0 = home_pose(truth)
    R1 = R0 @ exp_so3(np.deg2rad(np.array(angles_deg)))
    t1 = t0 + np.array([0.008, -0.006, 0.006])
    ref = PoseTrajectory("line", profile, R0, t0, speed=0.01, acceleration=0.05,
                         goal_rotation=R1, goal_translation=t1, angular_speed=0.03,
                         angular_acceleration=0.1)
    return R0, t0, R1, t1, ref


def assert_tracks_the_rotated_line(world: CtcWorld, law: Controller) -> None:
    """``law`` through the study's tracking wrapper
    (:class:`controllers.tracking.TrackingController`) along the trapezoidal line with a
    (1.2, -1.0, 1.2) degree rotation of :func:`line_reference`: the true pose within
    30 um and 0.005 degree of the reference all along, and 2 um and 1e-4 degree of it at
    the end."""
    from controllers.tracking import TrackingController
    from hexapod.se3 import pose_error

    R0, t0, R1, t1, ref = line_reference(world.truth, "trapezoidal", (1.2, -1.0, 1.2))
    ctrl = TrackingController(law)
    ctrl.reset(world.context(world.goal(R1, t1), ref))
    steps = math.ceil(ref.duration / DT) + 25
    p, R, _ = world.run(ctrl, (R0, t0), steps)
    sample = ref.at(DT * np.arange(steps + 1))
    pos, ang = pose_error(R, p, sample.rotation, sample.translation)
    assert pos.max() < 30e-6, pos.max()
    assert ang.max() < np.deg2rad(0.005), np.rad2deg(ang.max())
    assert pos[-1] < 2e-6 and ang[-1] < np.deg2rad(1e-4)
