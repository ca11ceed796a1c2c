"""The status of a computed-torque step's row: its codes and the one wording of each.

Every compiled computed-torque step returns a ``status`` per row
(:func:`controllers.solvers.compiled_ctc.sx_status`): 0 for a command, else why not; the
laws refuse such a row with :func:`status_reason`'s wording
(:func:`controllers.ctc_rows.refusal`). The kernel decides ``TOO_FEW_ROWS``,
``TOO_FEW_LEGS``, ``NOT_CONVERGED``, ``NON_FINITE`` and ``SINGULAR_INVERSE``; the caller
``RANK_DEFICIENT`` (LAPACK on the output ``factor``) and ``COLLINEAR_LEGS``.
"""

from __future__ import annotations

from enum import IntEnum


class Status(IntEnum):
    """A step's status code (0: a command)."""

    OK = 0
    NOT_CONVERGED = 1
    NON_FINITE = 2
    SINGULAR_INVERSE = 3
    RANK_DEFICIENT = 4
    TOO_FEW_ROWS = 5
    TOO_FEW_LEGS = 6
    COLLINEAR_LEGS = 7


def status_reason(status: int, *, residual: float = float("nan"),
                  pose_name: str = "forward kinematics of the lengths",
                  non_finite: str = "leg forces", condition: float = float("inf"),
                  rows: int = 0, legs: list[int] | None = None) -> str:
    """Why a row of status ``status`` is not a command (the refusal's text).

    Args:
        status: The row's code (not 0).
        residual: The pose's residual (``NOT_CONVERGED``).
        pose_name: What found the pose (``NOT_CONVERGED``).
        non_finite: What is not finite (``NON_FINITE``: "leg forces" or "Jacobian").
        condition: The Jacobian's condition number (``RANK_DEFICIENT``).
        rows: The task rows in use (``TOO_FEW_ROWS``).
        legs: The legs seen (``TOO_FEW_LEGS``, ``COLLINEAR_LEGS``).

    Raises:
        ValueError: ``status`` is 0 or not a code.
    """
    code = Status(int(status))
    seen = [] if legs is None else legs
    if code is Status.NOT_CONVERGED:
        return f"nominal model failed: {pose_name} did not converge (residual {residual:.3g})"
    if code is Status.NON_FINITE:
        return f"non-finite {non_finite} (numerical failure)"
    if code is Status.SINGULAR_INVERSE:
        return "nominal model failed: singular inverse Jacobian (the inverse dynamics' solve)"
    if code is Status.RANK_DEFICIENT:
        return f"Jacobian of rank < 6 (condition {condition:.3g})"
    if code is Status.TOO_FEW_ROWS:
        return f"task Jacobian of rank < 6: {rows} task rows in use (the features seen)"
    if code is Status.TOO_FEW_LEGS:
        return f"only {len(seen)} legs seen (legs {seen}): the pose needs at least 3"
    if code is Status.COLLINEAR_LEGS:
        return f"the {len(seen)} legs seen are collinear on the platform: no pose"
    raise ValueError(f"status {int(status)}: a command has no refusal")


__all__ = ["Status", "status_reason"]
