"""Workspace of the hexapod: home pose, random poses inside the strokes, extremal configurations."""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from hexapod.exceptions import WorkspaceError
from hexapod.geometry import HexapodGeometry
from hexapod.kinematics import inverse_kinematics, platform_points_in_base
from hexapod.se3 import exp_so3

#: Home heights found, keyed by all they depend on (the joint points and the stroke): a
#: study loads its robot afresh for every unit of trials, and the bisection costs about
#: 20 ms. Bounded: cleared when it holds :data:`HOME_CACHE_SIZE` robots.
_HOME_HEIGHTS: dict[tuple[bytes, bytes, tuple[float, float]], float] = {}
HOME_CACHE_SIZE = 256


def _home_key(geometry: HexapodGeometry) -> tuple[bytes, bytes, tuple[float, float]]:
    """What a home height depends on: the joint points and the stroke."""
    return (np.asarray(geometry.base_points, dtype=float).tobytes(),
            np.asarray(geometry.platform_points, dtype=float).tobytes(),
            (float(geometry.q_min), float(geometry.q_max)))


def _remember(key: tuple[bytes, bytes, tuple[float, float]], height: float) -> None:
    if len(_HOME_HEIGHTS) >= HOME_CACHE_SIZE:
        _HOME_HEIGHTS.clear()
    _HOME_HEIGHTS[key] = height


def home_height(geometry: HexapodGeometry) -> float:
    """Height [m] where the platform, parallel to the base and centred, has its mean leg
    length at the middle of the stroke (bisection, remembered per robot; use
    ``geometry.home_height``, cached on the instance)."""
    key = _home_key(geometry)
    known = _HOME_HEIGHTS.get(key)
    if known is not None:
        return known
    height = _bisect_home_height(geometry)
    _remember(key, height)
    return height


def remember_home_heights(geometries: list[HexapodGeometry]) -> None:
    """Find the home heights of many robots in one bisection (:func:`_bisect_home_heights`,
    the same numbers as :func:`home_height` robot by robot) and remember them, so that
    ``geometry.home_height`` of each is a look-up (a study's trials each have their own
    robot: about a millisecond and a half each, robot by robot)."""
    todo: dict[tuple[bytes, bytes, tuple[float, float]], list[HexapodGeometry]] = {}
    for g in geometries:
        if "home_height" in g.__dict__:  # already on the instance (its cached_property)
            continue
        key = _home_key(g)
        known = _HOME_HEIGHTS.get(key)
        if known is None:
            todo.setdefault(key, []).append(g)
        else:
            g.__dict__["home_height"] = known
    if not todo:
        return
    heights = _bisect_home_heights([same[0] for same in todo.values()])
    for (key, same), h in zip(todo.items(), heights.tolist(), strict=True):
        _remember(key, h)
        for g in same:  # on the instance too: more robots than the cache holds
            g.__dict__["home_height"] = h


def _bisect_home_height(geometry: HexapodGeometry) -> float:
    """:func:`home_height` by bisection on the mean leg length (100 halvings): the
    bisection of :func:`_bisect_home_heights` for one robot."""
    return float(_bisect_home_heights([geometry])[0])


def _bisect_home_heights(geometries: list[HexapodGeometry]) -> np.ndarray:
    """(k,) the home heights [m] of ``geometries``, bisected together (100 halvings each).
    Each halving is :func:`~hexapod.kinematics.inverse_kinematics` at the level pose, its
    operations in its order (the same numbers, elementwise over the robots) without its
    checks, the rotated platform points computed once."""
    k = len(geometries)
    lo = np.full(k, 1e-3)
    hi = np.array([4.0 * g.q_max for g in geometries], dtype=float)
    q_mid = np.array([g.q_mid for g in geometries], dtype=float)
    rotated = np.array([platform_points_in_base(g, np.eye(3), np.zeros(3))  # (+ 0: exact)
                        for g in geometries]).reshape(k, 6, 3)
    A = np.array([np.asarray(g.base_points, dtype=float) for g in geometries]).reshape(k, 6, 3)
    lift = np.zeros((k, 1, 3))
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        lift[:, 0, 2] = mid
        v = (rotated + lift) - A
        q = np.sqrt(np.add.reduce(v * v, axis=-1))  # numpy.linalg.norm's own operations
        below = q.mean(axis=-1) < q_mid
        lo = np.where(below, mid, lo)
        hi = np.where(below, hi, mid)
    return 0.5 * (lo + hi)  # type: ignore[no-any-return]


def home_pose(
    geometry: HexapodGeometry, height: float | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Home pose: platform parallel to the base, centred, at ``height`` [m].

    The default height makes the mean leg length equal to the middle of the stroke.
    """
    if height is None:
        height = geometry.home_height
    return np.eye(3), np.array([0.0, 0.0, float(height)])


def sample_poses(
    geometry: HexapodGeometry,
    n: int,
    rng: np.random.Generator | int | None = None,
    max_translation: float = 0.08,
    max_angle: float = np.deg2rad(15.0),
    margin: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Uniform random poses whose leg lengths are inside the strokes (rejection sampling).

    Positions are uniform in a box of half-width ``max_translation`` around the
    home pose, orientations uniform in a ball of rotation vectors of radius
    ``max_angle``; a pose is kept if every leg is within ``[q_min + margin,
    q_max - margin]``.

    Args:
        geometry: The robot.
        n: Number of poses.
        rng: Generator or seed.
        max_translation: Half-width of the position box [m].
        max_angle: Maximal rotation from the home orientation [rad].
        margin: Distance kept from the stroke limits [m].

    Returns:
        Rotations (n, 3, 3) and translations (n, 3) in the base frame.
    """
    rng = np.random.default_rng(rng)
    return _sample_rounds(geometry, n, rng, max_translation, max_angle, margin, [], [], 0, 0)


def _sample_rounds(geometry: HexapodGeometry, n: int, rng: np.random.Generator,
                   max_translation: float, max_angle: float, margin: float,
                   Rs: list[np.ndarray], ts: list[np.ndarray], count: int, attempts: int
                   ) -> tuple[np.ndarray, np.ndarray]:
    """The rounds of :func:`sample_poses` from a state (the poses kept so far, their
    count and the candidates drawn)."""
    _, t0 = home_pose(geometry)
    while count < n:
        m = max(2 * (n - count), 16)
        t = t0 + rng.uniform(-max_translation, max_translation, size=(m, 3))
        d = rng.normal(size=(m, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        ang = max_angle * rng.uniform(0, 1, size=m) ** (1 / 3)
        R = exp_so3(d * ang[:, None])
        q = inverse_kinematics(geometry, R, t)
        ok = np.all((q >= geometry.q_min + margin) & (q <= geometry.q_max - margin), axis=1)
        Rs.append(R[ok])
        ts.append(t[ok])
        count += int(ok.sum())
        attempts += m
        if attempts > 1000 * max(n, 1):
            raise WorkspaceError(geometry.name, count, attempts, max_translation, max_angle,
                                 margin)
    return np.concatenate(Rs)[:n], np.concatenate(ts)[:n]


def sample_poses_many(
    geometries: list[HexapodGeometry],
    n: int,
    rngs: list[np.random.Generator],
    max_translation: float = 0.08,
    max_angle: float = np.deg2rad(15.0),
    margin: float = 0.0,
) -> list[tuple[np.ndarray, np.ndarray] | WorkspaceError]:
    """:func:`sample_poses` for many generators at once, each with its robot.

    The same poses, to the last bit, as ``sample_poses(geometries[k], n, rngs[k], ...)``
    for each ``k`` in turn: each generator makes the same draws in the same order; the
    first round of candidates of every generator is evaluated in one batch (the
    arithmetic is elementwise), and a generator whose first round keeps fewer than
    ``n`` poses goes on alone.

    Args:
        geometries: One robot per generator.
        n: Poses per generator.
        rngs: The generators (advanced as by :func:`sample_poses`).
        max_translation, max_angle, margin: As :func:`sample_poses`.

    Returns:
        Per generator, ``(rotations (n, 3, 3), translations (n, 3))``, or the
        :class:`~hexapod.exceptions.WorkspaceError` that :func:`sample_poses` raises.
    """
    k = len(rngs)
    if len(geometries) != k:
        raise ValueError(f"{len(geometries)} geometries for {k} generators")
    m = max(2 * n, 16)
    t = np.empty((k, m, 3))
    d = np.empty((k, m, 3))
    u = np.empty((k, m))
    homes: dict[int, np.ndarray] = {}
    remember_home_heights(geometries)  # one bisection for every robot
    for j, (g, rng) in enumerate(zip(geometries, rngs, strict=True)):
        t0 = homes.get(id(g))
        if t0 is None:
            t0 = homes[id(g)] = home_pose(g)[1]
        t[j] = t0 + rng.uniform(-max_translation, max_translation, size=(m, 3))
        d[j] = rng.normal(size=(m, 3))
        u[j] = rng.uniform(0, 1, size=m)
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    R = exp_so3(d * (max_angle * u ** (1 / 3))[..., None])
    ok = np.empty((k, m), dtype=bool)
    groups: dict[int, list[int]] = {}
    for j, g in enumerate(geometries):
        groups.setdefault(id(g), []).append(j)
    for idx in groups.values():
        g = geometries[idx[0]]
        q = inverse_kinematics(g, R[idx], t[idx])
        ok[idx] = np.all((q >= g.q_min + margin) & (q <= g.q_max - margin), axis=-1)
    out: list[tuple[np.ndarray, np.ndarray] | WorkspaceError] = []
    counts = ok.sum(axis=1)
    for j in range(k):
        if n <= 0:
            out.append((np.empty((0, 3, 3)), np.empty((0, 3))))
            continue
        kept = np.flatnonzero(ok[j])
        if counts[j] >= n:  # the first round sufficed
            out.append((R[j, kept[:n]], t[j, kept[:n]]))
            continue
        try:
            out.append(_sample_rounds(geometries[j], n, rngs[j], max_translation, max_angle,
                                      margin, [R[j, kept]], [t[j, kept]], int(counts[j]), m))
        except WorkspaceError as exc:
            out.append(exc)
    return out


@dataclass(frozen=True)
class ExtremalConfigurations:
    """The 64 configurations where every leg is at one of its stroke limits.

    Attributes:
        lengths: (64, 6) leg lengths [m].
        reachable: (64,) whether forward kinematics found a pose.
        rotations: (64, 3, 3) poses (NaN where unreachable).
        translations: (64, 3) [m] (NaN where unreachable).
    """

    lengths: np.ndarray
    reachable: np.ndarray
    rotations: np.ndarray
    translations: np.ndarray

    @property
    def unreachable_indices(self) -> list[int]:
        """Indices of the configurations without a pose."""
        return [int(i) for i in np.flatnonzero(~self.reachable)]


def extremal_configurations(
    geometry: HexapodGeometry, margin: float = 0.0
) -> ExtremalConfigurations:
    """Every leg at one of its stroke limits (64 combinations), with their poses.

    The pose of each is found by forward kinematics from the home pose, through
    a continuation path (lengths moved from mid-stroke in small steps) so that the
    solution stays on the assembly mode of the home pose.

    Args:
        geometry: The robot.
        margin: Distance from each limit [m] (e.g. to stay off the hard stops).
    """
    from hexapod.fk import forward_kinematics_batch

    lo, hi = geometry.q_min + margin, geometry.q_max - margin
    combos = np.array(list(itertools.product([0, 1], repeat=6)), dtype=float)
    lengths = lo + combos * (hi - lo)
    R0, t0 = home_pose(geometry)
    q0 = inverse_kinematics(geometry, R0, t0)
    n = len(lengths)
    R = np.broadcast_to(R0, (n, 3, 3)).copy()
    t = np.broadcast_to(t0, (n, 3)).copy()
    ok = np.ones(n, dtype=bool)
    for s in np.linspace(0.1, 1.0, 10):
        target = q0 + s * (lengths - q0)
        sol = forward_kinematics_batch(geometry, target, R, t)
        ok &= sol.converged
        R = np.where(sol.converged[:, None, None], sol.rotations, R)
        t = np.where(sol.converged[:, None], sol.translations, t)
    R[~ok] = np.nan
    t[~ok] = np.nan
    return ExtremalConfigurations(lengths, ok, R, t)
