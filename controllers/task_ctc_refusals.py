"""Why a row of the task computed-torque step (:class:`controllers.task_ctc_rows.TaskRows`)
is no command: its readings, a law without a compiled step, the compiled step's status,
or a parallel singularity at the row's nominal pose (forces over a limit)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from controllers.control_grid import chunks, model_world
from controllers.ctc_rows import refusal
from controllers.data import ObservationBatch
from controllers.plausible import stroke_of
from controllers.task_ctc_c import NOT_FINITE, UNUSABLE
from controllers.task_ctc_inputs import encoder_readings
from hexapod.c_step import RowArrays
from hexapod.kinematics import inverse_jacobian, leg_directions

if TYPE_CHECKING:
    from controllers.task_ctc_compiled import CompiledTaskStep


def parallel_singular(laws: list[Any], b: RowArrays, rows: np.ndarray, pose: slice,
                      threshold: float) -> dict[int, str]:
    """Why some of ``rows``, whose forces are over a limit, are no command: the legs'
    Jacobian at the row's nominal pose is singular (a parallel singularity: the task's own
    Jacobian stays regular there, and the forces that hold the task were clipped to the
    drives' limits where computed torque refuses). One batched test of the rows of one
    robot model (the trials' nominal robots).

    Args:
        laws: The batch's instances, in trial order.
        b: The step's arrays (the trials and the compiled step's outputs ``Y``).
        rows: The rows to test.
        pose: The pose block of an output row (``R`` column-major, then ``t`` [m]).
        threshold: The relative singular-value threshold of the rank test.

    Returns:
        Row -> reason, for the singular rows.
    """
    out: dict[int, str] = {}
    of_rows = [laws[int(b.trials[j])] for j in rows.tolist()]
    for members in chunks([None if law.context is None else model_world(law.context)
                           for law in of_rows]):
        law = of_rows[members[0]]
        if law.context is None:
            continue
        at = rows[members]
        p = b.Y[at][:, pose]
        R = np.swapaxes(p[:, :9].reshape(-1, 3, 3), 1, 2)  # (column-major)
        g = law.context.geometry
        K = inverse_jacobian(g.base_points, leg_directions(g, R, p[:, 9:12]))
        w = np.linalg.eigvalsh(np.swapaxes(K, 1, 2) @ K)  # (ascending)
        with np.errstate(divide="ignore", invalid="ignore"):
            singular = ~(w[:, 0] > threshold**2 * w[:, -1])
            cond = np.sqrt(w[:, -1] / w[:, 0])
        for k in np.flatnonzero(singular).tolist():
            c = float(cond[k]) if w[k, 0] > 0 else math.inf
            out[int(at[k])] = (f"the legs' Jacobian at the nominal pose has rank < 6 "
                               f"(condition {c:.3g}): a parallel singularity, where no "
                               "leg forces hold the platform")
    return out


def unusable(observations: ObservationBatch, j: int) -> str:
    """Why row ``j`` has no step at all (no leg velocities read, or no compiled step)."""
    if observations.q_dot is None:
        reason = encoder_readings(observations.item(j))
        assert isinstance(reason, str)
        return reason
    return "no compiled step (compiled_kind is None and the law made none at reset)"


def step_refusal(step: CompiledTaskStep, y: np.ndarray, views: dict[str, np.ndarray],
                 threshold: float) -> str:
    """The reason of a compiled step's output row ``y`` that is not a command (its inputs'
    ``views``, the rank test's ``threshold``)."""
    outs = step.outputs
    reason = refusal(y, outs.index("status"), outs.index("fk_residual"), outs["factor"],
                     threshold, step.pose_name, views)
    assert reason is not None
    return reason


def row_reason(laws: list[Any], observations: ObservationBatch, b: RowArrays, j: int,
               threshold: float) -> str:
    """Why row ``j`` is refused, from its code: its readings, no step, or its status."""
    code = int(b.code[j])
    law = laws[int(b.trials[j])]
    if code == NOT_FINITE:
        readings = encoder_readings(observations.item(j), stroke_of(law.context))
        return readings if isinstance(readings, str) else "readings not finite"
    if code == UNUSABLE:
        return unusable(observations, j)
    step = law.compiled
    assert step is not None
    return step_refusal(step, b.Y[j], step.inputs.views(b.X[j]), threshold)


__all__ = ["parallel_singular", "row_reason", "step_refusal", "unusable"]
