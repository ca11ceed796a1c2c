"""Every interaction matrix against finite differences of the true kinematics and cameras.

The platform is moved by a small twist (camera frame) with the SE(3)
exponential, the features are recomputed from the true pose
(``legs_in_frame`` + ``vision.legs.leg_edges`` + ``camera.normal_to_line``), and
the central difference quotient is compared with the analytic matrix. At the
``other_geometry`` robot (not the reference one), for both camera models.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from hexapod.kinematics import inverse_jacobian
from tests.controllers.controller_world import World, make_camera
from tests.controllers.interaction_oracle import (
    direction_interaction,
    direction_task,
    edge_interaction,
    edge_line_task,
    edge_normal_task,
    edge_rank_one,
    line_jacobian,
)
from vision.legs import leg_edges

H_STEP = 1e-6
N_POSES = 3


@pytest.fixture(params=["perspective", "unified"])
def world(request: pytest.FixtureRequest, other_geometry) -> World:  # type: ignore[no-untyped-def]
    return World(other_geometry, make_camera(request.param, other_geometry))


def numeric_jacobian(world: World, R: np.ndarray, t: np.ndarray,
                     feature: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> np.ndarray:
    """d feature / d tau (..., 6) by central differences of the true motion."""
    cols = []
    for j in range(6):
        tau = np.zeros(6)
        tau[j] = 1.0
        Rp, tp = world.move(R, t, tau, H_STEP)
        Rm, tm = world.move(R, t, -tau, H_STEP)
        cols.append((feature(Rp, tp) - feature(Rm, tm)) / (2 * H_STEP))
    return np.stack(cols, axis=-1)


def poses(world: World, rng: np.random.Generator) -> list[tuple[np.ndarray, np.ndarray]]:
    Rs, ts = world.poses(N_POSES, rng, max_translation=0.06, max_angle=np.deg2rad(12))
    return list(zip(Rs, ts, strict=True))


def close(analytic: np.ndarray, numeric: np.ndarray, rtol: float = 1e-6) -> None:
    scale = max(float(np.abs(numeric).max()), 1e-3)
    np.testing.assert_allclose(analytic, numeric, rtol=0, atol=rtol * scale)


def test_inverse_jacobian(world: World, rng: np.random.Generator) -> None:
    for R, t in poses(world, rng):
        legs = world.legs(R, t)
        num = numeric_jacobian(world, R, t, lambda R, t: world.legs(R, t).lengths)
        close(inverse_jacobian(legs.base_points, legs.directions), num)


def test_direction_interaction(world: World, rng: np.random.Generator) -> None:
    for R, t in poses(world, rng):
        legs = world.legs(R, t)
        num = numeric_jacobian(world, R, t, lambda R, t: world.legs(R, t).directions)
        close(direction_interaction(legs.base_points, legs.directions, legs.lengths), num)


def test_edge_interaction_h_alone(world: World, rng: np.random.Generator) -> None:
    """n_dot = H u_dot with A fixed, u moving on the sphere in a random tangent direction."""
    r = world.geometry.leg_radius
    for R, t in poses(world, rng):
        legs = world.legs(R, t)
        A, u = legs.base_points, legs.directions
        d = rng.normal(size=(6, 3))
        d -= np.sum(d * u, axis=1, keepdims=True) * u  # tangent

        def normals_at(s: float, A: np.ndarray = A, u: np.ndarray = u,
                       d: np.ndarray = d) -> np.ndarray:
            us = u + s * d
            us /= np.linalg.norm(us, axis=1, keepdims=True)
            return leg_edges(A, us, r)[0]

        num = (normals_at(H_STEP) - normals_at(-H_STEP)) / (2 * H_STEP)
        n = leg_edges(A, u, r)[0]
        H = edge_interaction(n, u[:, None, :], A[:, None, :])
        close(np.einsum("ijab,ib->ija", H, d), num)


def test_edge_interaction_hm(world: World, rng: np.random.Generator) -> None:
    """n_dot = H M_i tau, explicit product and rank-one factors."""
    r = world.geometry.leg_radius
    for R, t in poses(world, rng):
        legs = world.legs(R, t)
        A, u, q = legs.base_points, legs.directions, legs.lengths
        n = leg_edges(A, u, r)[0]
        num = numeric_jacobian(world, R, t, lambda R, t: world.features(R, t)["normals"])
        M = direction_interaction(A, u, q)
        HM = edge_interaction(n, u[:, None, :], A[:, None, :]) @ M[:, None]
        close(HM, num)
        z, g = edge_rank_one(n, u[:, None, :], A[:, None, :], q[:, None])
        close(-z[..., :, None] * g[..., None, :], num)


@pytest.fixture
def perspective_world(other_geometry) -> World:  # type: ignore[no-untyped-def]
    return World(other_geometry, make_camera("perspective", other_geometry))


def test_line_jacobian_alone(perspective_world: World, rng: np.random.Generator) -> None:
    """l_dot = J_l n_dot with l = camera.normal_to_line(n), n moving on the sphere."""
    world = perspective_world
    cam = world.camera
    for R, t in poses(world, rng):
        n = world.features(R, t)["normals"]
        d = rng.normal(size=n.shape)
        d -= np.sum(d * n, axis=-1, keepdims=True) * n

        def lines_at(s: float, n: np.ndarray = n, d: np.ndarray = d) -> np.ndarray:
            ns = n + s * d
            ns /= np.linalg.norm(ns, axis=-1, keepdims=True)
            return cam.normal_to_line(ns)  # type: ignore[attr-defined,no-any-return]

        num = (lines_at(H_STEP) - lines_at(-H_STEP)) / (2 * H_STEP)
        J = line_jacobian(cam.normal_to_line(n), cam.line_matrix)  # type: ignore[attr-defined]
        close(np.einsum("...ab,...b->...a", J, d), num)


def test_line_jacobian_hm(perspective_world: World, rng: np.random.Generator) -> None:
    """l_dot = J_l H M_i tau against the motion of the true image lines."""
    world = perspective_world
    cam = world.camera
    for R, t in poses(world, rng):
        f = world.features(R, t)
        A, u, q, n, l = (f[k] for k in ("base_points", "directions", "lengths", "normals",
                                        "lines"))
        num = numeric_jacobian(world, R, t, lambda R, t: world.features(R, t)["lines"])
        HM = edge_interaction(n, u[:, None, :], A[:, None, :]) @ direction_interaction(A, u, q
                                                                                       )[:, None]
        close(line_jacobian(l, cam.line_matrix) @ HM, num)  # type: ignore[attr-defined]


def test_edge_line_task(perspective_world: World, rng: np.random.Generator) -> None:
    """e = l x l*: de/dt = -[l*]_x J_l H M tau (seed 002 features)."""
    world = perspective_world
    cam = world.camera
    (Rg, tg), *_ = poses(world, rng)
    l_star = world.features(Rg, tg)["lines"]
    for R, t in poses(world, rng):
        f = world.features(R, t)
        A, u, q, n, l = (f[k] for k in ("base_points", "directions", "lengths", "normals",
                                        "lines"))
        num = numeric_jacobian(world, R, t,
                               lambda R, t: np.cross(world.features(R, t)["lines"], l_star))
        L = edge_line_task(l.reshape(12, 3), l_star.reshape(12, 3), n.reshape(12, 3),
                           np.repeat(u, 2, axis=0), np.repeat(A, 2, axis=0), np.repeat(q, 2),
                           cam.line_matrix)  # type: ignore[attr-defined]
        close(L.reshape(6, 2, 3, 6), num)


def test_edge_normal_task(world: World, rng: np.random.Generator) -> None:
    """e = n x n*: de/dt = -[n*]_x H M tau (unified-camera features; also valid in perspective)."""
    (R, t), (Rg, tg), *_ = poses(world, rng)
    n_star = world.features(Rg, tg)["normals"]
    for R, t in poses(world, rng):
        f = world.features(R, t)
        A, u, q, n = f["base_points"], f["directions"], f["lengths"], f["normals"]
        num = numeric_jacobian(world, R, t,
                               lambda R, t: np.cross(world.features(R, t)["normals"], n_star))
        L = edge_normal_task(n.reshape(12, 3), n_star.reshape(12, 3), np.repeat(u, 2, axis=0),
                             np.repeat(A, 2, axis=0), np.repeat(q, 2))
        close(L.reshape(6, 2, 3, 6), num)


def test_direction_task(world: World, rng: np.random.Generator) -> None:
    (Rg, tg), *_ = poses(world, rng)
    u_star = world.features(Rg, tg)["directions"]
    for R, t in poses(world, rng):
        f = world.features(R, t)
        num = numeric_jacobian(world, R, t,
                               lambda R, t: np.cross(world.legs(R, t).directions, u_star))
        e, L = direction_task(f["directions"], u_star, f["base_points"], f["lengths"])
        close(L, num)
        np.testing.assert_allclose(e, np.cross(f["directions"], u_star), atol=1e-15)
