"""The controller plugin interface: one step over a batch of trials.

A controller sees only what a real robot and camera give (an
:class:`Observation`, or an :class:`ObservationBatch` of many trials) and what the user
knows or calibrated (a :class:`ControllerContext`); it never sees the simulator's true
state. The data types live in :mod:`controllers.data` and are re-exported here.

Controllers are found by name in the registry (:mod:`controllers.registry`, re-exported
here: ``registry``, ``Registry``, ``ENTRY_POINT_GROUP``).
"""

from __future__ import annotations

import logging
from abc import ABC
from collections.abc import Sequence
from dataclasses import replace
from typing import Any, final

import numpy as np

from controllers.data import (
    GOAL_FIELDS,
    TRIAL_ZERO,
    Command,
    CommandBatch,
    ControllerContext,
    Goal,
    GoalBatch,
    Observation,
    ObservationBatch,
    observation_problem,
)
from controllers.options import RemembersOptions
from hexapod.actuation import Actuation

log = logging.getLogger(__name__)


class Controller(RemembersOptions, ABC):
    """A controller: ``reset_batch(contexts)`` once, then ``step_batch(observations)``
    every period, over the trials of a batch (``docs/plugins.md``).

    Subclasses set ``name`` and ``features`` (of ``lengths``, ``normals``, ``lines``,
    ``directions``), say what they command in ``actuation`` (leg velocities unless set to
    :attr:`~hexapod.actuation.Actuation.FORCE`). A class is its own factory: its
    constructor takes the options as keyword arguments.

    The step is ONE method over a batch of trials, :meth:`step_batch`: the base's
    computes the rows it can as arrays (:meth:`step_arrays`) and steps the others with
    each trial's own instance (:meth:`step_trial`, the package's one per-row loop). A
    controller defines :meth:`reset_trial` and :meth:`step_trial` (and maybe
    :meth:`step_arrays`), or overrides :meth:`reset_batch`, :meth:`step_batch` and (for
    a goal that moves) :meth:`retarget_batch`. :meth:`step`, :meth:`reset` and
    :meth:`retarget` are the final per-trial adapters (a batch of one: the servo loop);
    a class of this shape that overrides one gets a ``TypeError``.

    A plugin written before batches, that defines ``reset(context)`` and
    ``step(observation)`` (and maybe ``retarget(goal)``), keeps working: the base takes
    them as its per-trial methods (the batch then steps one instance per trial).

    Failures of one trial stay that trial's (:meth:`step_rows`, :meth:`reset_batch`); a
    batch step that raises as a whole (an own ``step_batch``, :meth:`step_arrays`) fails
    the batch.
    """

    #: Registry name.
    name: str = "controller"
    #: Observation fields the controller needs.
    features: frozenset[str] = frozenset({"lengths"})
    #: What the commands set: leg velocities [m/s] (default) or leg forces [N].
    actuation: Actuation = Actuation.VELOCITY
    #: The instance of each trial of the batch (this one is trial 0), after a reset.
    trial_instances: list[Any] = []  # noqa: RUF012 (replaced, never mutated)
    #: The context each instance was last reset with (None before).
    trial_context: ControllerContext | None = None
    #: The rows (positions in the last stepped batch) whose trial's instance raised or
    #: returned a malformed command at the last :meth:`step_batch`, with the exception.
    crashes: dict[int, BaseException] = {}  # noqa: RUF012 (replaced, never mutated)
    #: Set by the base on a plugin class that defines the per-trial ``step`` itself.
    _per_trial_plugin: bool = False

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        batch_shaped = any({"step_batch", "step_trial", "step_arrays"} & vars(k).keys()
                           for k in cls.__mro__
                           if k is not Controller and issubclass(k, Controller))
        if "step" in vars(cls) and not getattr(cls, "_per_trial_plugin", False):
            if batch_shaped:
                raise TypeError(f"{cls.__qualname__}: step(observation) is the base's "
                                "per-trial adapter (final): define step_batch or step_trial")
            cls._per_trial_plugin = True  # a plugin written before batches
        if getattr(cls, "_per_trial_plugin", False):  # its methods are the trial's
            for name in ("reset", "step", "retarget"):
                method = getattr(cls, name)
                if method is not getattr(Controller, name):  # its own or inherited
                    setattr(cls, name + "_trial", method)
            return
        if batch_shaped:  # the adapters are final
            for name, batch in (("reset", "reset_batch"), ("retarget", "retarget_batch")):
                if getattr(cls, name) is not getattr(Controller, name):
                    raise TypeError(f"{cls.__qualname__}: {name}() is the base's per-trial "
                                    f"adapter (final): define {batch} or {name}_trial")

    # ------------------------------------------------------------------ per-trial adapters
    @final
    def reset(self, context: ControllerContext) -> None:
        """Prepare a batch of one trial (:meth:`reset_batch` of ``[context]``).

        Raises:
            ContextError: A field the controller needs is missing or invalid.
        """
        self.reset_batch([context])
        failed = self.trial_instances[0] if self.trial_instances else None
        if isinstance(failed, FailedReset):
            self.trial_instances = []
            raise failed.exc

    @final
    def step(self, observation: Observation) -> Command:
        """The command of one observation: :meth:`step_batch` of a batch of one (never
        raises for bad measurements; with the base's batch step, :meth:`step_row`).

        Raises:
            Exception: The trial's own failure (what its step raised, or a
                :class:`~controllers.exceptions.CommandError` for a malformed command).
        """
        if not self.trial_instances:
            return self._not_reset()
        cls = type(self)
        if cls.step_batch is Controller.step_batch:
            if cls.step_row is Controller.step_row:  # (its body, one call less)
                return self.trial_instances[0].step_trial(observation)  # type: ignore[no-any-return]
            return self.step_row(0, observation)
        batch = ObservationBatch.of(observation)
        if batch is None:
            problem = observation_problem(observation, self.features)
            return Command.refuse(problem or "malformed observation", actuation=self.actuation)
        out = self.step_batch(batch)
        crash = self.crashes.get(0)
        if crash is not None:
            raise crash
        return out.command(0)

    @final
    def retarget(self, goal: Goal) -> None:
        """A new goal for a batch of one, keeping the state (:meth:`retarget_batch`).

        Raises:
            ContextError: The goal is invalid, or :meth:`reset` was not called.
        """
        self.retarget_batch(TRIAL_ZERO, GoalBatch.of(goal))

    # ------------------------------------------------------------------ the batch
    def reset_batch(self, contexts: Sequence[ControllerContext]) -> None:
        """One instance per context (this one is the first; the others built with its
        options, :meth:`clone`), each reset with its context by :meth:`reset_trial`.

        Where every row is stepped by its trial's instance (neither :meth:`step_batch`
        nor :meth:`step_arrays` overridden), a trial whose reset raises fails alone, at
        its first step (its place holds a :class:`FailedReset`).

        Raises:
            ContextError: A context the controller cannot use (where rows are computed
                as arrays, the batch's reset fails as a whole).
        """
        isolate = (type(self).step_batch is Controller.step_batch  # rows by their instances
                   and type(self).step_arrays is Controller.step_arrays)
        instances: list[Any] = []
        self.crashes = {}
        for k, ctx in enumerate(contexts):
            inst = self if k == 0 else self.clone()
            try:
                inst.reset_trial(ctx)
            except Exception as exc:
                if not isolate:
                    raise
                log.debug("%s: the reset of trial %d raised %r", self.name, k, exc)
                instances.append(FailedReset(exc))
                continue
            inst.trial_context = ctx
            instances.append(inst)
        self.trial_instances = instances

    def step_batch(self, observations: ObservationBatch) -> CommandBatch:
        """The commands of every row: the rows the controller computes as arrays
        (:meth:`step_arrays`, for two rows or more: one row costs less by its instance),
        the others each by its trial's instance (:meth:`step_rows`)."""
        n = len(observations)
        self.crashes = {}
        if (unreset := self.checked_batch(observations)) is not None:
            return unreset
        if n == 1:  # a batch of one (the per-trial engine's): its row by its instance
            return CommandBatch.of_row(self._row_command(0, int(observations.trials[0]),
                                                         observations.item(0)),
                                       self.actuation)
        out = CommandBatch.zeros(n, self.actuation)
        if n:
            self.step_rows(observations, self.step_arrays(observations, out), out)
        return out

    def checked_batch(self, observations: ObservationBatch) -> CommandBatch | None:
        """How every batch step starts: every row refused (zero, with the reason) before a
        reset made the trials' instances, else None once the rows' trials and the arrays'
        shapes are checked (those of a batch of one made by ``ObservationBatch.of``, the
        per-trial step's, were checked there).

        Raises:
            ValueError: A row's trial is not one of the batch's (``0 <= trial < n``), the
                trials are not distinct integers, or an array is not of the batch's shape
                (the field named).
        """
        trials = self.trial_instances
        if trials:
            rows, size = observations.trials, len(trials)
            n = len(rows)
            if n > 1 or observations.single is None:
                problem = observations.shape_problem()
                if problem is not None:
                    raise ValueError(f"{self.name}: {problem}")
            if (n == 1 and 0 <= rows.item() < size) or (n > 1 and (
                    rows.min() >= 0 and rows.max() < size)) or not n:
                return None
            raise ValueError(f"{self.name}: trials {np.asarray(rows).tolist()} outside the "
                             f"batch's {size} trials (0 to {size - 1})")
        out = CommandBatch.zeros(len(observations), self.actuation)
        for j in range(len(observations)):
            out.put(j, self._not_reset())
        return out

    def _not_reset(self) -> Command:
        """The refusal of a step before a reset."""
        return Command.refuse(f"{self.name}: reset(context) was not called",
                              actuation=self.actuation)

    def step_arrays(self, observations: ObservationBatch, out: CommandBatch) -> np.ndarray:
        """Compute the rows the controller can as arrays, into ``out``; returns the rows
        left to the trials' instances (by default all of them)."""
        return np.arange(len(observations))

    def step_rows(self, observations: ObservationBatch, rows: np.ndarray,
                  out: CommandBatch) -> None:
        """Step ``rows`` of a batch one by one (:meth:`step_row`), writing the commands
        into ``out``: a row whose step raises, or returns a command of the wrong type,
        shape or kind (:func:`checked_command`), gets a refusal and its exception in
        :attr:`crashes` (by position in the batch); the other rows are stepped as usual."""
        trials = observations.trials
        for k in rows.tolist():
            out.put(k, self._row_command(k, int(trials[k]), observations.item(k)))

    def _row_command(self, k: int, trial: int, observation: Observation) -> Command:
        """The checked command of row ``k`` (trial ``trial``) by its trial's instance, or
        the refusal of its failure (the exception kept in :attr:`crashes`)."""
        try:
            return checked_command(self.step_row(trial, observation), self.name,
                                   self.actuation)
        except Exception as exc:  # that trial's failure
            if not self.crashes:
                self.crashes = {}
            self.crashes[k] = exc
            return Command.refuse(f"{type(exc).__name__}: {exc}", actuation=self.actuation)

    def step_row(self, trial: int, observation: Observation) -> Command:
        """The command of one row, by its trial's instance (:meth:`step_trial`)."""
        return self.trial_instances[trial].step_trial(observation)  # type: ignore[no-any-return]

    def retarget_batch(self, trials: np.ndarray, goals: GoalBatch) -> None:
        """New goals for some trials (row ``j`` of ``goals`` for trial ``trials[j]``),
        keeping their state: each instance's :meth:`retarget_trial`.

        Raises:
            ContextError: A goal the controller cannot use, or no reset yet.
        """
        if not self.trial_instances:
            from controllers.exceptions import ContextError

            raise ContextError(self.name, "context", "retarget(goal) before reset(context)")
        for j, k in enumerate(np.asarray(trials, dtype=int).tolist()):
            inst = self.trial_instances[k]
            if isinstance(inst, FailedReset):  # it fails at its next step
                continue
            goal = goals.item(j)
            inst.retarget_trial(goal)
            if inst.trial_context is not None:  # (None: an own reset_batch's instance)
                inst.trial_context = replace(inst.trial_context, goal=goal)

    # ------------------------------------------------------------------ one trial
    def reset_trial(self, context: ControllerContext) -> None:
        """Prepare this instance for one trial (the estimated parameters and the goal)."""
        cls = type(self)
        if cls.reset is not Controller.reset:  # a per-trial plugin's reset, without step
            raise NotImplementedError(
                f"{cls.__qualname__}: defines reset(context) but no step(observation): a "
                "controller of one trial defines both (a batch one step_batch, or "
                "reset_trial and step_trial)")
        if cls.step is not Controller.step:  # a per-trial plugin's step, without reset
            raise NotImplementedError(
                f"{cls.__qualname__}: defines step(observation) but no reset(context): a "
                "controller of one trial defines both (reset reads the trial's goal and "
                "parameters)")
        raise NotImplementedError(f"{cls.__qualname__}: defines neither reset(context) "
                                  "with step(observation), nor reset_batch with step_batch")

    def step_trial(self, observation: Observation) -> Command:
        """The command of this instance's trial (never raises for bad measurements)."""
        raise NotImplementedError(f"{type(self).__qualname__}: defines neither step_batch "
                                  "nor step_trial")

    def retarget_trial(self, goal: Goal) -> None:
        """A new goal for this instance's trial (by default a reset with it: the state
        starts afresh).

        Raises:
            NotImplementedError: The instance has no context of its own to reset with
                (its controller's own ``reset_batch`` made the batch's instances; it
                then defines ``retarget_batch``, or this method).
        """
        if self.trial_context is None:
            raise NotImplementedError(
                f"{type(self).__qualname__}: a new goal for a running trial (a trajectory "
                "task gives one every period), and the controller's own reset_batch left "
                "no per-trial context to reset with: define retarget_batch(trials, goals) "
                "(or retarget_trial(goal)) to take it")
        self.reset_trial(replace(self.trial_context, goal=goal))


class FailedReset:
    """The place of a trial whose reset raised (:meth:`Controller.reset_batch`): its
    step raises that exception again.

    Args:
        exc: The reset's exception.
    """

    trial_context: ControllerContext | None = None

    def __init__(self, exc: BaseException) -> None:
        self.exc = exc

    def step_trial(self, observation: Observation) -> Command:
        """Raise the reset's exception."""
        raise self.exc


def checked_command(cmd: Any, name: str, actuation: Actuation) -> Command:
    """A per-trial command of the right type, shape and kind.

    Args:
        cmd: What a trial's step returned.
        name: The controller's name (named by the refusal).
        actuation: What the controller declared it commands.

    Raises:
        CommandError: Not a :class:`Command`, not 6 leg values, or another kind than the
            controller declared (named, with the shapes or kinds).
    """
    if type(cmd) is Command and cmd.actuation is actuation:  # the common case
        values = cmd.forces if actuation is Actuation.FORCE else cmd.velocities
        if type(values) is np.ndarray and values.shape == (6,):
            return cmd
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


# The registry lives in :mod:`controllers.registry` (documented there); re-exported for the
# names users import from here.
from controllers.registry import ENTRY_POINT_GROUP as ENTRY_POINT_GROUP  # noqa: E402
from controllers.registry import Registry as Registry  # noqa: E402
from controllers.registry import registry as registry  # noqa: E402

__all__ = [
    "GOAL_FIELDS", "Actuation", "Command", "CommandBatch", "Controller",
    "ControllerContext", "FailedReset", "Goal", "GoalBatch", "Observation", "ObservationBatch",
    "checked_command", "observation_problem",
]
