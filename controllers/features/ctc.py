"""Computed torque on a :class:`~controllers.tasks.leg_feature.LegFeature` (``<name>-ctc``).

The law of ``leg-direction-ctc`` (:class:`~controllers.feature_ctc.LegDirectionCTC`: the
encoders' pose and twist for the NOMINAL dynamic model, the legs seen by the camera,
the error given the dynamics ``e_ddot + 2 zeta omega_n e_dot + omega_n^2 e = 0``) on the
feature's task: the taught value is the feature of the goal's legs (``goal.directions``,
``goal.lengths``), the reference ``s*(t)`` the feature of the NOMINAL robot along the
reference pose trajectory seen by the estimated camera, with its rate and acceleration
by automatic differentiation (:attr:`LegFeature.motion_function`), anchored at the taught
value (``s* = s_taught + s_model(t) - s_model(end)``). Each period is one call of the
feature's compiled step (:mod:`controllers.features.ctc_step`); off its happy path the
law refuses with the reason of the row's status (:mod:`controllers.ctc_status`), as the
built-ins do.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from controllers.base import ControllerContext, Goal
from controllers.exceptions import ContextError
from controllers.feature_ctc import LegDirectionCTC
from controllers.features.ctc_step import FeatureTaskStep
from controllers.tasks.leg_feature import LegFeature


class FeatureComputedTorque(LegDirectionCTC):
    """Computed torque on a leg feature (see the module docstring); the class's
    ``feature`` is set by :func:`~controllers.features.controllers_for`.

    Args:
        natural_frequency: Natural frequency ``f_n`` [Hz] of the error's second-order
            response (default 2 Hz).
        damping: Damping ratio ``zeta`` of that response (default 1).
        smooth_goal: Reach a fixed goal along the feature of a quintic line (False: the
            taught feature as a step).
    """

    #: The feature (set on the generated class).
    feature: ClassVar[LegFeature]
    #: The built-in compiled steps are per kind; this law's is the feature's own.
    compiled_kind = None

    def reset_trial(self, context: ControllerContext) -> None:
        """As the built-in law, with the feature's compiled step.

        Raises:
            ContextError: What the law needs is missing from the context.
        """
        super().reset_trial(context)
        self.compiled = FeatureTaskStep(self)

    def take_goal(self, goal: Goal) -> None:
        """The taught feature: that of the goal's leg directions and lengths.

        Raises:
            ContextError: Either is missing or not finite.
        """
        for key in ("directions", "lengths"):
            if getattr(goal, key) is None:
                raise ContextError(self.name, f"goal.{key}",
                                   f"missing (the taught {self.feature.name})")
        u = np.asarray(goal.directions, dtype=float)
        q = np.asarray(goal.lengths, dtype=float)
        if u.shape != (6, 3) or q.shape != (6,):
            raise ContextError(self.name, "goal.directions/lengths",
                               f"expected (6, 3) and (6,), got {u.shape} and {q.shape}")
        taught = self.feature.desired(u, q, self._A)
        if not np.all(np.isfinite(taught)):
            bad = np.flatnonzero(~np.all(np.isfinite(taught), axis=1)).tolist()
            raise ContextError(self.name, "goal.directions/lengths",
                               f"the taught {self.feature.name} of legs {bad} is not finite")
        self._taught = taught
        self._grid = None
        self.reference_changed()

    def prepare(self, context: ControllerContext) -> None:
        """The built-in checks, and the mask of every row."""
        super().prepare(context)
        self.every_rows = np.ones(6 * self.feature.rows, dtype=bool)
        self.every_rows.flags.writeable = False

    def motion_and_seen(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(m, 3, 6 rows) the model's feature along the reference at ``times`` (m,) [s],
        its rate and acceleration, anchored at the taught value; every row seen."""
        ctx = self.context
        assert ctx is not None and self.reference is not None
        end = float(self.reference.duration) + 1.0
        poses = self.pose_rows(np.append(np.asarray(times, dtype=float), end))
        g, cam = ctx.geometry, self._frame
        k = len(poses)
        frame = np.concatenate([cam.rotation.ravel(), cam.translation])
        f, fd, fdd = self.feature.motion_function.map(k)(
            poses[:, 0:9].T, poses[:, 9:12].T, poses[:, 12:18].T, poses[:, 18:24].T,
            np.tile(self._A.reshape(18, 1), (1, k)),
            np.tile(np.asarray(g.platform_points, float).reshape(18, 1), (1, k)),
            np.tile(frame.reshape(12, 1), (1, k)))
        f, fd, fdd = (np.asarray(x, dtype=float).T for x in (f, fd, fdd))
        f = f[:-1] + (self._taught.reshape(-1) - f[-1])
        out = np.stack([f, fd[:-1], fdd[:-1]], axis=1)
        return out, np.ones((len(out), out.shape[2]), dtype=bool)
