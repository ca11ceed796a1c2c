"""Images of 3D segments through a distorted lens, as adaptive polylines.

With lens distortion the image of a straight 3D segment is a curve. The renderer
(:mod:`vision.render`) fills polygons, so each curve is replaced by a polyline whose
vertices are true projections of points of the segment, fine enough that the
polyline stays within a tolerance of the curve: a segment of the polyline (between
the images of the 3D points ``s_a`` and ``s_b``) is split at the image of the 3D
midpoint ``(s_a + s_b) / 2`` while that image is farther than ``tolerance_px`` from
the chord. For a curve of slowly varying curvature the largest distance between a
chord and its arc is within a few percent of the distance at the middle, so the
polyline is within about ``tolerance_px`` of the curve everywhere (the tests check
0.02 px on the limbs with the default tolerance, by dense sampling). The split is
vectorised over all segments of all curves, one projection per level.
"""

from __future__ import annotations

import numpy as np

from vision.cameras.base import Camera

#: Default largest distance [px] between the image of a segment's 3D midpoint and
#: the chord it replaces.
CURVE_TOLERANCE_PX = 0.005

#: Levels of halving at most (a segment is then 2^-24 of the initial one).
MAX_DEPTH = 24


def projected_polylines(
    camera: Camera,
    starts: np.ndarray,
    ends: np.ndarray,
    s: np.ndarray,
    tolerance_px: float = CURVE_TOLERANCE_PX,
    max_depth: int = MAX_DEPTH,
) -> list[np.ndarray]:
    """Adaptive pixel polylines of the images of 3D segments.

    Args:
        camera: The camera (:meth:`Camera.project`, distortion included).
        starts: (L, 3) first end of each segment, in the camera frame [m].
        ends: (L, 3) second end of each segment [m].
        s: (n,) increasing initial parameters in ``[0, 1]`` (``n >= 2``; the points
            ``start + s (end - start)``), the coarsest sampling of every curve.
        tolerance_px: Largest distance [px] of a segment's midpoint image from its
            chord (> 0).
        max_depth: Most halvings of an initial interval.

    Returns:
        L arrays (V_k, 2) [px], the vertices of each polyline in the order of ``s``
        (from ``starts`` to ``ends``); a vertex the camera does not image (behind it,
        or beyond the lens's fold, where OpenCV's pixel is of no image) is NaN, and the
        curve is not refined next to it (beyond a fold every level split: 24 levels
        took 28 s for a camera at the base origin).
    """
    a = np.asarray(starts, float).reshape(-1, 3)
    d = np.asarray(ends, float).reshape(-1, 3) - a
    s0 = np.asarray(s, float)
    L, n = a.shape[0], s0.size
    X0 = a[:, None, :] + s0[None, :, None] * d[:, None, :]
    pix0, im0 = camera.project_imaged(X0)
    ids = np.repeat(np.arange(L), n - 1)
    sa, sb = np.tile(s0[:-1], L), np.tile(s0[1:], L)
    pa, pb = pix0[:, :-1].reshape(-1, 2), pix0[:, 1:].reshape(-1, 2)
    ia, ib = im0[:, :-1].reshape(-1), im0[:, 1:].reshape(-1)
    kept_id, kept_s, kept_p = [np.arange(L)], [np.full(L, s0[-1])], [pix0[:, -1]]
    kept_i = [im0[:, -1]]
    for _ in range(max_depth):
        if ids.size == 0:
            break
        sm = 0.5 * (sa + sb)
        Xm = a[ids] + sm[:, None] * d[ids]
        pm, im = camera.project_imaged(Xm)
        chord = pb - pa
        length = np.hypot(chord[:, 0], chord[:, 1])
        off = pm - pa
        cross = np.abs(chord[:, 0] * off[:, 1] - chord[:, 1] * off[:, 0])
        with np.errstate(invalid="ignore", divide="ignore"):
            dev = np.where(length > 0, cross / length, np.hypot(off[:, 0], off[:, 1]))
            split = (dev > tolerance_px) & ia & ib & im  # (NaN: False)
        keep = ~split
        kept_id.append(ids[keep])
        kept_s.append(sa[keep])
        kept_p.append(pa[keep])
        kept_i.append(ia[keep])
        ids = np.concatenate([ids[split], ids[split]])
        sa, sb = np.concatenate([sa[split], sm[split]]), np.concatenate([sm[split], sb[split]])
        pa, pb = np.concatenate([pa[split], pm[split]]), np.concatenate([pm[split], pb[split]])
        ia, ib = np.concatenate([ia[split], im[split]]), np.concatenate([im[split], ib[split]])
    kept_id.append(ids)
    kept_s.append(sa)
    kept_p.append(pa)
    kept_i.append(ia)
    all_id, all_s = np.concatenate(kept_id), np.concatenate(kept_s)
    # a vertex the lens does not image is NaN, as one behind the camera (beyond a fold
    # OpenCV's pixel is of no image: a polygon through it crossed the picture)
    all_p = np.where(np.concatenate(kept_i)[:, None], np.concatenate(kept_p), np.nan)
    order = np.lexsort((all_s, all_id))
    counts = np.bincount(all_id, minlength=L)
    return np.split(all_p[order], np.cumsum(counts)[:-1])
