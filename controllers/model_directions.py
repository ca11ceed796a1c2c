"""The nominal model's leg directions of legs an image law has never seen, for many rows
at once.

An image law that has never seen a leg takes its direction from the nominal model: the
forward kinematics of the measured lengths (Newton, warm-started at the trial's last
model pose) and the legs of that pose seen through the estimated camera
(:meth:`controllers.laws.VisionLaw.tasks`). A batch step leaves the rows with a hidden
feature to each trial's own step, one by one; :class:`ModelDirections` holds the rows of
one period and solves all of them together when the first row asks
(:func:`hexapod.fk.forward_kinematics_batch`: the same compiled Newton steps from the
same guesses, each row on its own, so a row's pose and directions are those of its trial
alone). A trial's own step outside a batch solves its one row the same way.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from controllers.control_grid import chunks, model_world
from controllers.estimators import PoseEstimate
from hexapod.fk import forward_kinematics_batch
from hexapod.kinematics import leg_directions
from hexapod.workspace import home_pose

#: The forward kinematics' tolerance on the length residual [m] and iteration budget.
FK_TOLERANCE, FK_ITERATIONS = 1e-12, 50


class ModelDirections:
    """The model poses and leg directions of rows of one period (see the module
    docstring), solved on first use.

    Args:
        laws: Each row's law (reset, with a camera pose); ``law.model_pose`` is its
            guess (None: the home pose).
        lengths: (m, 6) each row's measured lengths [m].
    """

    def __init__(self, laws: list[Any], lengths: np.ndarray) -> None:
        self.laws = laws
        self.lengths = np.array(lengths, dtype=float)
        self.guesses = [law.model_pose for law in laws]
        self._solved: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None

    def holds(self, k: int, law: Any, q: np.ndarray) -> bool:
        """Whether row ``k`` is ``law``'s with the lengths ``q`` and the guess it has now."""
        return (self.laws[k] is law and law.model_pose is self.guesses[k]
                and np.array_equal(q, self.lengths[k]))

    def take(self, k: int) -> np.ndarray | None:
        """Row ``k``'s leg directions (6, 3) (camera frame), its law's ``model_pose`` set
        to the pose found; None where the forward kinematics finds none (no convergence,
        a singular Jacobian, lengths not finite)."""
        if self._solved is None:
            self._solved = self._solve()
        R, t, ok, u = self._solved
        if not ok[k]:
            return None
        self.laws[k].model_pose = PoseEstimate(R[k].copy(), t[k].copy())
        return u[k].copy()

    def _solve(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Every row's pose, whether found, and directions: the rows of one nominal robot
        and camera in one call."""
        m = len(self.laws)
        R, t = np.empty((m, 3, 3)), np.empty((m, 3))
        ok, u = np.zeros(m, dtype=bool), np.full((m, 6, 3), np.nan)
        finite = np.isfinite(self.lengths).all(axis=1)
        contexts: list[Any] = [getattr(law, "context", None) for law in self.laws]
        usable = [c is not None and getattr(c.camera, "camera_from_base", None) is not None
                  for c in contexts]  # (a law without them has no model directions)
        keys = [model_world(c) if fit else None for c, fit in zip(contexts, usable, strict=True)]
        for members in chunks(keys, None):
            rows = np.array([k for k in members if finite[k] and usable[k]], dtype=np.int64)
            if not len(rows):
                continue
            geometry = contexts[rows[0]].geometry
            home = home_pose(geometry)
            guesses = [home if (g := self.guesses[k]) is None else g.pose for k in rows.tolist()]
            sol = forward_kinematics_batch(
                geometry, self.lengths[rows], np.array([g[0] for g in guesses], dtype=float),
                np.array([g[1] for g in guesses], dtype=float), FK_TOLERANCE, FK_ITERATIONS)
            R[rows], t[rows] = sol.rotations, sol.translations
            found = rows[sol.converged]
            ok[found] = True
            if len(found):
                u[found] = contexts[rows[0]].camera.camera_from_base.rotate(
                    leg_directions(geometry, R[found], t[found]))
        return R, t, ok, u


__all__ = ["FK_ITERATIONS", "FK_TOLERANCE", "ModelDirections"]
