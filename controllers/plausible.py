"""Leg lengths no leg of the robot can have: the per-trial adapter's refusal
(:meth:`controllers.base.Controller.step`).

A measured length further from the nominal stroke than the stroke's own span is not a
leg at an end stop nor a calibration offset but a reading in other units (millimetres
for metres), a sign slip or a failed encoder; a controller stepped on it commands
nonsense (``leg-edge`` 34 m/s, ``joint-space`` 419 m/s on lengths in millimetres). The
real-robot backends check their readings against the stroke before a controller sees
them (:func:`hexapod.backends.base.check_reading`); this check protects the controllers'
own per-trial step, the one a user stepping a robot by hand calls.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np


def implausible_lengths(lengths: Any, stroke: tuple[float, float]) -> str | None:
    """Why ``lengths`` (6,) [m] cannot be the legs of a robot of ``stroke``
    ``(q_min, q_max)`` [m] (a value outside ``(q_min - span, q_max + span)``, ``span =
    q_max - q_min``, or not positive), or None. Values that are not six numbers, or not
    finite, are left to the controller's own checks (which name them)."""
    try:
        values = lengths.tolist() if type(lengths) is np.ndarray else list(lengths)
        if len(values) != 6:
            return None
        q_min, q_max = stroke
        span = q_max - q_min
        low, high = max(0.0, q_min - span), q_max + span
        if low < min(values) and max(values) < high:  # the common case
            return None
        for i, v in enumerate(values):
            v = float(v)
            if math.isfinite(v) and not low < v < high:
                hint = " (millimetres? SI units: metres)" if low < v / 1e3 < high else ""
                return (f"lengths: leg {i} reads {v:.6g} m, where no leg of the nominal robot "
                        f"can be (its stroke {q_min * 1e3:g} to {q_max * 1e3:g} mm){hint}")
    except (TypeError, ValueError):
        return None
    return None


__all__ = ["implausible_lengths"]
