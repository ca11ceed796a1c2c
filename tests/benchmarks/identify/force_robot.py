"""A robot backend that reports its drive forces, as ``docs/identification.md`` asks of a
lab robot (``--backend my_package:MyRobot``): the dynamic world's true robot (the
closed-chain mechanism with velocity-mode drives, integrated at 20 us) behind the
:class:`~hexapod.backends.base.Backend` interface, ``measured_forces()`` the drives'
forces read in the middle of the last step (``force_timing = "middle"``; ``:end`` reads
them at its end and says so, ``:unsaid`` too without saying it). Named
``tests.benchmarks.identify.force_robot:ForceRobot``; ``:nan-at=K`` makes its reading of
leg 3 NaN from step ``K`` on (a sensor or link fault), ``:mm`` reports millimetres."""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from hexapod.backends.base import Backend, BackendStep
from hexapod.dynamics.identification.excitation import legs
from hexapod.dynamics.robots import DynamicRobots
from hexapod.fk import forward_kinematics
from hexapod.geometry import HexapodGeometry
from hexapod.workspace import home_pose

#: The physics step [s].
PHYSICS_DT = 2e-5


class ForceRobot(Backend):
    """The dynamic world's robot with force readings (module docstring).

    Args:
        geometry: The robot (its true one: the same file).
        args: ``""``, ``"nan-at=K"``, ``"force-nan-at=K"`` (leg 2's force NaN from step
            ``K`` on), ``"mm"``, ``"kN"`` (the forces in kilonewtons), ``"end"`` or
            ``"unsaid"`` (the forces at the step's end).
    """

    simulated = True
    #: Every instance's halts (the tests read them: the robot was stopped).
    halts: ClassVar[list[str]] = []

    def __init__(self, geometry: HexapodGeometry, args: str = "") -> None:
        self.geometry = geometry
        self.stroke = geometry.stroke
        self.max_speed = geometry.max_speed
        self.nan_at = int(args.split("=")[1]) if args.startswith("nan-at=") else None
        self.mm = args == "mm"
        self.force_nan_at = (int(args.split("=")[1]) if args.startswith("force-nan-at=")
                             else None)
        self.force_unit = 1e3 if args == "kN" else 1.0
        self.at_end = args in ("end", "unsaid")
        if args != "unsaid":  # (an instance attribute: the backend's declaration)
            self.force_timing = "end" if self.at_end else "middle"
        self._force = np.zeros(6)
        self.steps = 0
        R, t = home_pose(geometry)
        self._robots = DynamicRobots([geometry], R[None].copy(), t[None].copy())

    def reset(self, lengths: np.ndarray | None = None) -> np.ndarray:
        """Start at rest at the pose of ``lengths`` (the forward kinematics)."""
        if lengths is not None:
            fk = forward_kinematics(self.geometry, np.asarray(lengths, float),
                                    home_pose(self.geometry))
            self._robots = DynamicRobots([self.geometry], fk.rotation[None].copy(),
                                         fk.translation[None].copy())
        return self.measured_lengths()

    def step(self, velocities: np.ndarray, dt: float) -> BackendStep:
        """The drives' velocity setpoints for ``dt`` [s]."""
        v = np.asarray(velocities, float)
        sub = max(1, round(dt / PHYSICS_DT))
        first = sub if self.at_end else sub // 2  # the force is read after these steps
        self._advance(v, dt / sub, first)
        self._force = np.asarray(self._robots.forces[0], float).copy()
        self._advance(v, dt / sub, sub - first)
        self.steps += 1
        return BackendStep(self.measured_lengths(), v.copy(), np.zeros(6, bool))

    def _advance(self, v: np.ndarray, h: float, steps: int) -> None:
        if steps and self._robots.advance(np.array([0]), v[None], h, steps).any():
            raise RuntimeError("the robot diverged")

    def measured_lengths(self) -> np.ndarray:
        """The legs' lengths [m] (NaN on leg 3 from step ``nan_at``; mm with ``mm``)."""
        g = self.geometry
        q = legs(self._robots.R, self._robots.t, g.base_points[None],
                 g.platform_points[None])[0][0].copy()
        if self.nan_at is not None and self.steps >= self.nan_at:
            q[3] = np.nan
        return q * 1e3 if self.mm else q

    def measured_forces(self) -> np.ndarray:
        """The drives' forces in the middle (or at the end) of the last step [N] (leg 2's
        NaN from step ``force_nan_at``)."""
        f = self._force / self.force_unit
        if self.force_nan_at is not None and self.steps >= self.force_nan_at:
            f[2] = np.nan
        return f

    def halt(self) -> None:
        ForceRobot.halts.append(f"halted after {self.steps} steps")
