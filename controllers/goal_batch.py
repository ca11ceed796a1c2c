"""Goals of several trials at once (the batch form of :class:`controllers.base.Goal`),
for ``retarget_batch(trials, goals)``: the goal of each period of a trajectory task
stepped in a batch (:mod:`controllers.tracking_batch`)."""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from controllers.base import Goal


@dataclass
class GoalBatch:
    """Goals of several trials: :class:`Goal` fields with a leading row axis (m, ...),
    for ``retarget_batch(trials, goals)`` (the goal of each period of a trajectory task
    stepped in a batch, :mod:`controllers.tracking_batch`). A field is None when no row
    has it.

    Attributes:
        normals: (m, 6, 2, 3) or None.
        lines: (m, 6, 2, 3) or None.
        directions: (m, 6, 3) or None.
        lengths: (m, 6) [m] or None.
        rotation: (m, 3, 3) or None.
        translation: (m, 3) [m] or None.
        edge_visible: (m, 6, 2) bool or None.
    """

    normals: np.ndarray | None = None
    lines: np.ndarray | None = None
    directions: np.ndarray | None = None
    lengths: np.ndarray | None = None
    rotation: np.ndarray | None = None
    translation: np.ndarray | None = None
    edge_visible: np.ndarray | None = None

    def __len__(self) -> int:
        for name in GOAL_FIELDS:
            value = getattr(self, name)
            if value is not None:
                return len(value)
        return 0

    def item(self, k: int) -> Goal:
        """The goal of row ``k`` (views of the batch arrays)."""
        return Goal(**{name: None if getattr(self, name) is None else getattr(self, name)[k]
                       for name in GOAL_FIELDS})

    @staticmethod
    def of(goal: Goal) -> GoalBatch:
        """A batch of one goal (its arrays with a leading axis of one)."""
        return GoalBatch(**{name: None if getattr(goal, name) is None
                            else np.asarray(getattr(goal, name))[None]
                            for name in GOAL_FIELDS})


#: The fields of :class:`Goal` (and of :class:`GoalBatch`, which mirrors them typed).
GOAL_FIELDS = tuple(f.name for f in fields(Goal))
