"""Stepping many trials at once (``docs/plugins.md``, "Batched controllers").

A controller that implements ``reset_batch(contexts)`` and
``step_batch(observations)`` steps every trial of a study in one call (the built-in
controllers do: their compiled cores are looped over the trials in C). Any other
controller is wrapped by :class:`PerTrialLoop`: one instance per trial, ``step`` in a
loop. :func:`batch_controller` chooses.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from controllers.base import (
    Actuation,
    Command,
    CommandBatch,
    Controller,
    ControllerContext,
    ObservationBatch,
    registry,
)

log = logging.getLogger(__name__)


def actuation_of(controller: Any) -> Actuation:
    """What a controller object (or a batch wrapper of one) declares it commands: its
    ``actuation`` attribute, leg velocities when it has none (plugins written before
    typed actuation)."""
    return Actuation(getattr(controller, "actuation", Actuation.VELOCITY))


def supports_batch(controller: Any) -> bool:
    """Whether a controller object steps many trials itself."""
    return callable(getattr(controller, "reset_batch", None)) and callable(
        getattr(controller, "step_batch", None))


def step_rows_per_trial(instances: Sequence[Any], observations: ObservationBatch,
                        trials: np.ndarray, rows: np.ndarray, out: CommandBatch) -> None:
    """Step ``rows`` of a batch with their trials' own instances (the rows a batched core
    cannot finish), writing each command into ``out``.

    Args:
        instances: The per-trial controllers, by trial.
        observations: The batch.
        trials: (n,) the trial of each row.
        rows: The rows to step.
        out: The batch's commands.
    """
    for k in rows:
        out.put(int(k), instances[int(trials[k])].step(observations.item(int(k))))


class _FailedReset:
    """The place of a trial whose controller's ``reset`` raised: its first ``step``
    raises that exception again (the trial fails at step 0 with it; nothing is rerun)."""

    def __init__(self, exc: BaseException) -> None:
        self.exc = exc

    def step(self, observation: Any) -> Command:
        raise self.exc


def checked_command(cmd: Any, name: str, actuation: Actuation) -> Command:
    """A per-trial command of the right type, shape and kind.

    Raises:
        CommandError: Not a :class:`Command`, not 6 leg values, or another kind than the
            controller declared (named, with the shapes or kinds).
    """
    from controllers.exceptions import CommandError

    if not all(hasattr(cmd, a) for a in ("values", "reason", "actuation", "error_norm")):
        raise CommandError(name, f"returned {type(cmd).__name__}, not a Command")
    shape = np.shape(cmd.values)
    if shape != (6,):
        raise CommandError(name, f"returned a command of shape {shape}; a command holds one "
                                 "value per leg, shape (6,)")
    if cmd.actuation is not actuation:
        raise CommandError(name, f"returned {cmd.actuation.quantity} but declared "
                                 f"{actuation.quantity} (its 'actuation' attribute)")
    return cmd  # type: ignore[no-any-return]


class PerTrialLoop:
    """The batch interface over one controller per trial (``step`` in a loop).

    A trial whose controller raises (in ``reset`` or ``step``) or returns a command of the
    wrong shape or kind is isolated: its row gets a zero command and its exception in
    :attr:`crashes`, the other rows are stepped as usual (the engine ends that trial with
    the exception and the step; nothing is run twice).

    Args:
        factory: Builds a fresh controller (with its options).
    """

    def __init__(self, factory: Callable[[], Any],
                 actuation: Actuation = Actuation.VELOCITY) -> None:
        self.factory = factory
        #: What the wrapped controllers command.
        self.actuation = actuation
        self.controllers: list[Any] = []
        #: The last :class:`Command` of each row of the last step (diagnostics).
        self.last_commands: list[Command] = []
        #: The rows (positions in the last observation batch) whose controller raised at
        #: the last step, with the exception.
        self.crashes: dict[int, BaseException] = {}

    def reset_batch(self, contexts: Sequence[ControllerContext]) -> None:
        """One controller per context, reset with it (a reset that raises fails that
        trial at its first step)."""
        self.controllers = []
        for ctx in contexts:
            ctrl = self.factory()
            try:
                ctrl.reset(ctx)
            except Exception as exc:  # that trial's failure, reported at step 0
                ctrl = _FailedReset(exc)
            self.controllers.append(ctrl)

    def step_batch(self, observations: ObservationBatch) -> CommandBatch:
        """``step`` of each row's controller."""
        cmds = []
        self.crashes = {}
        for k, t in enumerate(observations.trials):
            ctrl = self.controllers[int(t)]
            try:
                cmd = checked_command(ctrl.step(observations.item(k)),
                                      str(getattr(ctrl, "name", type(ctrl).__name__)),
                                      self.actuation)
            except Exception as exc:  # that trial's failure
                self.crashes[k] = exc
                cmd = Command.refuse(f"{type(exc).__name__}: {exc}", actuation=self.actuation)
            cmds.append(cmd)
        self.last_commands = cmds
        return CommandBatch.from_commands(cmds)


def batch_controller(name: str, options: dict[str, Any], batched: bool = True) -> Any:
    """The batch-interface object of a registered controller.

    Args:
        name: Registry name or ``module:attr``.
        options: The controller's options.
        batched: Use the controller's own ``step_batch`` when it has one (False: always
            the per-trial loop, the reference the batched path is tested against).

    Returns:
        An object with ``reset_batch`` and ``step_batch``.
    """
    ctrl = registry.create(name, **options)
    if batched and supports_batch(ctrl):
        return ctrl
    first = [ctrl]

    def factory() -> Controller:
        return first.pop() if first else registry.create(name, **options)

    return PerTrialLoop(factory, actuation_of(ctrl))
