"""Visual predictive control: prediction models, problem, controllers (controllers/mpc).

The prediction models are checked against the TRUE kinematics and camera of the
test world (:mod:`tests.controllers.controller_world`: ``legs_in_frame``,
``vision.legs.leg_edges``, ``camera.normal_to_line``, motion by the SE(3)
exponential), never against a second copy of their formulas.
"""

from __future__ import annotations

import numpy as np
import pytest

from controllers.interaction import cross, direction_task, edge_line_task, edge_normal_task
from controllers.mpc.prediction import GlobalModel, LocalModel, fit_pose
from hexapod.kinematics import inverse_jacobian
from tests.controllers.controller_world import World, make_camera

DT = 0.02
#: Global model vs the true world, zero calibration error: features (unit vectors) and
#: lengths [m] after up to 10 periods. Both integrate the twist with the exact SE(3)
#: exponential, so only rounding separates them (measured: below 1e-15).
GLOBAL_TOL = 1e-12

KINDS = [("perspective", "lines"), ("unified", "normals"), ("unified", "directions")]


@pytest.fixture(params=["perspective", "unified"])
def camera_kind(request: pytest.FixtureRequest) -> str:
    return str(request.param)


def _world(kind: str, geometry) -> World:  # type: ignore[no-untyped-def]
    return World(geometry, make_camera(kind, geometry))


def _true_features(world: World, R: np.ndarray, t: np.ndarray, kind: str) -> np.ndarray:
    f = world.features(R, t)
    if kind == "directions":
        return f["directions"]
    return (f["lines"] if kind == "lines" else f["normals"]).reshape(12, 3)


def _twists(rng: np.random.Generator, n: int, scale: float = 1.0) -> np.ndarray:
    """Random twists: up to ~20 mm/s and ~6 deg/s, camera frame."""
    return scale * rng.normal(size=(n, 6)) * np.array([0.02, 0.02, 0.02, 0.1, 0.1, 0.1])


def _global_model(world: World, kind: str, R: np.ndarray, t: np.ndarray
                  ) -> tuple[GlobalModel, np.ndarray, np.ndarray]:
    f = world.features(R, t)
    cam = world.camera
    model = GlobalModel(kind, world.context(world.goal(R, t), DT).base_points,
                        world.geometry.platform_points, world.geometry.leg_radius,
                        getattr(cam, "line_matrix", None))
    Rc, tc = model.fit(f["lengths"], f["directions"])
    return model, Rc, tc


# ----------------------------------------------------------------------------- models
def test_pose_fit_recovers_a_rigid_motion(rng: np.random.Generator) -> None:
    m = rng.normal(size=(6, 3))
    R, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    R *= np.sign(np.linalg.det(R))
    t = rng.normal(size=3)
    Rf, tf = fit_pose(m @ R.T + t, m)
    np.testing.assert_allclose(Rf, R, atol=1e-12)
    np.testing.assert_allclose(tf, t, atol=1e-12)
    w = np.array([1.0, 1.0, 1.0, 0.0, 0.0, 1.0])  # zero weight: the point is ignored
    p = m @ R.T + t
    p[3] += 5.0
    Rf, tf = fit_pose(p, m, w)
    np.testing.assert_allclose(Rf, R, atol=1e-12)


@pytest.mark.parametrize(("camera", "kind"), KINDS)
def test_global_model_equals_the_true_world(camera: str, kind: str, other_geometry,  # type: ignore[no-untyped-def]
                                            rng: np.random.Generator) -> None:
    world = _world(camera, other_geometry)
    Rs, ts = world.poses(3, rng)
    for R, t in zip(Rs, ts, strict=True):
        model, Rc, tc = _global_model(world, kind, R, t)
        taus = _twists(rng, 10)
        feats, lens = model.rollout(Rc, tc, taus, DT)
        Rk, tk = R, t
        for k in range(11):
            np.testing.assert_allclose(feats[k], _true_features(world, Rk, tk, kind),
                                       atol=GLOBAL_TOL, rtol=0, err_msg=f"period {k}")
            np.testing.assert_allclose(lens[k], world.legs(Rk, tk).lengths, atol=GLOBAL_TOL,
                                       rtol=0)
            if k < 10:
                Rk, tk = world.move(Rk, tk, taus[k], DT)
        # ... and the motion was not negligible: the features moved far beyond the tolerance.
        assert np.abs(feats[10] - feats[0]).max() > 1e-3


def test_global_model_sees_a_wrong_twist(other_geometry, rng: np.random.Generator) -> None:  # type: ignore[no-untyped-def]
    """The comparison above can fail: a twist off by 1 % moves the prediction visibly."""
    world = _world("perspective", other_geometry)
    Rs, ts = world.poses(1, rng)
    model, Rc, tc = _global_model(world, "lines", Rs[0], ts[0])
    taus = _twists(rng, 5)
    feats, _ = model.rollout(Rc, tc, 1.01 * taus, DT)
    Rk, tk = Rs[0], ts[0]
    for k in range(5):
        Rk, tk = world.move(Rk, tk, taus[k], DT)
    assert np.abs(feats[5] - _true_features(world, Rk, tk, "lines")).max() > 1e3 * GLOBAL_TOL


def _local_model(world: World, kind: str, R: np.ndarray, t: np.ndarray
                 ) -> tuple[LocalModel, np.ndarray, np.ndarray, np.ndarray]:
    """The local model at (R, t) towards a goal, from the interaction matrices of
    controllers.interaction (the classical laws' L)."""
    f = world.features(R, t)
    A, u, q = f["base_points"], f["directions"], f["lengths"]
    Rg, tg = world.poses(1, np.random.default_rng(5))
    star = _true_features(world, Rg[0], tg[0], kind)
    s = _true_features(world, R, t, kind)
    if kind == "directions":
        _, L = direction_task(u, star, A, q, error=False)
    else:
        n = f["normals"].reshape(12, 3)
        u2, A2, q2 = np.repeat(u, 2, axis=0), np.repeat(A, 2, axis=0), np.repeat(q, 2)
        if kind == "lines":
            K = world.camera.line_matrix  # type: ignore[attr-defined]
            L = edge_line_task(s, star, n, u2, A2, q2, K)
        else:
            L = edge_normal_task(n, star, u2, A2, q2)
    model = LocalModel(L.reshape(-1, 6), inverse_jacobian(A, u))
    return model, cross(s, star).reshape(-1), q, star


@pytest.mark.parametrize(("camera", "kind"), KINDS)
def test_local_model_error_grows_with_the_horizon(camera: str, kind: str, other_geometry,  # type: ignore[no-untyped-def]
                                                  rng: np.random.Generator) -> None:
    """First order in the displacement: the prediction error grows with k (about as k^2
    under a constant twist) and falls as the square of the twist."""
    world = _world(camera, other_geometry)
    Rs, ts = world.poses(3, rng)
    for R, t in zip(Rs, ts, strict=True):
        model, e0, q0, star = _local_model(world, kind, R, t)
        tau = _twists(rng, 1)[0]
        errs = {}
        for scale in (1.0, 0.5):
            taus = np.tile(scale * tau, (10, 1))
            e_pred, q_pred = model.rollout(e0, q0, taus, DT)
            Rk, tk = R, t
            err, qerr = [], []
            for k in range(11):
                e_true = cross(_true_features(world, Rk, tk, kind), star).reshape(-1)
                err.append(np.abs(e_pred[k] - e_true).max())
                qerr.append(np.abs(q_pred[k] - world.legs(Rk, tk).lengths).max())
                if k < 10:
                    Rk, tk = world.move(Rk, tk, taus[k], DT)
            errs[scale] = np.array(err)
            assert qerr[0] < 1e-15 and qerr[10] > 10 * qerr[1] > 0, qerr
        err = errs[1.0]
        assert err[0] < 1e-15
        assert np.all(np.diff(err[1:]) > 0), err  # grows with k
        assert 30 < err[10] / err[1] < 200, err  # ~ k^2 = 100
        ratio = errs[0.5][1:] / err[1:]  # second order in the displacement
        np.testing.assert_allclose(ratio, 0.25, atol=0.03)
