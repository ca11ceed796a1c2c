"""What a trial that did not converge ended outside of, in the user's units."""

from __future__ import annotations

import math
from typing import Any


def _pair(value: float, tolerance: float) -> tuple[str, str]:
    """``value`` and ``tolerance`` printed with enough digits to tell them apart."""
    for digits in range(3, 10):
        a, b = f"{value:.{digits}g}", f"{tolerance:.{digits}g}"
        if a != b or value == tolerance:
            return a, b
    return f"{value!r}", f"{tolerance!r}"


def _outside(name: str, value: float, tolerance: float, unit: str) -> str | None:
    if value < tolerance:
        return None
    if not math.isfinite(value):
        return f"{name} {value} {unit}"
    a, b = _pair(value, tolerance)
    relation = ">" if value > tolerance else "not below"
    return f"{name} {a} {unit} {relation} {b} {unit}"


def unconverged_reason(task: Any, position_mm: float, orientation_deg: float) -> str:
    """Why a trial that ran out of steps did not converge.

    Args:
        task: The scenario's :class:`~benchmarks.scenario_sections.TaskConfig`.
        position_mm: Final position error [mm].
        orientation_deg: Final orientation error [deg].

    Returns:
        ``"not converged: rotation 0.0565 deg > 0.05 deg after 800 steps"`` (what ended
        outside the tolerances), or, when the end was within them, that it did not stay
        within them for ``settle_steps`` periods.
    """
    outside = [text for text in (
        _outside("position", position_mm, task.position_tolerance_mm, "mm"),
        _outside("rotation", orientation_deg, task.orientation_tolerance_deg, "deg"))
        if text]
    if outside:
        return f"not converged: {' and '.join(outside)} after {task.max_steps} steps"
    return (f"not converged within {task.max_steps} steps: within the tolerances at the end "
            f"but not for {task.settle_steps} consecutive periods")


def outside_counts(rows: list[dict[str, Any]]) -> dict[str, dict[str, int]]:
    """Per controller label, how many unconverged trials ended outside the position
    tolerance only, the rotation tolerance only, both, or within them but unsettled
    (read from the ``failure`` texts of :func:`unconverged_reason`)."""
    out: dict[str, dict[str, int]] = {}
    for r in rows:
        text = r.get("failure") or ""
        if not text.startswith("not converged"):
            continue
        pos, rot = "position " in text, "rotation " in text
        kind = ("position and rotation" if pos and rot else "position" if pos
                else "rotation" if rot else "within, not settled")
        counts = out.setdefault(str(r["controller"]), {})
        counts[kind] = counts.get(kind, 0) + 1
    return out
