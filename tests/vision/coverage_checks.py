"""The row-coverage measurement of the renderer tests (test_render.py and, through a
distorting lens, test_render_distortion.py): along an image row, the leg coverage
summed across a limb gives where the limb crosses the row."""

from __future__ import annotations

import numpy as np

#: Width of the window across a limb [px].
WINDOW = 10


def limb_column(row: np.ndarray, x0: int, background: float, leg: float) -> float | None:
    """Where a limb crosses the window ``row[x0:x0 + 10]`` [px, pixel centres at integers]:
    from the fraction of each pixel the leg covers (1 inside, 0 on the background), the
    window's sum of coverage past its inside end. None unless the window is one monotonic
    step from fully covered to background, or back (another leg in it).

    Args:
        row: One image row (grey levels).
        x0: First column of the window.
        background: Grey level of the background.
        leg: Grey level of a leg's edge.
    """
    cov = (background - row[x0:x0 + WINDOW]) / (background - leg)
    step = np.diff(cov)
    if abs(cov[0] - 1) < 0.01 and abs(cov[-1]) < 0.01 and step.max() < 0.01:
        return float(x0 - 0.5 + cov.sum())  # inside on the left
    if abs(cov[0]) < 0.01 and abs(cov[-1] - 1) < 0.01 and step.min() > -0.01:
        return float(x0 + WINDOW - 0.5 - cov.sum())  # inside on the right
    return None
