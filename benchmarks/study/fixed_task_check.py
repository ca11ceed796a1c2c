"""A fixed task's checks before a study (``hexapod-bench check`` and ``run``): its start and
goal leg lengths have a platform pose, and the camera's edges there determine it for the
controllers that steer by the image."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from benchmarks.study.setup_check import (
    MIN_EDGES,
    SINGULAR_RATIO,
    Problem,
    edge_interaction_ratio,
)
from hexapod.exceptions import HexapodError
from hexapod.geometry import HexapodGeometry


def fixed_task_problems(geometry: HexapodGeometry, start_mm: Any, goal_mm: Any,
                        key_prefix: str = "task", camera: Any = None,
                        needs_camera: Sequence[str] = (), controllers: int = 0,
                        where_camera: str = "the camera's pose") -> list[Problem]:
    """A fixed task's start and goal leg lengths have a platform pose (forward kinematics
    from home converges), else an error naming the key; with ``camera``, the edges it
    sees there determine the platform's six degrees of freedom, else the controllers
    that steer by the image (``needs_camera``, of ``controllers`` in all) cannot move
    there: an error when every controller is one of them, else a warning naming them."""
    from hexapod.fk import forward_kinematics

    out: list[Problem] = []
    for key, value in (("start_mm", start_mm), ("goal_mm", goal_mm)):
        if value is None:
            continue
        try:
            pose = forward_kinematics(geometry, 1e-3 * np.asarray(value, float))
        except HexapodError:  # no convergence, a singular Jacobian: unreachable lengths
            out.append(Problem("error", f"{key_prefix}.{key}: no platform pose near the home "
                               "pose has these six leg lengths (the goal is unreachable); "
                               "choose lengths of a reachable pose"))
            continue
        if camera is None or not needs_camera:
            continue
        from vision.legs import observe_legs

        obs = observe_legs(camera, geometry, pose.rotation, pose.translation)
        seen = int(np.asarray(obs.edge_visible, bool).sum())
        ratio = edge_interaction_ratio(obs)[0] if seen else 0.0
        if seen >= MIN_EDGES and ratio >= SINGULAR_RATIO:
            continue
        every = len(needs_camera) >= controllers
        where = "start" if key == "start_mm" else "goal"
        out.append(Problem(
            "error" if every else "warning",
            f"{key_prefix}.{key}: the camera sees {seen} leg edge(s) at the task's {where}, "
            f"which do not determine the platform's six degrees of freedom (edge "
            f"interaction {'singular' if seen else 'empty'}: smallest/largest singular value "
            f"{ratio:.1e}): {', '.join(needs_camera)} cannot steer by the image there "
            f"(they refuse to move: rank < 6)"
            f"{'' if every else ' (the other controllers do not need the camera)'}; "
            f"change {where_camera}, or {key_prefix}.{key}", "camera"))
    return out


__all__ = ["fixed_task_problems"]
