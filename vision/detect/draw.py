"""Display of a detection over its image."""

from __future__ import annotations

import cv2
import numpy as np

from vision.cameras import Camera
from vision.detect.common import EdgeDetection


def draw_detection(
    image: np.ndarray, camera: Camera, detection: EdgeDetection,
    colors: tuple[tuple[int, int, int], tuple[int, int, int]] = ((0, 0, 255), (255, 128, 0)),
) -> np.ndarray:
    """A BGR copy of the image with the detected edges (fitted curves over the span of
    their inlier points) and the inlier points drawn over it.

    Edge 1 in the first colour, edge 2 in the second (BGR).
    """
    out = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR) if image.ndim == 2 else image.copy()
    for i in range(6):
        for j in range(2):
            if not detection.edge_visible[i, j]:
                continue
            n = detection.normals[i, j]
            p = detection.points[i, j]
            p = p[np.all(np.isfinite(p), -1)]
            X = camera.lift(p)
            X = X - np.outer(X @ n, n)
            X /= np.linalg.norm(X, axis=-1, keepdims=True)
            # Extreme points along the great circle, then slerp between them.
            ref = X[0]
            tang = np.cross(n, ref)
            ang = np.arctan2(X @ tang, X @ ref)
            a = np.linspace(ang.min(), ang.max(), 40)
            arc = np.cos(a)[:, None] * ref + np.sin(a)[:, None] * tang
            pix, _ = camera.project(arc)
            pix = pix[np.all(np.isfinite(pix), -1)]
            cv2.polylines(out, [np.round(pix * 16).astype(np.int32)], False, colors[j], 1,
                          cv2.LINE_AA, 4)
            for q in p:
                cv2.circle(out, (round(q[0] * 16), round(q[1] * 16)), 2 * 16,
                           colors[j], 1, cv2.LINE_AA, 4)
    return out
