"""Leg forces as colours (the dynamic world's records): a leg's rod is grey at rest and
turns orange as its drive pushes (lengthens it), blue as it pulls, fully so at the drive's
force limit; a saturated drive is drawn magenta. Plain arrays, no MeshCat."""

from __future__ import annotations

import numpy as np

from hexapod.model import LEG_ROD_COLOR

#: Colour (RGBA) of a rod whose drive pushes at its force limit.
PUSH_COLOR = np.array([1.0, 0.45, 0.0, 1.0])
#: Colour (RGBA) of a rod whose drive pulls at its force limit.
PULL_COLOR = np.array([0.1, 0.3, 1.0, 1.0])
#: Colour (RGBA) of a rod whose drive is saturated (at or beyond 99.9 % of its limit).
SATURATED_COLOR = np.array([0.9, 0.0, 0.9, 1.0])


def force_colours(forces: np.ndarray, limits: np.ndarray) -> np.ndarray:
    """RGBA colours (..., 6, 4) of the legs' rods for their drive forces.

    Args:
        forces: (..., 6) drive forces [N], positive pushing the platform away.
        limits: (6,) the drives' force limits [N], positive.

    Returns:
        The rest colour blended towards :data:`PUSH_COLOR` or :data:`PULL_COLOR` by
        ``|f| / limit`` (clipped to 1); :data:`SATURATED_COLOR` at the limit.
    """
    f = np.nan_to_num(np.asarray(forces, float))
    ratio = np.clip(np.abs(f) / np.asarray(limits, float), 0.0, 1.0)[..., None]
    target = np.where((f >= 0)[..., None], PUSH_COLOR, PULL_COLOR)
    out = (1.0 - ratio) * LEG_ROD_COLOR + ratio * target
    return np.where((ratio >= 0.999), SATURATED_COLOR, out)  # type: ignore[no-any-return]
