"""Cylindrical legs as image features (``docs/math.md`` section 4).

Leg ``i`` is a cylinder of radius ``r`` whose axis passes through ``A_i`` with
unit direction ``u_i`` (both in the camera frame). Its two apparent edges define
interpretation planes through the projection centre with unit normals
``n1, n2``:

``h = A x u``, ``h_hat = h / |h|``, ``w = u x h_hat``, ``sin(theta) = r / |h|``,
``n1 = cos(theta) h_hat - sin(theta) w``, ``n2 = -cos(theta) h_hat - sin(theta) w``.

Both satisfy ``n.A = -r``, ``n.u = 0``, ``|n| = 1``, and
``u = (n2 x n1) / |n2 x n1|``. This order and orientation is the convention of the
whole project (simulation, estimation and control).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from hexapod.geometry import HexapodGeometry
from hexapod.kinematics import legs_in_frame
from vision import kernels
from vision.cameras import Camera, PerspectiveCamera
from vision.occlusion import occluded_by_disc, occluded_by_legs, occluded_by_legs_compiled

__all__ = [
    "DEFAULT_MIN_VISIBLE_FRACTION",
    "DEFAULT_VISIBILITY_SAMPLES",
    "EdgePoints",
    "LegObservation",
    "directions_from_edges",
    "edge_points",
    "leg_edges",
    "limb_points",
    "observation_edge_points",
    "observe_edges",
    "observe_legs",
    "observe_legs_numpy",
    "occluded_by_disc",
    "occluded_by_legs",
]


def leg_edges(
    base_points: np.ndarray, directions: np.ndarray, radius: float | np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Edge normals of cylindrical legs.

    Args:
        base_points: (..., 6, 3) points ``A_i`` on the leg axes, in the camera frame [m].
        directions: (..., 6, 3) unit leg directions ``u_i`` in the camera frame.
        radius: Leg radius [m] (scalar or broadcastable to (..., 6)).

    Returns:
        ``normals`` (..., 6, 2, 3) and ``exists`` (..., 6): False where the
        projection centre is inside (or on) the cylinder, so that the edges do not
        exist; the normals there are NaN.
    """
    A = np.asarray(base_points, dtype=float)
    u = np.asarray(directions, dtype=float)
    r = np.asarray(radius, dtype=float)
    h = np.cross(A, u)
    hn = np.linalg.norm(h, axis=-1)
    exists = hn > r
    with np.errstate(invalid="ignore", divide="ignore"):
        h_hat = h / hn[..., None]
        w = np.cross(u, h_hat)
        s = (r / hn)[..., None]
        c = np.sqrt(np.clip(1.0 - s**2, 0.0, None))
    n1 = c * h_hat - s * w
    n2 = -c * h_hat - s * w
    normals = np.stack([n1, n2], axis=-2)
    normals = np.where(exists[..., None, None], normals, np.nan)
    return normals, exists


def directions_from_edges(normals: np.ndarray) -> np.ndarray:
    """Leg directions ``u = (n2 x n1) / |n2 x n1|`` from edge normals (..., 2, 3) -> (..., 3)
    (NaN where the normals are NaN or parallel), in one C call when compiled
    (``vision/csrc/sensor_kernels.c``: the numpy path's bits)."""
    n = np.asarray(normals, dtype=float)
    lib = kernels.library()
    if lib is not None and n.shape[-2:] == (2, 3):  # the same bits, one C call
        n = np.ascontiguousarray(n)
        out = np.empty((*n.shape[:-2], 3))
        lib.hexapod_directions_from_edges(n.ctypes.data, out.size // 3, out.ctypes.data)
        return out
    a0, a1, a2 = n[..., 1, 0], n[..., 1, 1], n[..., 1, 2]
    b0, b1, b2 = n[..., 0, 0], n[..., 0, 1], n[..., 0, 2]
    d = np.empty((*n.shape[:-2], 3))
    # np.cross and np.linalg.norm, operation for operation (the same bits), three times
    # faster on the engine's batches
    d[..., 0] = a1 * b2 - a2 * b1
    d[..., 1] = a2 * b0 - a0 * b2
    d[..., 2] = a0 * b1 - a1 * b0
    norm = np.sqrt(d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1] + d[..., 2] * d[..., 2])
    return d / norm[..., None]


# ============================================================================
# Observation of the legs by a camera: edges, image lines, visibility.
# ============================================================================

#: Default number of points sampled along each edge to decide its visibility.
DEFAULT_VISIBILITY_SAMPLES = 16
#: Default fraction of visible samples for an edge to count as observed.
DEFAULT_MIN_VISIBLE_FRACTION = 0.5


@dataclass(frozen=True)
class LegObservation:
    """What a camera sees of the six legs, batched over leading axes ``(...)``.

    Every vector is in the camera frame. Edge ``j`` of leg ``i`` is the limb
    (apparent contour) of the leg cylinder on the interpretation plane of normal
    ``normals[..., i, j, :]``: the 3D segment ``A_i + r n_ij + s q_i u_i``,
    ``s`` in ``[0, 1]``.

    Visibility rule: the edge is sampled at ``n_samples`` points ``s = (k + 1/2) /
    n_samples``; a sample is visible when it is imaged (in front of the camera /
    inside the mirror's field of view, and inside the image) and the segment from
    the projection centre to it crosses neither another leg (a solid finite
    cylinder of radius ``r`` between ``A_j`` and ``B_j``) nor the platform disc.
    An edge is observed (``edge_visible``) when its edges exist (camera outside
    the cylinder) and at least ``min_visible_fraction`` of its samples are visible.

    Attributes:
        base_points: (..., 6, 3) ``A_i`` [m].
        directions: (..., 6, 3) unit ``u_i``.
        lengths: (..., 6) ``q_i`` [m].
        normals: (..., 6, 2, 3) edge normals (convention of :func:`leg_edges`); NaN
            where the edges do not exist. Given for hidden edges too: mask them
            with ``edge_visible``.
        exists: (..., 6) False where the camera is inside the leg cylinder.
        edge_visible: (..., 6, 2) the edge is observed.
        visible_fraction: (..., 6, 2) fraction of visible samples.
        lines: (..., 6, 2, 3) unit lines in normalised pixel coordinates of the ideal
            (undistorted) image (:meth:`PerspectiveCamera.normal_to_line`), None for
            other cameras.
        segments: (..., 6, 2, 2, 2) pixels of the two ends (``s = 0``: base end,
            ``s = 1``: platform end) of each edge segment, in the raw (distorted)
            image; NaN where not imaged. (With lens distortion the image of the edge
            between them is a curve.)
            (For a unified camera the image of the edge is an arc of the conic
            between these ends.)
        visible_interval: (..., 6, 2, 2) ``s`` of the first and last visible samples
            (NaN when none is visible).
        platform_centre: (..., 3) centre of the platform disc [m].
        platform_normal: (..., 3) unit normal of the platform disc.
        platform_radius: Radius of the platform disc [m].
        radius: Leg radius [m].
    """

    base_points: np.ndarray
    directions: np.ndarray
    lengths: np.ndarray
    normals: np.ndarray
    exists: np.ndarray
    edge_visible: np.ndarray
    visible_fraction: np.ndarray
    lines: np.ndarray | None
    segments: np.ndarray
    visible_interval: np.ndarray
    platform_centre: np.ndarray
    platform_normal: np.ndarray
    platform_radius: float
    radius: float

    @property
    def direction_visible(self) -> np.ndarray:
        """(..., 6) both edges of the leg are observed (its direction is measurable)."""
        return np.all(self.edge_visible, axis=-1)

    @property
    def batch_shape(self) -> tuple[int, ...]:
        """Leading batch shape ``(...)``."""
        return tuple(self.lengths.shape[:-1])


def limb_points(
    base_points: np.ndarray,
    directions: np.ndarray,
    radius: float | np.ndarray,
    lengths: np.ndarray,
    normals: np.ndarray,
    s: np.ndarray,
) -> np.ndarray:
    """Points ``A_i + r n_ij + s q_i u_i`` on the edges (limbs) of the legs.

    Args:
        base_points: (..., 6, 3).
        directions: (..., 6, 3).
        radius: Leg radius [m].
        lengths: (..., 6).
        normals: (..., 6, 2, 3) edge normals.
        s: Fractions of the leg length, broadcastable to (..., 6, 2, N).

    Returns:
        (..., 6, 2, N, 3) camera-frame points [m].
    """
    A = np.asarray(base_points, float)[..., :, None, None, :]
    u = np.asarray(directions, float)[..., :, None, None, :]
    q = np.asarray(lengths, float)[..., :, None, None, None]
    n = np.asarray(normals, float)[..., None, :]
    s = np.asarray(s, float)[..., None]
    r = np.asarray(radius, float)
    if r.ndim:
        r = r[..., None, None, None]
    return A + r * n + (s * q) * u


def _check_sampling(min_visible_fraction: float, n_samples: int) -> None:
    if not 0.0 < min_visible_fraction <= 1.0:
        raise ValueError(f"min_visible_fraction must be in (0, 1], got {min_visible_fraction}")
    if n_samples < 1:
        raise ValueError(f"n_samples must be >= 1, got {n_samples}")


def observe_legs(
    camera: Camera,
    geometry: HexapodGeometry,
    rotation: np.ndarray,
    translation: np.ndarray,
    min_visible_fraction: float = DEFAULT_MIN_VISIBLE_FRACTION,
    n_samples: int = DEFAULT_VISIBILITY_SAMPLES,
    platform_radius: float | None = None,
    occlusion: bool = True,
) -> LegObservation:
    """Simulate what a camera sees of the legs at platform poses (batched).

    The compiled core (:func:`vision.fast_observe.observe_batch`) computes the legs,
    edges and visibility when it is available; :func:`observe_legs_numpy` is the
    numpy reference (same arguments, same results, tested equal).

    Args:
        camera: The camera (its ``camera_from_base`` places it).
        geometry: The robot (leg radius ``geometry.leg_radius``).
        rotation: (..., 3, 3) platform orientation in the base frame.
        translation: (..., 3) platform position in the base frame [m].
        min_visible_fraction: Fraction of visible samples (in ``(0, 1]``) for an edge
            to be observed (see :class:`LegObservation`).
        n_samples: Samples per edge for the visibility test.
        platform_radius: Radius of the platform disc [m]; default: the largest
            distance of a platform joint from the platform origin.
        occlusion: Test occlusions by the legs and the platform (True), or only
            existence and the image bounds (False).

    Returns:
        A :class:`LegObservation`.
    """
    _check_sampling(min_visible_fraction, n_samples)
    fast = _compiled_observation(camera, geometry, rotation, translation, min_visible_fraction,
                                 n_samples, platform_radius, occlusion)
    if fast is None:
        return observe_legs_numpy(camera, geometry, rotation, translation,
                                  min_visible_fraction, n_samples, platform_radius, occlusion)
    obs, lead, params = fast
    r = geometry.leg_radius
    A = obs.base_points.reshape(*lead, 6, 3)
    u = obs.directions.reshape(*lead, 6, 3)
    q = obs.lengths.reshape(*lead, 6)
    normals = obs.normals.reshape(*lead, 6, 2, 3)
    ends = limb_points(A, u, r, q, normals, np.array([0.0, 1.0]))
    segments, _ = camera.project(ends)
    lines = camera.normal_to_line(normals) if isinstance(camera, PerspectiveCamera) else None
    return LegObservation(
        base_points=A, directions=u, lengths=q, normals=normals,
        exists=obs.exists.reshape(*lead, 6),
        edge_visible=obs.edge_visible.reshape(*lead, 6, 2),
        visible_fraction=obs.visible_fraction.reshape(*lead, 6, 2),
        lines=lines, segments=segments,
        visible_interval=obs.visible_interval.reshape(*lead, 6, 2, 2),
        platform_centre=obs.platform_centre.reshape(*lead, 3),
        platform_normal=obs.platform_normal.reshape(*lead, 3),
        platform_radius=float(params.platform_radius[0]), radius=float(r))


def observe_edges(camera: Camera, geometry: HexapodGeometry, rotation: np.ndarray,
                  translation: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The edge normals (..., 6, 2, 3) and their visibility (..., 6, 2) of
    :func:`observe_legs` (default sampling, occlusions tested), the same numbers,
    without the rest of its observation (the image segments and lines, which cost about
    as much as the compiled core: a reference sampled on a control grid needs only
    these two)."""
    fast = _compiled_observation(camera, geometry, rotation, translation,
                                 DEFAULT_MIN_VISIBLE_FRACTION, DEFAULT_VISIBILITY_SAMPLES,
                                 None, True)
    if fast is None:
        seen = observe_legs(camera, geometry, rotation, translation)
        return np.asarray(seen.normals), np.asarray(seen.edge_visible, dtype=bool)
    obs, lead, _ = fast
    return obs.normals.reshape(*lead, 6, 2, 3), obs.edge_visible.reshape(*lead, 6, 2)


def _compiled_observation(camera: Camera, geometry: HexapodGeometry, rotation: np.ndarray,
                          translation: np.ndarray, min_visible_fraction: float,
                          n_samples: int, platform_radius: float | None, occlusion: bool
                          ) -> tuple[Any, tuple[int, ...], Any] | None:
    """The compiled core's observation of the poses (flat), the poses' leading shape and
    the world parameters; None where the core does not apply (not compiled, or a camera
    model it does not cover)."""
    from vision import fast_observe

    if (not fast_observe.compiled() or getattr(camera, "kind", None) not in (
            "perspective", "unified") or not fast_observe.supported(camera)):
        return None
    from hexapod.exceptions import ShapeError
    from hexapod.kinematics import check_rotations

    R = np.asarray(rotation, float)
    t = np.asarray(translation, float)
    if R.shape[-2:] != (3, 3):
        raise ShapeError("rotation", "shape (..., 3, 3)", R.shape)
    lead = R.shape[:-2]
    if t.shape != (*lead, 3):
        raise ShapeError("translation", f"shape {(*lead, 3)}", t.shape)
    if not (np.isfinite(R).all() and np.isfinite(t).all()):  # (as the numpy reference)
        raise ShapeError("pose", "finite values", "NaN or inf")
    check_rotations(R)
    params = fast_observe.WorldParams.from_worlds([geometry], [camera])
    if platform_radius is not None:
        params.platform_radius[:] = float(platform_radius)
    n = int(np.prod(lead, dtype=int))
    obs = fast_observe.observe_batch(params, R.reshape(n, 3, 3), t.reshape(n, 3),
                                     np.zeros(n, dtype=int), n_samples, min_visible_fraction,
                                     occlusion)
    return obs, lead, params


def observe_legs_numpy(
    camera: Camera,
    geometry: HexapodGeometry,
    rotation: np.ndarray,
    translation: np.ndarray,
    min_visible_fraction: float = DEFAULT_MIN_VISIBLE_FRACTION,
    n_samples: int = DEFAULT_VISIBILITY_SAMPLES,
    platform_radius: float | None = None,
    occlusion: bool = True,
) -> LegObservation:
    """The numpy reference of :func:`observe_legs` (same arguments, same result)."""
    _check_sampling(min_visible_fraction, n_samples)
    T = camera.camera_from_base
    legs = legs_in_frame(geometry, rotation, translation, T)
    A, u, q = legs.base_points, legs.directions, legs.lengths
    r = geometry.leg_radius
    normals, exists = leg_edges(A, u, r)
    R = np.asarray(rotation, float)
    centre = T.apply(np.asarray(translation, float))
    disc_normal = T.rotate(R[..., :, 2])
    rho = (
        float(np.max(np.linalg.norm(geometry.platform_points, axis=1)))
        if platform_radius is None
        else float(platform_radius)
    )
    s = (np.arange(n_samples) + 0.5) / n_samples
    P = limb_points(A, u, r, q, normals, s)
    _, imaged = camera.project(P)
    vis = imaged & exists[..., None, None]
    if occlusion:
        vis &= ~occluded_by_legs_compiled(P, A, u, q, r)
        vis &= ~occluded_by_disc(P, centre, disc_normal, rho)
    frac = vis.mean(axis=-1)
    edge_visible = exists[..., None] & (frac >= min_visible_fraction - 1e-12)
    with np.errstate(invalid="ignore"):
        s_first = np.where(vis.any(-1), s[np.argmax(vis, axis=-1)], np.nan)
        s_last = np.where(vis.any(-1), s[n_samples - 1 - np.argmax(vis[..., ::-1], axis=-1)],
                          np.nan)
    ends = limb_points(A, u, r, q, normals, np.array([0.0, 1.0]))
    segments, _ = camera.project(ends)
    lines = camera.normal_to_line(normals) if isinstance(camera, PerspectiveCamera) else None
    return LegObservation(
        base_points=A,
        directions=u,
        lengths=q,
        normals=normals,
        exists=exists,
        edge_visible=edge_visible,
        visible_fraction=frac,
        lines=lines,
        segments=segments,
        visible_interval=np.stack([s_first, s_last], axis=-1),
        platform_centre=centre,
        platform_normal=disc_normal,
        platform_radius=rho,
        radius=float(r),
    )


class EdgePoints(NamedTuple):
    """Pixels sampled along the edges: ``pixels`` (..., 6, 2, N, 2) and ``visible``
    (..., 6, 2, N) (imaged, inside the image, not occluded when tested)."""

    pixels: np.ndarray
    visible: np.ndarray


def edge_points(
    camera: Camera,
    base_points: np.ndarray,
    directions: np.ndarray,
    radius: float,
    lengths: np.ndarray,
    n_points: int,
    normals: np.ndarray | None = None,
    span: tuple[Any, Any] = (0.0, 1.0),
    occlusion: bool = True,
    platform: tuple[np.ndarray, np.ndarray, float] | None = None,
) -> EdgePoints:
    """Pixels of points sampled along each edge (for estimation and noise studies).

    Points are at ``s = s0 + (s1 - s0) k / (n_points - 1)``, ``k = 0..n_points-1``
    (the middle of the span when ``n_points = 1``), on the limb ``A_i + r n_ij +
    s q_i u_i``.

    Args:
        camera: The camera.
        base_points, directions, lengths: (..., 6, 3), (..., 6, 3), (..., 6), camera frame.
        radius: Leg radius [m].
        n_points: Points per edge.
        normals: (..., 6, 2, 3) edge normals; computed with :func:`leg_edges` if None.
        span: ``(s0, s1)``, fractions of the leg length, each a scalar or broadcastable
            to (..., 6, 2) (e.g. ``obs.visible_interval[..., 0]`` and ``[..., 1]``).
        occlusion: Mark points hidden by the other legs (and the platform disc, if
            ``platform`` is given) as not visible.
        platform: ``(centre (..., 3), normal (..., 3), radius)`` of the platform disc in
            the camera frame (``obs.platform_centre, obs.platform_normal,
            obs.platform_radius``).

    Returns:
        :class:`EdgePoints` ``(pixels, visible)``; pixels NaN where not imaged.
    """
    if n_points < 1:
        raise ValueError(f"n_points must be >= 1, got {n_points}")
    A = np.asarray(base_points, float)
    u = np.asarray(directions, float)
    q = np.asarray(lengths, float)
    if normals is None:
        normals, _ = leg_edges(A, u, radius)
    normals = np.asarray(normals, float)
    exists = np.all(np.isfinite(normals), axis=(-2, -1))
    s0 = np.asarray(span[0], float)[..., None]
    s1 = np.asarray(span[1], float)[..., None]
    k = np.linspace(0.0, 1.0, n_points) if n_points > 1 else np.array([0.5])
    s = s0 + (s1 - s0) * k
    P = limb_points(A, u, radius, q, normals, s)
    pix, vis = camera.project(P)
    vis = vis & exists[..., None, None] & np.isfinite(s)
    if occlusion:
        vis &= ~occluded_by_legs(P, A, u, q, radius)
        if platform is not None:
            vis &= ~occluded_by_disc(P, platform[0], platform[1], float(platform[2]))
    return EdgePoints(pix, vis)


def observation_edge_points(
    camera: Camera, obs: LegObservation, n_points: int, visible_part: bool = True
) -> EdgePoints:
    """:func:`edge_points` on an observation: ``n_points`` per edge, spread over the
    visible interval of the edge (``visible_part``) or the whole edge, with the
    occlusions of the observation (legs and platform)."""
    span: tuple[Any, Any]
    if visible_part:
        span = (obs.visible_interval[..., 0], obs.visible_interval[..., 1])
    else:
        span = (0.0, 1.0)
    return edge_points(
        camera, obs.base_points, obs.directions, obs.radius, obs.lengths, n_points,
        normals=obs.normals, span=span, occlusion=True,
        platform=(obs.platform_centre, obs.platform_normal, obs.platform_radius),
    )
