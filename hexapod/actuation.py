"""What a command commands: leg velocities [m/s] or leg forces [N].

A controller declares its :class:`Actuation` (``Controller.actuation``), every
command carries one (``Command.actuation``), and whatever applies commands (the
study's world, a backend, an emulated board) says which it accepts and refuses
the others with :class:`~hexapod.exceptions.ActuationError` (naming the
controller, what it commands, and what the receiver accepts).

The kinematic world, the simulated robot and the serial and GCS boards apply leg
velocities only; a force command there is refused, never converted.
"""

from __future__ import annotations

from collections.abc import Iterable
from enum import StrEnum

from hexapod.exceptions import ActuationError


class Actuation(StrEnum):
    """The quantity a leg command sets."""

    #: Leg velocities ``q_dot`` [m/s] (integrated by a kinematic robot).
    VELOCITY = "velocity"
    #: Leg (prismatic joint) forces ``f`` [N] (need a dynamic world).
    FORCE = "force"

    @property
    def unit(self) -> str:
        """SI unit of the command's entries."""
        return "m/s" if self is Actuation.VELOCITY else "N"

    @property
    def quantity(self) -> str:
        """What the six entries are, with their unit (for messages)."""
        return f"leg {self.value.replace('velocity', 'velocities').replace('force', 'forces')}" \
            f" [{self.unit}]"


def as_actuation(value: object, where: str = "actuation") -> Actuation:
    """An :class:`Actuation` from itself or its name (``"velocity"``, ``"force"``).

    Raises:
        ActuationError: An unknown name.
    """
    try:
        return Actuation(str(value))
    except ValueError:
        raise ActuationError(where, str(value), tuple(Actuation), where,
                             problem=f"unknown actuation {value!r}") from None


def check_actuation(actuation: object, accepted: Iterable[Actuation], receiver: str,
                    controller: str) -> Actuation:
    """Refuse a command kind the receiver cannot apply.

    Args:
        actuation: What the controller commands (an :class:`Actuation` or its name).
        accepted: What the receiver applies.
        receiver: Who applies it (for the message, e.g. ``"the kinematic world"``).
        controller: The controller's name or label (for the message).

    Returns:
        The actuation, as an :class:`Actuation`.

    Raises:
        ActuationError: ``actuation`` is not in ``accepted``.
    """
    kind = as_actuation(actuation, f"{controller}: actuation")
    ok = tuple(accepted)
    if kind not in ok:
        raise ActuationError(controller, kind.value, tuple(a.value for a in ok), receiver,
                             problem=None, quantity=kind.quantity,
                             accepted_quantities=[a.quantity for a in ok])
    return kind
