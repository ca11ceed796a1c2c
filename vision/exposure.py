"""Motion blur: an image exposed while the legs move.

A camera integrates the light over its exposure time ``T``. :func:`render_exposed`
approximates the integral by the mean of ``S`` sub-images drawn at poses sampled along
the motion (the caller gives them: the midpoints of ``S`` equal slices of the exposure),
then applies the optics' blur and the pixel noise once, as the sensor does to a single
image. A leg edge moving at ``v`` pixels per second across the image is smeared into a
ramp ``v T`` pixels wide (a staircase of ``S`` steps of ``v T / S`` pixels, smoothed by
the renderer's anti-aliasing): choose ``S`` so that ``v T / S`` stays near a pixel.

One pose gives the renderer's image bit for bit (no exposure).
"""

from __future__ import annotations

import numpy as np

from vision.exceptions import RenderError
from vision.render import Renderer


def render_exposed(renderer: Renderer, rotations: np.ndarray, translations: np.ndarray
                   ) -> np.ndarray:
    """The mean of the scene drawn at each pose, then the optics and the noise.

    Args:
        renderer: The renderer (its style's blur and noise are applied once).
        rotations: (3, 3) one pose, or (S, 3, 3) the platform orientations along the
            exposure (base frame).
        translations: (3,) or (S, 3) the platform positions along it [m].

    Returns:
        (height, width) uint8 image.

    Raises:
        RenderError: When the shapes disagree or a sequence is empty.
    """
    R = np.asarray(rotations, float)
    t = np.asarray(translations, float)
    if R.ndim == 2:
        return renderer.render(R, t)
    if R.ndim != 3 or t.ndim != 2 or len(R) != len(t) or len(R) == 0:
        raise RenderError("exposure poses", f"expected (S, 3, 3) rotations and (S, 3) "
                          f"translations, S >= 1, got {R.shape} and {t.shape}")
    total = np.zeros(renderer.background.shape, dtype=np.float64)
    for Rk, tk in zip(R, t, strict=True):
        total += renderer.draw(Rk, tk)
    img = np.rint(total / len(R)).astype(np.uint8)
    return renderer.finish(img)


def middle_pose(rotations: np.ndarray, translations: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """The pose at the middle of the exposure (the sample nearest it): what the image
    shows on average, used for the detector's prediction."""
    R = np.asarray(rotations, float)
    t = np.asarray(translations, float)
    if R.ndim == 2:
        return R, t
    k = len(R) // 2
    return R[k], t[k]
