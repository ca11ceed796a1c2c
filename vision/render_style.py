"""Rendering settings (:class:`RenderStyle`) and the static backgrounds of
:mod:`vision.render`.

Backgrounds: ``"plain"`` (uniform, bright, as in seed 003) or ``"cluttered"`` (a seeded
low-frequency texture plus random rectangles, discs and lines, brighter than the legs).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from vision.exceptions import RenderError
from vision.render_curves import CURVE_TOLERANCE_PX

BACKGROUNDS = ("plain", "cluttered")


@dataclass(frozen=True)
class RenderStyle:
    """How the legs are drawn.

    Attributes:
        background: ``"plain"`` or ``"cluttered"``.
        background_level: Grey level of the plain background [0-255].
        clutter_min: Darkest grey level of the cluttered background.
        clutter_seed: Seed of the cluttered background (it is static, like a scene).
        leg_edge_level: Grey level of the legs at their limbs.
        leg_centre_level: Grey level of the legs along the generator facing the camera.
        shading_bands: Number of nested bands used for the shading (>= 1).
        platform: Draw the platform disc.
        platform_level: Grey level of the platform disc.
        platform_radius: Radius of the platform disc [m]; default: the largest
            distance of a platform joint from the platform origin (as
            :func:`vision.legs.observe_legs`).
        blur_px: Standard deviation of the Gaussian blur [px] (0: none).
        noise_std: Standard deviation of the additive pixel noise [grey levels].
        edge_samples: Points per generator along a leg; default 2 for a perspective
            camera, 24 for a unified one. With lens distortion: the initial points
            (at least 5) of the adaptive subdivision (``curve_tolerance_px``).
        cap_samples: Points on each end disc of a leg.
        aa_compensation_px: Fallback renderer only (no C compiler): inward offset
            of every polygon [px]. OpenCV's anti-aliased ``fillPoly`` draws a shape
            about 0.7 px too large on each side (measured: 0.67 to 0.83 px depending
            on the edge direction, mean 0.72, at the 50 % grey level); the offset
            puts the 50 % level of the rendered edges on the true edges within about
            0.1 px. The exact-coverage renderer needs no offset.
        curve_tolerance_px: Distorted cameras only: a generator's image (a curve) is
            drawn as a polyline refined until the image of the 3D midpoint of each of
            its segments is within this distance of the chord [px]
            (:mod:`vision.render_curves`); the drawn limbs are within about this
            distance of the true curved limbs.
    """

    background: str = "plain"
    background_level: int = 230
    clutter_min: int = 120
    clutter_seed: int = 0
    leg_edge_level: int = 35
    leg_centre_level: int = 95
    shading_bands: int = 4
    platform: bool = True
    platform_level: int = 160
    platform_radius: float | None = None
    blur_px: float = 0.0
    noise_std: float = 0.0
    edge_samples: int | None = None
    cap_samples: int = 16
    aa_compensation_px: float = 0.72
    curve_tolerance_px: float = CURVE_TOLERANCE_PX

    def __post_init__(self) -> None:
        if self.background not in BACKGROUNDS:
            raise RenderError("background", f"expected one of {BACKGROUNDS}, got "
                                            f"{self.background!r}")
        for name in ("background_level", "clutter_min", "leg_edge_level", "leg_centre_level",
                     "platform_level"):
            v = getattr(self, name)
            if not 0 <= v <= 255:
                raise RenderError(name, f"expected a grey level in [0, 255], got {v}")
        if self.shading_bands < 1:
            raise RenderError("shading_bands", f"must be >= 1, got {self.shading_bands}")
        if not (math.isfinite(self.blur_px) and self.blur_px >= 0):
            raise RenderError("blur_px", f"must be finite and >= 0, got {self.blur_px}")
        if not (math.isfinite(self.noise_std) and self.noise_std >= 0):
            raise RenderError("noise_std", f"must be finite and >= 0, got {self.noise_std}")
        if self.edge_samples is not None and self.edge_samples < 2:
            raise RenderError("edge_samples", f"must be >= 2, got {self.edge_samples}")
        if self.cap_samples < 3:
            raise RenderError("cap_samples", f"must be >= 3, got {self.cap_samples}")
        if not (math.isfinite(self.curve_tolerance_px) and self.curve_tolerance_px > 0):
            raise RenderError("curve_tolerance_px",
                              f"must be finite and > 0, got {self.curve_tolerance_px}")


def make_background(
    width: int, height: int, style: RenderStyle
) -> np.ndarray:
    """The static background image (height, width) uint8 of a style."""
    if style.background == "plain":
        return np.full((height, width), style.background_level, np.uint8)
    rng = np.random.default_rng(style.clutter_seed)
    lo = float(style.clutter_min)
    small = rng.uniform(lo + 20, 250, size=(max(height // 64, 2), max(width // 64, 2)))
    img = cv2.resize(small.astype(np.float32), (width, height), interpolation=cv2.INTER_CUBIC)
    img = np.clip(img, lo, 255).astype(np.uint8)
    n = 40
    for _ in range(n):
        kind = rng.integers(3)
        level = int(rng.uniform(lo, 255))
        x, y = int(rng.uniform(0, width)), int(rng.uniform(0, height))
        size = int(rng.uniform(0.02, 0.15) * max(width, height))
        if kind == 0:
            x2 = x + int(rng.uniform(-size, size))
            y2 = y + int(rng.uniform(-size, size))
            cv2.rectangle(img, (x, y), (x2, y2), (level,), -1)
        elif kind == 1:
            cv2.circle(img, (x, y), size // 2, (level,), -1, cv2.LINE_AA)
        else:
            ang = rng.uniform(0, np.pi)
            x2, y2 = int(x + 3 * size * np.cos(ang)), int(y + 3 * size * np.sin(ang))
            cv2.line(img, (x, y), (x2, y2), (level,), int(rng.integers(1, 6)), cv2.LINE_AA)
    return img

