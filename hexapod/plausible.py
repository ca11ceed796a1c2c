"""Leg lengths no leg of a robot can have: a value further from the nominal stroke than
the stroke's own span is not a leg at an end stop nor a calibration offset but a value in
other units (millimetres for metres) or a fault. Checked where lengths enter: a backend's
reading (:func:`reading_problem`), and what a controller is told or measures
(:mod:`controllers.plausible`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

#: The hint of a value that is plausible once divided by 1000.
MILLIMETRES = " (millimetres? SI units: metres)"


def plausible_range(stroke: tuple[float, float]) -> tuple[float, float]:
    """The open interval [m] of the lengths a leg of ``stroke`` ``(q_min, q_max)`` [m]
    may have: ``(max(0, q_min - span), q_max + span)``, ``span = q_max - q_min``."""
    q_min, q_max = stroke
    span = q_max - q_min
    return max(0.0, q_min - span), q_max + span


def implausible_lengths(lengths: Any, stroke: tuple[float, float]) -> str | None:
    """Why ``lengths`` (6,) [m] cannot be legs of a robot of ``stroke`` [m] (a value
    outside :func:`plausible_range`), or None; values that are not six finite numbers
    are left to the caller's own checks (which name them)."""
    try:
        values = np.asarray(lengths, dtype=float).ravel().tolist()
    except (TypeError, ValueError):
        return None
    low, high = plausible_range(stroke)
    if values and low < min(values) and max(values) < high:  # the common case
        return None
    for i, v in enumerate(values):
        if math.isfinite(v) and not low < v < high:
            hint = MILLIMETRES if low < v / 1e3 < high else ""
            return (f"leg {i} at {v:.6g} m, where no leg of the nominal robot can be (its "
                    f"stroke {stroke[0] * 1e3:g} to {stroke[1] * 1e3:g} mm){hint}")
    return None


def reading_problem(lengths: Any, stroke: tuple[float, float]) -> str | None:
    """Why a backend's reading ``lengths`` cannot be the legs of a robot of ``stroke``
    (q_min, q_max) [m], or None: not six values, a value that is not a number, or a leg
    where no leg of the robot can be (:func:`implausible_lengths`: millimetres for metres
    are named). The one check of what a robot reports: the study's and the servo
    session's loop, the identification's excitation, the backends' conformance."""
    q = np.asarray(lengths, dtype=float)
    if q.shape != (6,):
        return f"the backend measured {q.size} values of shape {q.shape}, not 6 leg lengths"
    if not np.isfinite(q).all():
        i = int(np.flatnonzero(~np.isfinite(q))[0])
        return (f"the backend measured leg {i} as {q[i]} (not a number: a fault of the "
                "robot's sensors or of its link)")
    problem = implausible_lengths(q, stroke)
    return None if problem is None else f"the backend measured {problem}"
