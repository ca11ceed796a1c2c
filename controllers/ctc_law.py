"""What the computed-torque laws share (``computed-torque`` and the task laws of
:mod:`controllers.task_ctc`): force controllers that sample their reference themselves,
built from the same options (the error dynamics, the smooth goal, the integral action
and the saturation strategy, :class:`~controllers.solvers.computed_torque.CTCOptions`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol

from controllers.base import Controller
from controllers.data import CommandBatch, ObservationBatch
from controllers.law_tools import check_flag
from controllers.solvers.computed_torque import CTCOptions
from hexapod.actuation import Actuation

#: Default natural frequency of the error [Hz] (``omega_n dt = 0.25`` at 20 ms).
NATURAL_FREQUENCY_HZ = 2.0
#: Default damping ratio of the error.
DAMPING = 1.0


class BatchRows(Protocol):
    """The arrays of a batch's trials and the one step over them
    (:class:`~controllers.joint_ctc_rows.JointRows`,
    :class:`~controllers.task_ctc_rows.TaskRows`)."""

    @property
    def laws(self) -> Sequence[Any]:
        """The trials' instances, in trial order."""

    def step(self, observations: ObservationBatch, out: CommandBatch) -> None:
        """Every row's command into ``out``."""


class ComputedTorqueLaw(Controller):
    """A computed-torque law's options (see the module docstring) and its one step over
    a batch (:meth:`step_batch`); a subclass sets up its own state in :meth:`init_state`
    and gives its batch's arrays and step in :meth:`batch_rows`.

    Args:
        natural_frequency: ``f_n`` [Hz] of the task error's second-order response.
        damping: Its damping ratio ``zeta``.
        smooth_goal: Reach a fixed goal along the quintic line (False: a step).
        integral_gain: Integral action Ki [1/s] on the task error (default 0: none).
            Stable below ``2 zeta omega_n``; the integral is held while a leg's force is
            over its limit (anti-windup).
        saturation: Forces over the drives' limit: "clip", "scale" or "qp" (default
            "clip"). Each leg clipped (as the drives do), the force vector scaled, or the
            acceleration scaled (:mod:`controllers.solvers.saturation`).

    Raises:
        ContextError: Naming the option that is not valid.
    """

    actuation = Actuation.FORCE
    #: The batch's arrays (:meth:`batch_rows`; built again for a copy).
    _rows: BatchRows | None = None
    #: Samples ``context.reference`` itself (:mod:`controllers.tracking` passes it through).
    tracks_reference = True

    def __init__(self, natural_frequency: float = NATURAL_FREQUENCY_HZ,
                 damping: float = DAMPING, smooth_goal: bool = True,
                 integral_gain: float = 0.0, saturation: str = "clip") -> None:
        self.ctc_options = CTCOptions(self.name, natural_frequency, damping, integral_gain,
                                      saturation)
        self.gains = self.ctc_options.gains
        self.integral_gain = self.ctc_options.integral_gain
        self.saturation = self.ctc_options.saturation
        self.solver = self.ctc_options.solver
        self.smooth_goal = check_flag(self.name, "smooth_goal", smooth_goal)
        self.init_state()

    def init_state(self) -> None:
        """Set up the law's state before its first reset (nothing by default)."""

    def batch_rows(self) -> BatchRows:
        """The arrays of this batch's trials (:attr:`trial_instances`, reset) and their
        one step."""
        raise NotImplementedError

    def step_batch(self, observations: ObservationBatch) -> CommandBatch:
        """The leg forces of every row [N] (the one step of :meth:`batch_rows`), or a
        refusal (zeros) with its reason."""
        self.crashes = {}
        if (unreset := self.checked_batch(observations)) is not None:
            return unreset
        out = CommandBatch.zeros(len(observations), Actuation.FORCE)
        rows = self._rows
        if rows is None or rows.laws is not self.trial_instances:  # (a copy: built again)
            rows = self._rows = self.batch_rows()
        if len(observations):
            rows.step(observations, out)
        return out


__all__ = ["DAMPING", "NATURAL_FREQUENCY_HZ", "BatchRows", "ComputedTorqueLaw"]
