"""The compiled law core gives the numpy oracle's commands (``numpy_law``); the QP shortcut
gives OSQP's."""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np
import pytest

from controllers import registry
from controllers.law_algebra import full_rank_certificate, jacobi_eigen
from controllers.law_kernel import LawKernel, feature_law_function, feature_law_kernel, law_layouts
from controllers.law_rows import ACCEPTED, REJECTED, LawRows
from controllers.law_tools import Gain
from controllers.solvers.osqp_limits import LimitQP
from controllers.tasks.leg_direction import LEG_DIRECTIONS
from hexapod.compiled import CompiledFunction
from tests.controllers.controller_world import World, make_camera
from tests.controllers.interaction_oracle import direction_task
from tests.controllers.numpy_law import numpy_law, solve_normal_damped

LAWS = ["leg-direction", "leg-edge", "leg-direction-qp", "leg-edge-qp"]
OPTIONS: list[dict[str, Any]] = [{}, {"adaptive_gain": (4.0, 0.5, 30.0)}, {"damping": 0.05}]


@pytest.fixture(params=["perspective", "unified"])
def world(request: pytest.FixtureRequest, other_geometry) -> World:  # type: ignore[no-untyped-def]
    return World(other_geometry, make_camera(request.param, other_geometry))


def _same(a: Any, b: Any, scale: float = 1.0) -> None:
    assert a.ok and b.ok, (a.reason, b.reason)
    np.testing.assert_allclose(a.velocities, b.velocities, rtol=1e-9, atol=1e-12 * scale)
    np.testing.assert_allclose(a.twist, b.twist, rtol=1e-9, atol=1e-12 * scale)
    np.testing.assert_allclose(a.error, b.error, rtol=1e-12, atol=1e-15)
    assert a.error_norm == pytest.approx(b.error_norm, rel=1e-12)
    assert a.rank == b.rank == 6
    np.testing.assert_allclose(a.condition, b.condition, rtol=1e-8)
    assert a.features_used == b.features_used
    assert a.active_constraints == b.active_constraints
    assert a.notes == b.notes


@pytest.mark.parametrize(("name", "options"), [(n, o) for n in LAWS for o in OPTIONS
                                               if not ("qp" in n and "damping" in o)])
def test_compiled_core_equals_numpy(world: World, name: str, options: dict[str, Any],
                                    rng: np.random.Generator) -> None:
    Rs, ts = world.poses(8, rng, max_translation=0.02, max_angle=np.deg2rad(4), margin=0.03)
    ctx = world.context(world.goal(Rs[0], ts[0]), 0.02)
    fast = registry.create(name, **options)
    slow = numpy_law(name, **options)
    fast.reset(ctx)
    slow.reset(ctx)
    for R, t in zip(Rs[1:], ts[1:], strict=True):
        obs = world.observation(R, t)
        _same(fast.step(obs), slow.step(obs))
        np.testing.assert_allclose(fast.estimate.directions, slow.estimate.directions,  # type: ignore[attr-defined]
                                   rtol=0, atol=1e-14)


def _hide(obs: Any, step: int, never_seen: bool) -> None:
    """Hide features on a schedule: one edge of leg 2 from step 1, leg 4 whole from step
    3 (its direction is then dead-reckoned), leg 5 whole from the start (never seen)."""
    edges = np.ones((6, 2), dtype=bool)
    legs = np.ones(6, dtype=bool)
    if step >= 1:
        edges[2, 0] = False
    if step >= 3:
        edges[4] = False
        legs[4] = False
    if never_seen:
        edges[5] = False
        legs[5] = False
    obs.edge_visible = edges
    obs.direction_visible = legs
    obs.normals = np.where(edges[..., None], obs.normals, np.nan)
    if obs.lines is not None:
        obs.lines = np.where(edges[..., None], obs.lines, np.nan)
    obs.directions = np.where(legs[:, None], obs.directions, np.nan)


@pytest.mark.parametrize("interaction", ["current", "desired", "mean"])
@pytest.mark.parametrize("name", LAWS)
@pytest.mark.parametrize("case", ["hidden", "never-seen", "goal-hidden"])
def test_compiled_core_equals_numpy_with_hidden_features(world: World, name: str,
                                                         interaction: str, case: str,
                                                         monkeypatch: pytest.MonkeyPatch
                                                         ) -> None:
    """Hidden features (zero-weight rows of the core), dead-reckoned, approximated and
    nominal-model leg directions, every interaction choice: the compiled core gives the
    numpy path's commands, notes, rank, error and estimate."""
    rng = np.random.default_rng(11)
    Rs, ts = world.poses(2, rng, max_translation=0.02, max_angle=np.deg2rad(4), margin=0.03)
    goal = world.goal(Rs[0], ts[0])
    if case == "goal-hidden":  # leg 5 unknown in the goal too: the nominal model's direction
        goal.edge_visible = np.ones((6, 2), dtype=bool)
        goal.edge_visible[5] = False
        goal.directions = goal.directions.copy()
        goal.directions[5] = np.nan
        goal.normals = np.where(goal.edge_visible[..., None], goal.normals, np.nan)
        if goal.lines is not None:
            goal.lines = np.where(goal.edge_visible[..., None], goal.lines, np.nan)
    ctx = world.context(goal, 0.02)
    fast = registry.create(name, interaction=interaction, gain=2.0)
    slow = numpy_law(name, interaction=interaction, gain=2.0)
    fast.reset(ctx)
    slow.reset(ctx)
    calls = []
    kernel = fast.kernel  # type: ignore[attr-defined]
    real = kernel.evaluate
    kernel.evaluate = lambda: calls.append(1) or real()
    rows_step = LawRows.step

    def counted_rows(self: LawRows, *args: Any) -> tuple[np.ndarray, np.ndarray]:
        code, Y = rows_step(self, *args)  # the batch's C: the rows it evaluated
        calls.extend([1] * int(np.count_nonzero((code == ACCEPTED) | (code == REJECTED))))
        return code, Y

    monkeypatch.setattr(LawRows, "step", counted_rows)
    R, t = Rs[1], ts[1]
    notes = set()
    for step in range(8):
        obs = world.observation(R, t, 0.02 * step)
        _hide(obs, step, case != "hidden")
        a, b = fast.step(obs), slow.step(obs)
        assert a.ok and b.ok, (a.reason, b.reason)
        # Cholesky against LAPACK's eigh (and OSQP's refined active set for the QP laws):
        # agreement to rounding times the condition number.
        scale = np.abs(b.velocities).max()
        np.testing.assert_allclose(a.velocities, b.velocities, rtol=0, atol=1e-8 * scale)
        np.testing.assert_allclose(a.twist, b.twist, rtol=0, atol=1e-8 * np.abs(b.twist).max())
        np.testing.assert_allclose(a.error, b.error, rtol=0, atol=1e-15)
        assert a.error_norm == pytest.approx(b.error_norm, rel=1e-12)
        assert a.rank == b.rank == 6
        np.testing.assert_allclose(a.condition, b.condition, rtol=1e-7)
        assert a.features_used == b.features_used
        assert a.notes == b.notes
        for k in ("directions", "in_use"):  # dead reckoning integrates the twists above
            np.testing.assert_allclose(getattr(fast.estimate, k), getattr(slow.estimate, k),  # type: ignore[attr-defined]
                                       rtol=0, atol=1e-10)
        notes.update(n.split(" ")[0] for n in a.notes)
        R, t = world.move(R, t, b.twist, 0.02)
    assert len(calls) >= 8
    expected = {"using", "predicted"} | {"hidden": set(), "never-seen": {"desired"},
                                         "goal-hidden": {"nominal-model"}}[case]
    assert expected <= notes, notes


@pytest.mark.parametrize("name", LAWS)
def test_too_few_features_give_the_numpy_rank(world: World, name: str) -> None:
    """Two legs left: the core's rank is the numpy path's (< 6), both refuse alike."""
    Rs, ts = world.poses(2, np.random.default_rng(5), margin=0.03)
    ctx = world.context(world.goal(Rs[0], ts[0]), 0.02)
    out = []
    for law in (registry.create(name), numpy_law(name)):
        law.reset(ctx)
        obs = world.observation(Rs[1], ts[1])
        obs.edge_visible = np.zeros((6, 2), dtype=bool)
        obs.edge_visible[:2] = True
        obs.direction_visible = np.zeros(6, dtype=bool)
        obs.direction_visible[:2] = True
        out.append(law.step(obs))
    a, b = out
    assert not a.ok and not b.ok
    assert a.rank == b.rank < 6 and a.features_used == b.features_used
    assert a.notes == b.notes
    # The condition number of a singular N is its rounding noise (inf or ~1e8 from
    # either eigen-solver): the reasons agree up to it, and both are beyond the threshold.
    assert a.reason is not None and b.reason is not None
    assert a.reason.split("(condition")[0] == b.reason.split("(condition")[0]
    assert min(a.condition, b.condition) > 1e6
    np.testing.assert_allclose(a.error, b.error, rtol=0, atol=1e-15)


def test_jacobi_eigen_solve_equals_lapack(rng: np.random.Generator) -> None:
    """Rank, condition and thresholded solution of the core = solve_normal_damped's."""
    Ns = ca.SX.sym("N", 6, 6)
    w, V = jacobi_eigen(Ns)
    f = ca.Function("eig", [Ns], [ca.vertcat(*w), ca.vertcat(*[ca.horzcat(*r) for r in V])])
    for trial in range(200):
        L = rng.normal(size=(36, 6)) * np.logspace(0, rng.uniform(0, 5), 6)
        if trial % 4 == 0:  # rank 5
            L[:, 5] = 2.0 * L[:, 4]
        N = L.T @ L
        b = L.T @ rng.normal(size=36)
        wj, Vj = (np.asarray(v, dtype=float) for v in f(N))
        wj = wj.ravel()
        np.testing.assert_allclose(np.sort(wj), np.linalg.eigvalsh(N), rtol=0,
                                   atol=1e-14 * np.abs(N).max())
        np.testing.assert_allclose(Vj.T @ Vj, np.eye(6), atol=1e-13)
        keep = wj > 1e-12 * wj.max()
        x = Vj @ np.where(keep, (Vj.T @ b) / np.where(keep, wj, 1.0), 0.0)
        xr, rank, _ = solve_normal_damped(N, b, 1e-6, 0.0)
        assert rank == int(keep.sum()) == (5 if trial % 4 == 0 else 6)
        # Both are backward stable: they agree to rounding times the condition number.
        kept_cond = wj.max() / wj[keep].min()
        np.testing.assert_allclose(x, xr, rtol=0, atol=1e-14 * kept_cond * np.abs(xr).max())


@pytest.mark.slow
@pytest.mark.parametrize("threshold", [1e-6, 1e-3, 0.1])
def test_full_rank_certificate_is_sound_and_tight(threshold: float,
                                                  rng: np.random.Generator) -> None:
    """The lean cores' certificate: never full rank where the eigenvalues say otherwise
    (w_min <= threshold^2 w_max), and always given above its margin (w_min / w_max >
    sqrt(6) (2 threshold^2 + 1e-10): |N|_F <= sqrt(6) w_max)."""
    Ns = ca.SX.sym("N", 6, 6)
    t2 = ca.SX.sym("t2")
    cert = ca.Function("cert", [Ns, t2], [full_rank_certificate(Ns, t2)])
    thr2 = threshold * threshold
    margin = np.sqrt(6.0) * (2.0 * thr2 + 1e-10)
    ratios = 10.0 ** rng.uniform(np.log10(thr2) - 6, 0.0, 3000)
    ratios[:300] = thr2 * (1.0 + rng.uniform(-1e-3, 1e-3, 300))  # at the threshold
    ratios[300:330] = 0.0  # singular
    certified = 0
    for r in ratios:
        Q, _ = np.linalg.qr(rng.normal(size=(6, 6)))
        w = np.sort(np.concatenate([[1.0, r], 10.0 ** rng.uniform(np.log10(max(r, 1e-300)),
                                                                   0.0, 4)]))
        N = (Q * (w * 10.0 ** rng.uniform(-6, 6))) @ Q.T
        N = 0.5 * (N + N.T)
        ok = float(cert(N, thr2)) == 1.0
        e = np.linalg.eigvalsh(N)
        if ok:
            assert e[0] > thr2 * e[-1], (r, e)
            certified += 1
        if r > 1.01 * margin:
            assert ok, (r, margin)
    assert certified >= (ratios > 1.01 * margin).sum() > 300


@pytest.mark.parametrize("name", ["leg-direction", "leg-edge", "leg-edge-qp"])
def test_lean_core_equals_the_full_core_where_it_certifies(world: World, name: str,
                                                           rng: np.random.Generator) -> None:
    """The batched laws' lean core: same error, twist and command, to the last bit, as
    the per-trial core wherever it certifies full rank; rank 0 (the row goes to the
    per-trial core) elsewhere, here on a leg-direction row made rank-deficient."""
    Rs, ts = world.poses(12, rng, max_translation=0.02, max_angle=np.deg2rad(4), margin=0.03)
    law = registry.create(name)
    law.reset(world.context(world.goal(Rs[0], ts[0]), 0.02))
    kernel = law.kernel  # type: ignore[attr-defined]
    assert kernel is not None and kernel.lean_function is not kernel.function
    o = kernel.outputs
    rows = []
    for R, t in zip(Rs[1:], ts[1:], strict=True):
        assert law._load_kernel(world.observation(R, t), np.ones(6))  # type: ignore[attr-defined]
        kernel.set("lengths", world.observation(R, t).lengths)
        rows.append(kernel.input_vector.copy())
    X = np.array(rows)
    full, lean = kernel.function.batch(X), kernel.lean_function.batch(X)
    assert np.all(full[:, o["rank"].start] == 6) and np.all(lean[:, o["rank"].start] == 6)
    for key in ("error", "error_norm", "tau", "qdot", "qdot_check", "directions"):
        assert np.array_equal(full[:, o[key]], lean[:, o[key]]), key
    # a threshold that no row passes (0.99: condition numbers below 1.01): no certificate
    X[:, kernel.slices["threshold2"]] = 0.99 ** 2
    full, lean = kernel.function.batch(X), kernel.lean_function.batch(X)
    assert np.all(full[:, o["rank"].start] < 6) and np.all(lean[:, o["rank"].start] == 0)
    if name == "leg-direction":  # every measured direction equal to the desired one's
        bad = X[:1].copy()     # mirror: a rank-deficient interaction matrix
        bad[0, kernel.slices["features"]] = 0.0
        bad[0, kernel.slices["features"].start + 2::3] = 1.0
        bad[0, kernel.slices["desired"]] = bad[0, kernel.slices["features"]]
        f, g = kernel.function.batch(bad)[0], kernel.lean_function.batch(bad)[0]
        assert f[o["rank"].start] < 6 and g[o["rank"].start] == 0


def test_virtual_machine_fallback_equals_c(monkeypatch: pytest.MonkeyPatch,
                                           rng: np.random.Generator) -> None:
    """Without a C compiler the CasADi VM evaluates the same core."""
    layouts = law_layouts(LEG_DIRECTIONS)
    c_kernel = LawKernel(CompiledFunction(feature_law_function(LEG_DIRECTIONS), True, *layouts))
    monkeypatch.setenv("CC", "/nonexistent/cc")
    vm_kernel = LawKernel(CompiledFunction(feature_law_function(LEG_DIRECTIONS), True, *layouts))
    assert c_kernel.function.compiled and not vm_kernel.function.compiled
    u = rng.normal(size=(6, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    us = u + 0.05 * rng.normal(size=(6, 3))
    us /= np.linalg.norm(us, axis=1, keepdims=True)
    for k in (c_kernel, vm_kernel):
        k.set("features", u)
        k.set("desired", us)
        k.set("base_points", rng.normal(size=(6, 3)) if k is c_kernel else c_kernel.inputs[
            "base_points"])
        k.set("lengths", np.full(6, 0.3))
        k.set("gain", (1.0, 1.0, 0.0))
        k.set("threshold2", 1e-12)
    for weights in (np.ones(6), np.array([1.0, 0.0, 1.0, 1.0, 1.0, 1.0])):
        for k in (c_kernel, vm_kernel):
            k.set("weights", weights)
        a, b = c_kernel.evaluate(), vm_kernel.evaluate()
        assert a.rank == b.rank == 6 and np.all(a.qdot != 0)
        np.testing.assert_allclose(a.qdot, b.qdot, rtol=1e-12, atol=1e-15)
        assert a.condition == pytest.approx(b.condition, rel=1e-12)


@pytest.mark.parametrize("name", ["leg-direction-qp", "leg-edge-qp"])
def test_qp_shortcut_equals_the_osqp_solution(world: World, name: str,
                                              rng: np.random.Generator,
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    """Away from the limits the unconstrained optimum is returned without calling OSQP,
    and it is the command OSQP (with the active-set refinement) gives."""
    Rs, ts = world.poses(8, rng, max_translation=0.02, max_angle=np.deg2rad(4), margin=0.03)
    ctx = world.context(world.goal(Rs[0], ts[0]), 0.02)
    short = registry.create(name, gain=0.5)
    full = registry.create(name, gain=0.5, shortcut=False)
    short.reset(ctx)
    full.reset(ctx)
    calls: list[str] = []
    real = LimitQP.solve

    def counting(self: LimitQP, *args: Any, **kwargs: Any) -> Any:
        calls.append("short" if self is short.solver.qp else "full")  # type: ignore[attr-defined]
        return real(self, *args, **kwargs)

    monkeypatch.setattr(LimitQP, "solve", counting)
    for R, t in zip(Rs[1:], ts[1:], strict=True):
        obs = world.observation(R, t)
        a, b = short.step(obs), full.step(obs)
        assert a.ok and b.ok and a.active_constraints == b.active_constraints == []
        scale = np.abs(b.velocities).max()
        np.testing.assert_allclose(a.velocities, b.velocities, rtol=0, atol=1e-9 * scale)
        np.testing.assert_allclose(a.twist, b.twist, rtol=0, atol=1e-9 * np.abs(b.twist).max())
        assert a.rank == b.rank and a.condition == pytest.approx(b.condition, rel=1e-9)
        assert a.error_norm == b.error_norm
    assert calls.count("full") == len(Rs) - 1 and "short" not in calls


def test_qp_shortcut_off_with_chosen_osqp_settings() -> None:
    assert registry.create("leg-edge-qp").solver.shortcut  # type: ignore[attr-defined]
    assert not registry.create("leg-edge-qp", max_iter=10).solver.shortcut  # type: ignore[attr-defined]
    assert registry.create("leg-edge-qp", max_iter=10,  # type: ignore[attr-defined]
                           shortcut=True).solver.shortcut


def _numpy_refine(P: np.ndarray, c: np.ndarray, J: np.ndarray, lower: np.ndarray,
                  upper: np.ndarray, x: np.ndarray, y: np.ndarray, tol: float) -> np.ndarray:
    """The active-set refinement as written in numpy before it was compiled (reference)."""
    Jx = J @ x
    at_up = (Jx >= upper - tol) & (y > 0)
    at_lo = (Jx <= lower + tol) & (y < 0)
    act = at_up | at_lo
    k = int(np.count_nonzero(act))
    try:
        if k == 0:
            xr, nu = np.linalg.solve(P, -c), np.zeros(0)
        else:
            Ja = J[act]
            K = np.zeros((6 + k, 6 + k))
            K[:6, :6] = P
            K[:6, 6:] = Ja.T
            K[6:, :6] = Ja
            sol = np.linalg.solve(K, np.concatenate([-c, np.where(at_up, upper, lower)[act]]))
            xr, nu = sol[:6], sol[6:]
    except np.linalg.LinAlgError:
        return x
    Jr = J @ xr
    slack = 1e-9 * (1.0 + np.abs(upper - lower))
    feasible = bool(np.all(Jr <= upper + slack) and np.all(Jr >= lower - slack))
    signs_ok = bool(np.all(nu[at_up[act]] >= -1e-12) and np.all(nu[at_lo[act]] <= 1e-12))
    return xr if feasible and signs_ok and np.all(np.isfinite(xr)) else x


def test_compiled_refinement_equals_numpy(rng: np.random.Generator) -> None:
    """Over OSQP solutions with 0 to 6 active bounds, the compiled KKT refinement
    returns what the numpy one returns."""
    qp = LimitQP()
    n_active = set()
    for _ in range(150):
        L = rng.normal(size=(36, 6))
        N = L.T @ L
        b = L.T @ rng.normal(size=36)
        J = rng.normal(size=(6, 6))
        free = np.linalg.solve(N, -b)
        Jf = J @ free
        width = np.abs(Jf).max() * rng.uniform(0.2, 1.5)
        lower, upper = -np.full(6, width), np.full(6, width)
        tau, status = qp.solve(N, b, 1.0, J, lower, upper)
        assert tau is not None, status
        P = 2.0 * (N + qp.regularization * np.eye(6))
        c = 2.0 * b
        y = np.array(qp._solver.solution.y if qp._ext is None else qp._ext.solution.y)
        x = np.array(qp._solver.solution.x if qp._ext is None else qp._ext.solution.x)
        ref = _numpy_refine(P, c, J, lower, upper, x, y, qp.active_tolerance)
        out = qp._refine(P, c, J, lower, upper, x, y)
        np.testing.assert_allclose(out, ref, rtol=1e-9, atol=1e-12 * np.abs(ref).max())
        n_active.add(int(np.count_nonzero(np.abs(J @ out) >= width - 1e-9)))
    assert {0, 1, 2} <= n_active


def test_weighted_rows_are_the_weighted_least_squares(rng: np.random.Generator) -> None:
    """Weights w_i: N = sum w_i L_i^T L_i and b = sum w_i L_i^T e_i with the numpy blocks of
    interaction_oracle; a zero weight leaves the block out of the error norm, the
    gain and the rank too, even when that block is not finite."""
    kernel = feature_law_kernel(LEG_DIRECTIONS)
    u = rng.normal(size=(6, 3)) + np.array([0.0, 0.0, 3.0])
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    us = u + 0.05 * rng.normal(size=(6, 3))
    us /= np.linalg.norm(us, axis=1, keepdims=True)
    A, q = rng.normal(size=(6, 3)), rng.uniform(0.2, 0.4, 6)
    for name, value in (("features", u), ("desired", us), ("base_points", A), ("lengths", q),
                        ("gain", (3.0, 0.5, 20.0)), ("threshold2", 1e-12)):
        kernel.set(name, value)
    e, L = direction_task(u, us, A, q)
    assert e is not None
    w = rng.uniform(0.1, 2.0, 6)
    w[2] = 0.0
    kernel.set("weights", w)
    r = kernel.evaluate()
    Lw = L * np.sqrt(w)[:, None, None]
    np.testing.assert_allclose(r.N, np.einsum("kij,kil->jl", Lw, Lw), rtol=1e-12,
                               atol=1e-14 * np.abs(r.N).max())
    np.testing.assert_allclose(r.b, np.einsum("kij,ki->j", L * w[:, None, None], e),
                               rtol=1e-12, atol=1e-14 * np.abs(r.b).max())
    used = e[w > 0]
    assert r.error_norm == pytest.approx(np.linalg.norm(used), rel=1e-14)
    assert r.gain == pytest.approx(Gain(3.0, 0.5, 20.0)(float(np.abs(used).max())), rel=1e-14)
    features = u.copy()
    features[2] = np.nan  # an unused block that is not finite changes nothing
    kernel.set("features", features)
    measured = np.ones(6)  # leg 2's direction for J_inv given, not measured
    measured[2] = 0.0
    kernel.set("measured", measured)
    kernel.set("leg_directions", np.where(measured[:, None] > 0, np.nan, u))
    s = kernel.evaluate()
    assert np.array_equal(s.N, r.N) and np.array_equal(s.b, r.b) and np.array_equal(s.qdot,
                                                                                    r.qdot)
    assert s.error_norm == r.error_norm and s.rank == r.rank == 6


def test_kernel_builds_each_core_on_first_use(monkeypatch: pytest.MonkeyPatch) -> None:
    """A law's kernel builds neither core at its creation: the full core when it first
    evaluates, the lean one when asked (a per-trial run never builds the lean core, a
    batch whose rows all take the lean core never builds the full one); the layouts are
    the cores' own."""
    import controllers.law_kernel as law_kernel

    built: list[bool] = []
    real = law_kernel._compiled_core

    def counting(*args: Any) -> CompiledFunction:
        built.append(args[2])
        return real(*args)

    monkeypatch.setattr(law_kernel, "_compiled_core", counting)
    kernel = feature_law_kernel(LEG_DIRECTIONS, "mean")
    kernel.set("gain", (1.0, 1.0, 0.0))
    assert built == []
    kernel.evaluate()
    assert built == [False]
    lean = kernel.lean_function
    assert built == [False, True]
    for core in (kernel.function, lean):
        assert (core.inputs.slices, core.outputs.slices) == (kernel.slices.slices,
                                                             kernel.outputs.slices)
    with pytest.raises(ValueError, match="layouts"):
        LawKernel(lambda: kernel.function)
