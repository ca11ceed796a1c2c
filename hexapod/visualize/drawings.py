"""Geometry of the scene's drawings: the camera's frustum or cone, the edges'
interpretation planes (plain arrays, no MeshCat)."""

from __future__ import annotations

import numpy as np

from hexapod.geometry import HexapodGeometry


def camera_centre(camera_from_base: np.ndarray) -> np.ndarray:
    T = np.asarray(camera_from_base, dtype=float)
    return np.asarray(-T[:3, :3].T @ T[:3, 3])


def frustum_segments(camera_from_base: np.ndarray, K: np.ndarray, size: np.ndarray,
                      kind: str, depth: float = 0.12) -> np.ndarray:
    """End points (3, 2N) in the base frame of the camera drawing's line segments.

    A perspective camera is a pyramid through the image corners (depth along the
    optical axis [m]); a unified (catadioptric) camera is a cone of rays 75 deg off
    its axis, wider than a hemisphere would be drawn by a pyramid; so is a fisheye,
    double sphere or extended unified camera.
    """
    T = np.asarray(camera_from_base, dtype=float)
    R = T[:3, :3]
    centre = camera_centre(T)
    w, h = float(size[0]), float(size[1])
    if kind == "perspective":
        Kinv = np.linalg.inv(K)
        corners = [Kinv @ np.array([u, v, 1.0]) for u, v in ((0, 0), (w, 0), (w, h), (0, h))]
        rim = [c / c[2] * depth for c in corners]
        # a small triangle above the top edge marks the image's "up" (-y)
        up = [rim[0] + 0.3 * (rim[1] - rim[0]), rim[0] + 0.7 * (rim[1] - rim[0]),
              0.5 * (rim[0] + rim[1]) + np.array([0.0, -0.25 * depth, 0.0])]
        loops = [rim, up]
    else:
        a = np.linspace(0.0, 2 * np.pi, 13)[:-1]
        half = np.deg2rad(75.0)
        rim = [depth * np.array([np.sin(half) * np.cos(x), np.sin(half) * np.sin(x),
                                 np.cos(half)]) for x in a]
        loops = [rim]
    segs: list[np.ndarray] = []
    for c in rim:
        segs += [np.zeros(3), c]
    for loop in loops:
        for k in range(len(loop)):
            segs += [loop[k], loop[(k + 1) % len(loop)]]
    pts = np.array(segs) @ R + centre  # camera frame -> base frame: R^T p + centre
    return np.asarray(pts.T)


def edge_planes(geometry: HexapodGeometry, rotation: np.ndarray, translation: np.ndarray,
                 centre: np.ndarray) -> np.ndarray:
    """Triangles (6, 2, 3, 3) [m]: camera centre and the two ends of each leg edge.

    A leg edge is a generator of the leg cylinder tangent to the ray from the camera
    centre; its interpretation plane contains the centre and the edge.
    """
    A = geometry.base_points
    B = np.asarray(translation) + geometry.platform_points @ np.asarray(rotation).T
    tris = np.zeros((6, 2, 3, 3))
    r = float(geometry.leg_radius)
    for i in range(6):
        axis = B[i] - A[i]
        length = float(np.linalg.norm(axis))
        u = axis / length
        d = (centre - A[i]) - ((centre - A[i]) @ u) * u
        dist = float(np.linalg.norm(d))
        if dist <= r:  # the centre is inside the cylinder: no edge
            continue
        dn = d / dist
        side = np.cross(u, dn)
        cos_a = r / dist
        sin_a = np.sqrt(1.0 - cos_a**2)
        for j, sgn in enumerate((1.0, -1.0)):
            p = A[i] + r * (cos_a * dn + sgn * sin_a * side)
            tris[i, j] = [centre, p, p + length * u]
    return tris
