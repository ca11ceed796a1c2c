"""Leg lengths no leg of the robot can have, in what a controller is told to reach: a
goal's lengths, or the legs of a goal pose (:func:`controllers.law_tools.goal_lengths`,
:func:`controllers.task_ctc_inputs.goal_pose_of`, ``model-based``'s goal), refused at
reset and at a new goal.

A length further from the nominal stroke than the stroke's own span is not a leg at an
end stop nor a calibration offset but a value in other units (millimetres for metres):
taught so, `joint-space` commanded 415 m/s and `model-based` 314 m/s at their first
step. The check costs nothing per period: it is made once per goal. The lengths' own
check (:func:`hexapod.plausible.implausible_lengths`, also a backend's reading's) lives
in the robot's layer; this module adds what depends on a controller's context.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

import numpy as np

from hexapod.geometry import HexapodGeometry
from hexapod.kinematics import inverse_kinematics
from hexapod.plausible import MILLIMETRES, implausible_lengths, plausible_range

__all__ = ["MILLIMETRES", "implausible_lengths", "implausible_pose", "plausible_range",
           "reading_bounds", "stroke_of"]


def reading_bounds(strokes: Iterable[tuple[float, float] | None]) -> tuple[float, float]:
    """The open interval [m] of the leg lengths a batch's readings may hold: the union
    of the :func:`plausible_range` of its rows' nominal strokes, or every finite number
    where a row's stroke is not known (None). The compiled steps refuse a reading outside
    it; the row's reason then names the leg from its own stroke."""
    ranges = [None if s is None else plausible_range(s) for s in strokes]
    if not ranges or any(r is None for r in ranges):
        return -math.inf, math.inf
    return min(r[0] for r in ranges if r), max(r[1] for r in ranges if r)


def stroke_of(context: Any) -> tuple[float, float] | None:
    """The nominal stroke (q_min, q_max) [m] of a controller's context (None: none)."""
    geometry = getattr(context, "geometry", None)
    return None if geometry is None else geometry.stroke


def implausible_pose(geometry: HexapodGeometry, rotation: Any, translation: Any
                     ) -> str | None:
    """Why the pose ``(rotation, translation [m])`` (base frame) cannot be reached by any
    robot near ``geometry`` (its legs, inverse kinematics, outside
    :func:`plausible_range`), or None; a pose the kinematics refuses is left to the
    caller's own checks."""
    try:
        R = np.asarray(rotation, dtype=float)
        t = np.asarray(translation, dtype=float)
        problem = implausible_lengths(inverse_kinematics(geometry, R, t), geometry.stroke)
        if problem is None:
            return None
        scaled = implausible_lengths(inverse_kinematics(geometry, R, t / 1e3),
                                     geometry.stroke)
    except (ArithmeticError, TypeError, ValueError, RuntimeError):
        return None
    problem = problem.removesuffix(MILLIMETRES)
    # millimetres: a translation ten times the longest leg, plausible once divided by 1000
    mm = scaled is None and float(np.linalg.norm(t)) > 10.0 * geometry.stroke[1]
    return f"the pose puts {problem}" + ("; the translation in millimetres? SI units: "
                                         "metres" if mm else "")


__all__ = ["MILLIMETRES", "implausible_lengths", "implausible_pose", "plausible_range",
           "reading_bounds", "stroke_of"]
