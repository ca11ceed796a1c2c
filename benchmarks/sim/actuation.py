"""The study worlds' side of typed actuation (:mod:`hexapod.actuation`).

The kinematic world integrates leg velocities exactly; it refuses a controller that
commands leg forces (before its first step, and any batch of another kind than the
controller declared), with an :class:`~hexapod.exceptions.ActuationError` naming the
controller. The trial's row then carries that message as its failure.

The dynamic world (``[robot] world = "dynamic"``) applies both: leg velocities go to
velocity-mode drives (the robot file's ``[drives] mode``), leg forces to the same drives
switched to force (torque) mode for that controller (:func:`drive_plant`): the drives'
mode follows what the controller commands, the rest of the robot file (force limits,
friction, rotor inertia, encoders) is kept. A non-finite force never reaches the drives:
the trial fails on it with the command named (:meth:`benchmarks.sim.book.Book.command`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from controllers.base import CommandBatch
from controllers.batch import actuation_of
from hexapod.actuation import Actuation, check_actuation

#: What the kinematic world applies.
KINEMATIC_WORLD: tuple[Actuation, ...] = (Actuation.VELOCITY,)
#: How the messages name it.
KINEMATIC_WORLD_NAME = "the kinematic world"
#: What the dynamic world applies.
DYNAMIC_WORLD: tuple[Actuation, ...] = (Actuation.VELOCITY, Actuation.FORCE)
#: How the messages name it.
DYNAMIC_WORLD_NAME = "the dynamic world"


def world_actuation(sc: Any) -> tuple[tuple[Actuation, ...], str]:
    """What the scenario's world applies and how messages name it.

    Args:
        sc: The scenario (``sc.world``: ``"kinematic"`` or ``"dynamic"``).
    """
    if getattr(sc, "world", "kinematic") == "dynamic":
        return DYNAMIC_WORLD, DYNAMIC_WORLD_NAME
    return KINEMATIC_WORLD, KINEMATIC_WORLD_NAME


def drive_plant(plant: Any, actuation: Actuation, label: str) -> None:
    """Put the plant's drives in the mode of what the controller commands (a dynamic
    plant's ``use_actuation``; the kinematic plant has no drives)."""
    use = getattr(plant, "use_actuation", None)
    if callable(use):
        use(actuation, label)


def require_actuation(controller: Any, label: str,
                      accepted: tuple[Actuation, ...] = KINEMATIC_WORLD,
                      receiver: str = KINEMATIC_WORLD_NAME) -> Actuation:
    """The actuation ``controller`` declares, if ``receiver`` applies it.

    Args:
        controller: A controller or batch wrapper (its ``actuation`` attribute).
        label: The controller's label in the study (named by the refusal).
        accepted: What the world applies.
        receiver: How the refusal names the world.

    Raises:
        ActuationError: The world does not apply it.
    """
    return check_actuation(actuation_of(controller), accepted, receiver, label)


def require_batch(commands: CommandBatch, declared: Actuation, label: str,
                  rows: int | None = None) -> None:
    """Refuse a batch of another kind than its controller declared, or of another shape
    than ``(rows, 6)``.

    Raises:
        ActuationError: ``commands.actuation`` is not ``declared``.
        CommandError: The values are not one row of 6 leg values per observed trial.
    """
    if rows is not None:
        shape = np.shape(commands.values)
        if shape != (rows, 6):
            from controllers.exceptions import CommandError

            raise CommandError(label, f"returned commands of shape {shape} for {rows} "
                                      f"trials; expected ({rows}, 6): one row of 6 leg "
                                      "values per trial")
    if commands.actuation is not declared:
        check_actuation(commands.actuation, (declared,),
                        f"a study whose controller declared {declared.quantity}", label)
