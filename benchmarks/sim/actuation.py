"""The study worlds' side of typed actuation (:mod:`hexapod.actuation`).

The kinematic world integrates leg velocities exactly; it refuses a controller that
commands leg forces (before its first step, and any batch of another kind than the
controller declared), with an :class:`~hexapod.exceptions.ActuationError` naming the
controller. The trial's row then carries that message as its failure.

The dynamic world (``[robot] world = "dynamic"``) applies both: leg velocities go to
velocity-mode drives (the robot file's ``[drives] mode``), leg forces to the same drives
switched to force (torque) mode for that controller (the plant's ``use_actuation``): the
drives' mode follows what the controller commands, the rest of the robot file (force
limits, friction, rotor inertia, encoders) is kept. A non-finite force never reaches the
drives: the trial fails on it with the command named
(:meth:`benchmarks.sim.book.Book.commanded`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from controllers.base import CommandBatch
from hexapod.actuation import Actuation, check_actuation


def world_actuation(sc: Any) -> tuple[tuple[Actuation, ...], str]:
    """What the scenario's world applies and how messages name it.

    Args:
        sc: The scenario (``sc.world``: ``"kinematic"`` or ``"dynamic"``).
    """
    if getattr(sc, "world", "kinematic") == "dynamic":
        return (Actuation.VELOCITY, Actuation.FORCE), "the dynamic world"
    return (Actuation.VELOCITY,), "the kinematic world"


def require_batch(commands: CommandBatch, declared: Actuation, label: str, rows: int
                  ) -> None:
    """Refuse a batch of another kind than its controller declared, or of another shape
    than ``(rows, 6)``.

    Raises:
        ActuationError: ``commands.actuation`` is not ``declared``.
        CommandError: The values are not one row of 6 leg values per observed trial.
    """
    shape = np.shape(commands.values)
    if shape != (rows, 6):
        from controllers.exceptions import CommandError

        raise CommandError(label, f"returned commands of shape {shape} for {rows} trials; "
                                  f"expected ({rows}, 6): one row of 6 leg values per trial")
    if commands.actuation is not declared:
        check_actuation(commands.actuation, (declared,),
                        f"a study whose controller declared {declared.quantity}", label)
