"""Model-based baseline (what the seeds argue against), ``MATH.md`` section 6.

Read the leg lengths, solve the forward kinematics with the NOMINAL geometry
(fast Newton, warm-started with the previous pose), servo that pose to the
goal pose of the nominal model, and map the twist through the nominal inverse
Jacobian. Its accuracy is bounded by the calibration error of the whole
geometry; the vision laws are not.

Pose servo (twist in the base frame, at its origin):
``w = lambda log(R* R^T)``, ``v = lambda (t* - t) - w x t``, so that the
orientation error and the platform origin both decay as ``exp(-lambda t)``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from controllers.base import (
    Command,
    Controller,
    ControllerContext,
    Observation,
    usable_observation_problem,
)
from controllers.exceptions import ContextError
from controllers.interaction import cross
from controllers.laws import Gain, check_number
from hexapod.exceptions import HexapodError
from hexapod.fk import forward_kinematics
from hexapod.kinematics import Transform, twist_to_frame
from hexapod.se3 import log_so3
from hexapod.workspace import home_pose


class ModelBasedController(Controller):
    """Forward kinematics of the measured lengths (nominal geometry) + pose servoing.

    Args:
        gain: Constant gain ``lambda`` [1/s].
        adaptive_gain: ``(lambda0, lambda_inf, lambda0')`` (overrides ``gain``), with
            ``x`` the largest entry of the pose error (metres and radians).
        fk_tolerance: Forward-kinematics residual tolerance [m].
        fk_max_iterations: Forward-kinematics iteration budget.
    """

    name = "model-based"
    features = frozenset({"lengths"})

    def __init__(self, gain: float = 1.0, adaptive_gain: Sequence[float] | None = None,
                 fk_tolerance: float = 1e-11, fk_max_iterations: int = 30) -> None:
        self.gain = Gain.from_options(self.name, gain, adaptive_gain)
        self.fk_tolerance = check_number(self.name, "fk_tolerance", fk_tolerance)
        self.fk_max_iterations = int(check_number(self.name, "fk_max_iterations",
                                                  fk_max_iterations, 1.0, strict=False))
        self.context: ControllerContext | None = None
        self._J = np.zeros((6, 6))

    def reset(self, context: ControllerContext) -> None:
        """Read the nominal geometry and the goal pose (or the goal lengths).

        Raises:
            ContextError: No goal pose and no goal lengths, or invalid values.
        """
        geo = context.geometry
        goal = context.goal
        if goal.rotation is not None and goal.translation is not None:
            R = np.asarray(goal.rotation, dtype=float)
            t = np.asarray(goal.translation, dtype=float)
            if R.shape != (3, 3) or t.shape != (3,) or not (np.all(np.isfinite(R))
                                                            and np.all(np.isfinite(t))):
                raise ContextError(self.name, "goal.rotation/translation",
                                   "expected a finite (3, 3) rotation and (3,) translation")
            if np.abs(R.T @ R - np.eye(3)).max() > 1e-6:
                raise ContextError(self.name, "goal.rotation", "not a rotation matrix")
        elif goal.lengths is not None:
            try:
                sol = forward_kinematics(geo, np.asarray(goal.lengths, dtype=float),
                                         check_stroke=False)
            except (HexapodError, ValueError) as exc:
                raise ContextError(self.name, "goal.lengths",
                                   f"no nominal pose for them: {exc}") from None
            R, t = sol.rotation, sol.translation
        else:
            raise ContextError(self.name, "goal", "needs rotation and translation (or lengths)")
        self.context = context
        self._R_star, self._t_star = R.copy(), t.copy()
        self._R, self._t = home_pose(geo)
        self._A = np.asarray(geo.base_points, dtype=float)
        self._E = np.asarray(geo.platform_points, dtype=float)
        cam: Any = context.camera
        pose = getattr(cam, "camera_from_base", None)
        self._camera_from_base: Transform | None = pose if isinstance(pose, Transform) else None

    def step(self, observation: Observation) -> Command:
        """Forward kinematics, pose error, twist, ``q_dot = J_inv(nominal) tau``."""
        if self.context is None:
            return Command.refuse(f"{self.name}: reset(context) was not called")
        problem = usable_observation_problem(observation, self.features)
        if problem is not None:
            return Command.refuse(problem)
        q = np.asarray(observation.lengths, dtype=float)
        try:
            sol = forward_kinematics(self.context.geometry, q, guess=(self._R, self._t),
                                     method="newton", tol=self.fk_tolerance,
                                     max_iterations=self.fk_max_iterations, check_stroke=False)
        except HexapodError as exc:
            # The next step starts again from the home pose.
            self._R, self._t = home_pose(self.context.geometry)
            return Command.refuse(f"forward kinematics failed: {exc}")
        R, t = sol.rotation, sol.translation
        self._R, self._t = R, t
        rot = log_so3(self._R_star @ R.T)
        dp = self._t_star - t
        e = np.concatenate([-dp, -rot])
        lam = self.gain(float(np.abs(e).max()))
        w = lam * rot
        v = lam * dp - cross(w, t)
        tau = np.concatenate([v, w])
        # Nominal inverse Jacobian at the estimated pose (base frame).
        legs = (self._E @ R.T) + t - self._A
        u = legs / np.linalg.norm(legs, axis=1, keepdims=True)
        J = self._J
        J[:, :3] = u
        J[:, 3:] = cross(self._A, u)
        qdot = J @ tau
        if not np.all(np.isfinite(qdot)):
            return Command.refuse("non-finite command (numerical failure)", e)
        twist = (twist_to_frame(tau, self._camera_from_base)
                 if self._camera_from_base is not None else None)
        return Command(qdot, twist=twist, error=e, error_norm=math.sqrt(float(e @ e)), rank=6,
                       condition=float(np.linalg.cond(J)), features_used=6,
                       notes=[f"forward kinematics: {sol.iterations} iterations"])
