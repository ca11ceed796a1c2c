"""The control grid on which every tracking controller samples its reference, and how
the references of many trials are sampled together.

A reference of duration ``T`` [s] is sampled once, at reset, at the instants ``k dt``
for ``k = 0 .. ceil(T / dt) + 1`` (:func:`grid_times`, ``dt`` the control period): the
last instant is past the reference's end, where the reference is at rest at its end
pose, so a controller stepped on the grid never evaluates the reference itself. An
observation time ``tr`` is on the grid when it is within :data:`GRID_TOLERANCE` of some
``k dt`` (:func:`grid_step`); off the grid, a controller evaluates the reference at
``tr``.

The trials' references are sampled :data:`CHUNK` trials at a time, trials of one model
world together (:func:`chunks`): their arrays stay in the processor's caches (200 trials
at once took longer than one by one). Every sample is a row of its own, so a trial's
grid holds the same numbers whatever trials it is sampled with.
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Sequence
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from controllers.data import ControllerContext

#: How far from ``k dt`` an observation time may be to be on the grid [s].
GRID_TOLERANCE = 1e-9
#: Trials whose references are sampled together.
CHUNK = 8


def grid_times(duration: float, dt: float) -> np.ndarray:
    """The control grid ``k dt`` [s], ``k = 0 .. ceil(duration / dt) + 1``, of a
    reference of ``duration`` [s] and a control period ``dt`` [s] (one instant past the
    reference's end)."""
    return dt * np.arange(math.ceil(float(duration) / dt) + 2)  # type: ignore[no-any-return]


def grid_step(tr: float, dt: float) -> int:
    """The step ``k`` of the control grid at ``tr`` [s] (``|tr - k dt| <=``
    :data:`GRID_TOLERANCE`, ``dt`` [s]), or -1 off the grid."""
    k = round(tr / dt)
    return k if abs(tr - k * dt) <= GRID_TOLERANCE and k >= 0 else -1


def model_world(context: ControllerContext) -> tuple[int, int]:
    """The key of a context's model world (its camera and robot objects): contexts of
    one model world can share one evaluation of the nominal model."""
    return id(context.camera), id(context.geometry)


def chunks(keys: Sequence[Hashable], size: int | None = CHUNK) -> list[list[int]]:
    """The indices of ``keys`` grouped by key (in order of first appearance), each group
    cut into chunks of at most ``size`` (None: not cut): the trials sampled together."""
    groups: dict[Hashable, list[int]] = {}
    for k, key in enumerate(keys):
        groups.setdefault(key, []).append(k)
    return [group[i:i + (size or len(group))] for group in groups.values()
            for i in range(0, len(group), size or len(group))]


__all__ = ["CHUNK", "GRID_TOLERANCE", "chunks", "grid_step", "grid_times", "model_world"]
