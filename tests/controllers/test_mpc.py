"""Visual predictive control: prediction models, problem, controllers (controllers/mpc).

The prediction models are checked against the TRUE kinematics and camera of the
test world (:mod:`tests.controllers.controller_world`: ``legs_in_frame``,
``vision.legs.leg_edges``, ``camera.normal_to_line``, motion by the SE(3)
exponential), never against a second copy of their formulas.
"""

from __future__ import annotations

from collections.abc import Callable

import casadi as ca
import numpy as np
import pytest

from controllers.mpc.prediction import FEATURE_KINDS, fit_pose, sx_exp_se3, sx_legs
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
                  ) -> tuple[Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
                             np.ndarray, np.ndarray]:
    """The global model's prediction from the pose fitted to the legs seen at (R, t): a
    function of the twists (k, 6) giving the features (k + 1, nf, 3) and lengths
    (k + 1, 6) after each period (index 0: the fitted pose), chained from the SX blocks
    of :mod:`controllers.mpc.prediction` as the problem kernel chains them."""
    f = world.features(R, t)
    feature = {f.kind: f for f in FEATURE_KINDS}[kind]
    A = world.context(world.goal(R, t), DT).base_points
    E, r = world.geometry.platform_points, world.geometry.leg_radius
    Rc, tc = fit_pose(A + f["lengths"][:, None] * f["directions"], E)
    Kit = feature.line_inv_t(getattr(world.camera, "line_matrix", None))

    def rollout(taus: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        Rk, tk = ca.SX.sym("R", 3, 3), ca.SX.sym("t", 3)
        x = [Rk, tk]
        feats, lens = [], []
        for k in range(len(taus) + 1):
            q, u, _ = sx_legs(Rk, tk, [ca.DM(a) for a in A], [ca.DM(e) for e in E])
            feats.append(ca.vertcat(*feature.sx_of_legs(u, [ca.DM(a) for a in A], r,
                                                        ca.DM(Kit))))
            lens.append(ca.vertcat(*q))
            if k < len(taus):
                dR, dp = sx_exp_se3(DT * ca.DM(taus[k, :3]), DT * ca.DM(taus[k, 3:]))
                Rk, tk = dR @ Rk, dR @ tk + dp
        out = ca.Function("rollout", x, [ca.horzcat(*feats), ca.horzcat(*lens)])(Rc, tc)
        return (np.asarray(out[0]).T.reshape(len(taus) + 1, -1, 3),
                np.asarray(out[1]).T.reshape(len(taus) + 1, 6))

    return rollout, Rc, tc


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
        rollout, _, _ = _global_model(world, kind, R, t)
        taus = _twists(rng, 10)
        feats, lens = rollout(taus)
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
    rollout, _, _ = _global_model(world, "lines", Rs[0], ts[0])
    taus = _twists(rng, 5)
    feats, _ = rollout(1.01 * taus)
    Rk, tk = Rs[0], ts[0]
    for k in range(5):
        Rk, tk = world.move(Rk, tk, taus[k], DT)
    assert np.abs(feats[5] - _true_features(world, Rk, tk, "lines")).max() > 1e3 * GLOBAL_TOL


# ----------------------------------------------------------------------------- controllers
def _pose(rotvec: list[float], t: list[float]) -> tuple[np.ndarray, np.ndarray]:
    from hexapod.se3 import exp_so3

    return exp_so3(np.array(rotvec)), np.array(t)


def _mpc(name: str, world: World, goal: tuple[np.ndarray, np.ndarray], **options):  # type: ignore[no-untyped-def]
    from controllers import registry

    ctrl = registry.create(name, **options)
    ctrl.reset(world.context(world.goal(*goal), DT))
    return ctrl


def _classical(world: World, goal: tuple[np.ndarray, np.ndarray], kind: str, gain: float):  # type: ignore[no-untyped-def]
    from controllers import registry

    name = "leg-direction" if kind == "directions" else "leg-edge"
    opts = {} if kind == "directions" else {"edge_feature": "normals" if kind == "normals"
                                             else "auto"}
    ctrl = registry.create(name, gain=gain, **opts)
    ctrl.reset(world.context(world.goal(*goal), DT))
    return ctrl


MPC_KINDS = [("perspective", "lines", "leg-edge-mpc"), ("unified", "normals", "leg-edge-mpc"),
             ("unified", "directions", "leg-direction-mpc")]


@pytest.mark.parametrize(("camera", "kind", "name"), MPC_KINDS)
def test_unconstrained_mpc_step_equals_the_classical_law(camera: str, kind: str, name: str,  # type: ignore[no-untyped-def]
                                                         other_geometry) -> None:
    """No active constraint: the local model's first move is the classical ``-lambda L^+ e``
    for horizon 1 (and, with the exponential reference, for any horizon); the global
    model's first Gauss-Newton iterate is the same step (its Jacobian is ``L`` in a
    perfect world), and its converged solution differs only at second order."""
    world = _world(camera, other_geometry)
    Rs, ts = world.poses(2, np.random.default_rng(3), max_translation=0.01,
                         max_angle=np.deg2rad(1.0), margin=0.02)
    start, goal = (Rs[0], ts[0]), (Rs[1], ts[1])
    obs = world.observation(*start)
    ref = _classical(world, goal, kind, 1.0).step(obs)
    scale = np.abs(ref.twist).max()
    # The virtual machine (compiled=False): twelve problem structures, nothing to build.
    common = {"gain": 1.0, "effort_weight": 0.0, "regularization": 1e-16, "compiled": False}
    for options in ({"horizon": 1}, {"horizon": 10},
                    {"horizon": 1, "model": "global", "tolerance": 1e9},
                    {"horizon": 1, "model": "global"}):
        ctrl = _mpc(name, world, goal, **common, **options)
        cmd = ctrl.step(obs)
        assert cmd.ok and not cmd.active_constraints, (options, cmd.notes)
        assert ctrl.stats.fallbacks == 0
        err = np.abs(cmd.twist - ref.twist).max() / scale
        converged_global = options.get("model") == "global" and "tolerance" not in options
        assert err < (2e-2 if converged_global else 1e-8), (options, err)
        if converged_global:
            assert err > 1e-8  # it is a different (nonlinear) solution
        np.testing.assert_allclose(cmd.error, ref.error, atol=1e-15)


def test_qp_data_match_finite_differences(other_geometry) -> None:  # type: ignore[no-untyped-def]
    """The condensed QP (global model, tilt and visibility rows) is the Gauss-Newton model
    of the cost and the linearisation of the constraints: ``2 g`` is the gradient of the
    cost and ``C`` the Jacobian of the constraint values (stage rows), by central
    differences at a random ``U``; the SQP's merit has the slope ``g^T d`` (with an effort
    weight and a regularization large enough to count: a regularization in the QP but not
    in the cost gave a slope 3 % off at 1e-2)."""
    world = _world("perspective", other_geometry)
    Rs, ts = world.poses(2, np.random.default_rng(4), margin=0.02)
    ctrl = _mpc("leg-edge-mpc", world, (Rs[1], ts[1]), model="global", horizon=4,
                visibility=True, max_tilt_deg=10.0, max_iter=1, accept_unconverged=True,
                compiled=False, regularization=1e-3, effort_weight=1e-2)
    ctrl.step(world.observation(Rs[0], ts[0]))
    spec = ctrl._spec
    o = ctrl._out.slices
    sl = ctrl._lay.slices["U"]
    vec = ctrl._vec.copy()
    U = _twists(np.random.default_rng(8), 4).reshape(-1)
    vec[sl] = U

    def kernel(u: np.ndarray) -> np.ndarray:
        v = vec.copy()
        v[sl] = u
        return ctrl._kernel.single(v)

    out = kernel(U)
    n, m = 24, spec.rows
    g, C, vals = out[o["g"]], out[o["C"]].reshape(m, n), out[o["values"]]
    stage = spec.horizon * spec.stage_rows
    h = 1e-6
    for j in range(n):
        du = np.zeros(n)
        du[j] = h
        op, om = kernel(U + du), kernel(U - du)
        grad = (op[o["cost"]][0] - om[o["cost"]][0]) / (2 * h)
        assert abs(grad - 2 * g[j]) <= 1e-6 * max(1.0, abs(grad)), (j, grad, 2 * g[j])
        col = (op[o["values"]] - om[o["values"]]) / (2 * h)
        np.testing.assert_allclose(C[:stage, j], col[:stage], rtol=1e-5,
                                   atol=1e-6 * (1 + np.abs(col[:stage]).max()))
    assert np.all(np.isfinite(vals))
    # the line search's merit (without its penalty) has the QP's slope along a step: the
    # SQP's Armijo test and penalty are in the QP's scale (the merit was the cost, twice
    # that scale: its slope was taken for g^T d, its penalty half what makes it exact)
    from controllers.mpc.solver import merit

    d = np.random.default_rng(9).normal(size=n)
    slope = (merit(kernel(U + h * d), o, 0.0)[0] - merit(kernel(U - h * d), o, 0.0)[0]) / (2 * h)
    assert abs(slope - g @ d) <= 1e-6 * max(1.0, abs(slope)), (slope, g @ d)


@pytest.mark.slow
def test_closed_loop_keeps_the_strokes(geometry) -> None:  # type: ignore[no-untyped-def]
    """A large motion (omni camera, reference robot) during which the classical edge law
    leaves the stroke (by about 10 mm); both predictive models keep every leg inside."""
    world = _world("unified", geometry)
    start = _pose([-0.032641, 0.008591, 0.205547], [0.018641, 0.149962, 0.334149])
    goal = _pose([-0.032927, -0.108506, -0.068374], [0.010904, -0.073369, 0.367773])
    q_min, q_max = geometry.stroke
    law = _classical(world, goal, "normals", 1.0)
    law.gain = type(law.gain)(5.0, 1.0, 30.0)
    from tests.controllers.controller_world import closed_loop

    run = closed_loop(world, law, start, goal, DT, 120)
    assert run.lengths.max() > q_max + 5e-3 or run.lengths.min() < q_min - 5e-3
    for model in ("local", "global"):
        ctrl = _mpc("leg-edge-mpc", world, goal, adaptive_gain=[5.0, 1.0, 30.0], model=model)
        run = closed_loop(world, ctrl, start, goal, DT, 120)
        assert run.lengths.max() <= q_max and run.lengths.min() >= q_min, model
        assert run.position_errors[-1] < 0.2 * run.position_errors[0], model


def _edge_end_pixels(world: World, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    from vision.legs import limb_points

    legs = world.legs(R, t)
    normals = world.features(R, t)["normals"]
    ends = limb_points(legs.base_points, legs.directions, world.geometry.leg_radius,
                       legs.lengths, normals, np.array([0.0, 1.0]))
    pix, _ = world.camera.project(ends)
    return pix


def _outside_by(world: World, pix: np.ndarray) -> float:
    """How far [px] the farthest edge end is outside the image (negative: inside)."""
    w, h = world.camera.width, world.camera.height
    return float(max((-0.5 - pix[..., 0]).max(), (pix[..., 0] - (w - 0.5)).max(),
                     (-0.5 - pix[..., 1]).max(), (pix[..., 1] - (h - 0.5)).max()))


@pytest.mark.slow
def test_visibility_constraint_keeps_the_edges_in_the_image(geometry) -> None:  # type: ignore[no-untyped-def]
    """Front camera with its principal point raised by 140 px (the platform ends of the legs
    near the top border): the classical edge law takes an edge out of the image on this
    pair; with the visibility constraint (5 px) every predicted edge stays inside."""
    from tests.controllers.controller_world import closed_loop

    cam = make_camera("perspective", geometry)
    K = np.array(cam.K)
    K[1, 2] -= 140.0
    world = World(geometry, cam.replace(K=K))
    start = _pose([-0.005459649, 0.020545822, 0.275008258], [0.028631272, 0.065541538, 0.34616185])
    goal = _pose([0.194095963, 0.008621488, -0.04159774], [0.006205513, -0.087198891, 0.354949135])
    assert _outside_by(world, _edge_end_pixels(world, *start)) < -6
    assert _outside_by(world, _edge_end_pixels(world, *goal)) < -6
    run = closed_loop(world, _classical(world, goal, "lines", 2.0), start, goal, DT, 150)
    assert max(_outside_by(world, _edge_end_pixels(world, R, t)) for R, t in run.poses) > 0
    for model in ("local", "global"):
        ctrl = _mpc("leg-edge-mpc", world, goal, gain=2.0, model=model, visibility=True,
                    visibility_margin=5.0)
        run = closed_loop(world, ctrl, start, goal, DT, 150)
        worst = max(_outside_by(world, _edge_end_pixels(world, R, t)) for R, t in run.poses)
        # The local model's constraint is linearised: allow it a pixel of slack.
        assert worst <= -5.0 + (1.0 if model == "local" else 1e-6), (model, worst)
        assert run.position_errors[-1] < 0.1 * run.position_errors[0], model


@pytest.mark.parametrize("name", ["leg-edge-mpc", "leg-direction-mpc"])
def test_failed_solve_falls_back_with_the_reason(name: str, other_geometry) -> None:  # type: ignore[no-untyped-def]
    from controllers import registry

    world = _world("unified", other_geometry)
    Rs, ts = world.poses(2, np.random.default_rng(6), margin=0.02)
    obs = world.observation(Rs[0], ts[0])
    ctrl = _mpc(name, world, (Rs[1], ts[1]), max_iter=0)
    cmd = ctrl.step(obs)
    assert cmd.ok
    assert any("mpc fallback: iteration limit 0" in n for n in cmd.notes), cmd.notes
    assert any("mpc fallback" in a for a in cmd.active_constraints)
    assert ctrl.stats.fallbacks == 1
    qp = registry.create(name.replace("-mpc", "-qp"))
    qp.reset(world.context(world.goal(Rs[1], ts[1]), DT))
    np.testing.assert_allclose(cmd.velocities, qp.step(obs).velocities, rtol=1e-12, atol=1e-15)
    slow = _mpc(name, world, (Rs[1], ts[1]), model="global", time_limit=1e-9, compiled=False)
    cmd = slow.step(obs)
    assert any("time limit" in n for n in cmd.notes), cmd.notes


@pytest.mark.parametrize("name", ["leg-edge-mpc", "leg-direction-mpc"])
@pytest.mark.parametrize("model", ["local", "global"])
def test_features_of_rank_below_six_are_refused_as_the_law_refuses_them(  # type: ignore[no-untyped-def]
        name: str, model: str, other_geometry) -> None:
    """One leg seen (rank 2), two (rank 4) or none (a lost frame): the one-step law
    refuses; the predictive controller moved at 9 mm/s along what it saw, and with no
    feature answered a zero command that was no refusal (a trial that lost its camera
    never counted as refused): it refuses as its law does now."""
    from dataclasses import replace

    world = _world("unified", other_geometry)
    Rs, ts = world.poses(2, np.random.default_rng(6), margin=0.02)
    field, mask = ("normals", "edge_visible") if name == "leg-edge-mpc" else (
        "directions", "direction_visible")
    for seen in ([5], [4, 5], []):
        ctrl = _mpc(name, world, (Rs[1], ts[1]), model=model)
        obs = world.observation(Rs[0], ts[0])
        assert ctrl.step(obs).ok
        hidden = [i for i in range(6) if i not in seen]
        values, visible = np.array(getattr(obs, field)), np.array(getattr(obs, mask))
        values[hidden], visible[hidden] = np.nan, False
        cmd = ctrl.step(replace(obs, **{field: values, mask: visible}))
        assert not cmd.ok and np.array_equal(cmd.velocities, np.zeros(6))
        assert cmd.reason is not None and "rank" in cmd.reason and "< 6" in cmd.reason
        assert any("mpc fallback: interaction matrix rank" in n for n in cmd.notes)


@pytest.mark.parametrize("name", ["leg-edge-mpc", "leg-direction-mpc"])
def test_nan_observation_is_refused_with_the_reason(name: str, other_geometry) -> None:  # type: ignore[no-untyped-def]
    world = _world("unified", other_geometry)
    Rs, ts = world.poses(2, np.random.default_rng(6), margin=0.02)
    ctrl = _mpc(name, world, (Rs[1], ts[1]), model="global", compiled=False)
    for field in ("lengths", "normals" if name == "leg-edge-mpc" else "directions"):
        obs = world.observation(Rs[0], ts[0])
        value = np.array(getattr(obs, field), dtype=float)
        value.flat[2] = np.nan
        setattr(obs, field, value)
        cmd = ctrl.step(obs)
        assert not cmd.ok and field in (cmd.reason or ""), cmd.reason
        assert np.array_equal(cmd.velocities, np.zeros(6))
    assert ctrl.stats.steps == 0  # refused before the solver


def test_warm_start_saves_iterations(other_geometry) -> None:  # type: ignore[no-untyped-def]
    """The global SQP restarted from the shifted previous solution needs fewer iterations
    than from zero over the same closed loop."""
    from tests.controllers.controller_world import closed_loop

    world = _world("unified", other_geometry)
    Rs, ts = world.poses(2, np.random.default_rng(9), margin=0.02)
    iters = {}
    for warm in (True, False):
        ctrl = _mpc("leg-edge-mpc", world, (Rs[1], ts[1]), model="global", gain=3.0,
                    tolerance=1e-6, max_iter=20)
        if not warm:
            ctrl._shift = lambda U: np.zeros_like(U)
        closed_loop(world, ctrl, (Rs[0], ts[0]), (Rs[1], ts[1]), DT, 20)
        assert ctrl.stats.fallbacks == 0
        iters[warm] = ctrl.stats.total_sqp_iterations
    assert iters[True] < 0.9 * iters[False], iters  # measured: 93 vs 118


def test_compiled_and_virtual_machine_agree(geometry) -> None:  # type: ignore[no-untyped-def]
    """The C kernel and DAQP (screened visibility rows) give the command of the CasADi
    virtual machine and ``casadi.conic`` (full QP)."""
    world = _world("perspective", geometry)
    Rs, ts = world.poses(2, np.random.default_rng(12), max_translation=0.06, margin=0.005)
    obs = world.observation(Rs[0], ts[0])
    cmds = [_mpc("leg-edge-mpc", world, (Rs[1], ts[1]), model="global", visibility=True,
                 compiled=compiled).step(obs) for compiled in (True, False)]
    assert all(c.ok and "fallback" not in c.notes[-1] for c in cmds)
    assert cmds[0].active_constraints  # a constrained step (speed limits at least)
    np.testing.assert_allclose(cmds[0].twist, cmds[1].twist, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize(("camera", "kind", "name"), MPC_KINDS)
def test_global_model_at_the_goal_and_on_malformed_observations(camera: str, kind: str,  # type: ignore[no-untyped-def]
                                                                name: str, other_geometry) -> None:
    """The registry checks (tests/controllers/test_registry.py) run the default (local)
    model; the global model also gives an exact zero at the goal and never raises."""
    from controllers.base import Observation

    world = _world(camera, other_geometry)
    Rs, ts = world.poses(2, np.random.default_rng(14), margin=0.02)
    ctrl = _mpc(name, world, (Rs[1], ts[1]), model="global", compiled=False)
    for _ in range(2):
        cmd = ctrl.step(world.observation(Rs[1], ts[1]))
        assert cmd.ok and cmd.error_norm < 1e-9, cmd.reason
        np.testing.assert_allclose(cmd.velocities, 0.0, atol=1e-9)
    good = world.observation(Rs[0], ts[0])
    for obs in (Observation(0.0, np.full(5, 0.4)), Observation(0.0, good.lengths),
                Observation(0.0, good.lengths, normals=np.zeros((6, 3)),
                            directions=np.zeros((6, 2, 3)), lines=np.zeros((6, 3)))):
        cmd = ctrl.step(obs)
        assert not cmd.ok and cmd.reason
        assert np.array_equal(cmd.velocities, np.zeros(6))


@pytest.mark.slow
def test_tilt_bound_is_kept(geometry) -> None:  # type: ignore[no-untyped-def]
    """Goal tilted by 8 deg, bound 4 deg: the classical law tilts the platform to 8 deg,
    the predictive laws stop at the bound (global: exactly at the predicted stages;
    local: a linearised bound, within 0.1 deg)."""
    from hexapod.se3 import rotation_from_rpy
    from tests.controllers.controller_world import closed_loop

    world = _world("unified", geometry)
    R0, t0 = world.home()
    goal = (rotation_from_rpy(np.deg2rad(8.0), 0.0, 0.0), t0 + np.array([0.01, 0.0, 0.0]))

    def tilt(run) -> float:  # type: ignore[no-untyped-def]
        return float(max(np.degrees(np.arccos(np.clip(R[2, 2], -1, 1))) for R, _ in run.poses))

    run = closed_loop(world, _classical(world, goal, "normals", 2.0), (R0, t0), goal, DT, 150)
    assert tilt(run) > 7.5
    for model, tol in (("global", 1e-6), ("local", 0.1)):
        ctrl = _mpc("leg-edge-mpc", world, goal, gain=2.0, model=model, max_tilt_deg=4.0)
        run = closed_loop(world, ctrl, (R0, t0), goal, DT, 150)
        assert 3.5 < tilt(run) <= 4.0 + tol, (model, tilt(run))
        assert any("tilt" in a for c in run.commands for a in c.active_constraints)


@pytest.mark.parametrize("model", ["local", "global"])
def test_hidden_edges_are_left_out(model: str, other_geometry) -> None:  # type: ignore[no-untyped-def]
    """An edge hidden at the current step (NaN, flagged) is left out of the error; the
    pose is fitted from the legs seen whole; the command stays close to the one with
    every edge."""
    world = _world("perspective", other_geometry)
    Rs, ts = world.poses(2, np.random.default_rng(15), max_translation=0.01,
                         max_angle=np.deg2rad(1.0), margin=0.02)
    full = _mpc("leg-edge-mpc", world, (Rs[1], ts[1]), model=model)
    ref = full.step(world.observation(Rs[0], ts[0]))
    ctrl = _mpc("leg-edge-mpc", world, (Rs[1], ts[1]), model=model)
    obs = world.observation(Rs[0], ts[0])
    obs.edge_visible = np.ones((6, 2), dtype=bool)
    obs.edge_visible[2, 1] = False
    assert obs.lines is not None
    obs.lines[2, 1] = np.nan
    cmd = ctrl.step(obs)
    assert cmd.ok and ctrl.stats.fallbacks == 0, cmd.notes
    assert cmd.features_used == 33
    assert any("using 11 of 12 edges" in n for n in cmd.notes)
    # measured: 3.8 % (local), 0.5 % (global) of the largest twist component
    np.testing.assert_allclose(cmd.twist, ref.twist, rtol=0, atol=0.1 * np.abs(ref.twist).max())


@pytest.mark.parametrize("model", ["local", "global"])
@pytest.mark.parametrize(("camera", "kind", "name"), MPC_KINDS)
def test_retarget_is_reset_on_the_new_goal_but_keeps_the_state(  # type: ignore[no-untyped-def]
        camera: str, kind: str, name: str, model: str, other_geometry) -> None:
    """Right after reset (warm start at rest), ``retarget(goal)`` then a step commands
    exactly what a controller reset on that goal commands; later, the warm start is
    kept (not zeroed as a reset would), and a bad goal leaves the old one in place."""
    from controllers.base import Goal
    from controllers.exceptions import ContextError

    world = _world(camera, other_geometry)
    Rs, ts = world.poses(3, np.random.default_rng(21), margin=0.02)
    moved = _mpc(name, world, (Rs[1], ts[1]), model=model, horizon=4, compiled=False)
    fresh = _mpc(name, world, (Rs[2], ts[2]), model=model, horizon=4, compiled=False)
    moved.retarget(world.goal(Rs[2], ts[2]))
    obs = world.observation(Rs[0], ts[0])
    a, b = moved.step(obs), fresh.step(obs)
    np.testing.assert_array_equal(a.velocities, b.velocities)
    np.testing.assert_array_equal(a.error, b.error)
    warm = moved._U.copy()
    assert np.abs(warm).max() > 0
    star = moved._star.copy()
    with pytest.raises(ContextError):
        moved.retarget(Goal(lengths=np.full(5, 0.4)))
    np.testing.assert_array_equal(moved._star, star)
    moved.retarget(world.goal(Rs[1], ts[1]))
    np.testing.assert_array_equal(moved._U, warm)
