"""The computed-torque family over a batch (:mod:`controllers.ctc_rows`): every row of a
batch tracking a reference goes through the law's one step, with the commands of its
batches of one (the per-trial step) to the last bit, trial by trial; a row the compiled
step cannot finish is refused with its reason."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import pytest

from controllers import registry
from controllers.base import ControllerContext, ObservationBatch
from controllers.task_ctc_compiled import CompiledTaskStep
from hexapod import HexapodGeometry
from hexapod.dynamics.robots import DynamicRobots
from tests.controllers.ctc_world import DT, CtcWorld, ideal_drives, line_reference

LAWS = ("computed-torque", "cartesian-ctc", "vision-ctc", "leg-edge-ctc",
        "leg-direction-ctc")


def line_trials(world: CtcWorld, n: int = 3) -> tuple[ControllerContext, DynamicRobots]:
    """The context of a quintic line (a reference) in ``world`` and ``n`` force-mode
    robots of its truth at the line's start, 1 mm apart along y."""
    R0, t0, R1, t1, ref = line_reference(world.truth, "quintic", (0.5, -0.3, 0.4))
    robots = DynamicRobots([world.truth] * n, np.array([R0] * n),
                           np.array([t0 + np.array([0.0, 0.001 * k, 0.0]) for k in range(n)]))
    robots.drives.mode = "force"
    return world.context(world.goal(R1, t1), reference=ref), robots


def _batch(world: CtcWorld, robots: DynamicRobots, t: float) -> ObservationBatch:
    """The observations of the robots' rows at ``t`` [s] as one batch."""
    rows = []
    for k in range(len(robots.R)):
        one = DynamicRobots([world.truth], robots.R[k:k + 1].copy(), robots.t[k:k + 1].copy())
        one.twist[:] = robots.twist[k:k + 1]
        rows.append(ObservationBatch.of(world.observation(one, t)))
    def stacked(field: str) -> np.ndarray | None:
        values = [getattr(r, field) for r in rows]
        return None if values[0] is None else np.concatenate(values)

    return ObservationBatch(
        np.arange(len(rows)), np.array([t] * len(rows)),
        *(stacked(f) for f in ("lengths", "normals", "lines", "directions", "edge_visible",
                               "direction_visible")),
        None, stacked("q_dot"))


def _rows_of(obs: ObservationBatch, idx: np.ndarray) -> ObservationBatch:
    """The rows ``idx`` of a batch."""
    return dataclasses.replace(obs, **{f.name: None if getattr(obs, f.name) is None
                                       else np.asarray(getattr(obs, f.name))[idx]
                                       for f in dataclasses.fields(obs) if f.init})


def _step_as_the_trials(batch: Any, singles: list[Any], obs: ObservationBatch, lone: bool,
                        label: object) -> np.ndarray:
    """Step ``batch`` on ``obs`` (with ``lone``: row 1 as a batch of its own, the other
    rows as one batch) and assert each row's forces and error norm are those of the
    single controller ``singles[j]`` stepped on its row, bit for bit; the forces (n, 6)."""
    n = len(singles)
    forces, norms = np.zeros((n, 6)), np.zeros(n)
    if lone:  # row 1 alone: a batch of one
        one = batch.step_batch(_rows_of(obs, np.array([1])))
        assert one.forces is not None and one.reasons == [None]
        forces[1], norms[1] = one.forces[0], one.error_norm[0]
        idx = np.array([j for j in range(n) if j != 1])
        part = batch.step_batch(_rows_of(obs, idx))
        assert part.forces is not None
        forces[idx], norms[idx] = part.forces, part.error_norm
    else:
        full = batch.step_batch(obs)
        assert full.forces is not None and all(r is None for r in full.reasons)
        forces, norms = full.forces, full.error_norm
    for j, s in enumerate(singles):
        cmd = s.step(obs.item(j))
        assert cmd.reason is None, cmd.reason
        assert forces[j].tobytes() == np.asarray(cmd.forces).tobytes(), (label, j)
        assert norms[j] == cmd.error_norm
    return forces


@pytest.mark.slow
@pytest.mark.parametrize("name", LAWS)
def test_every_row_in_one_call_and_equal_to_the_trials_steps(geometry: HexapodGeometry,
                                                             name: str) -> None:
    truth = ideal_drives(geometry)
    world = CtcWorld.make(truth)
    R0, t0, R1, t1, ref = line_reference(truth, "quintic", (0.5, -0.3, 0.4))
    ctx = world.context(world.goal(R1, t1), reference=ref)
    n = 3
    starts = [(R0, t0 + np.array([0.0, 0.001 * k, 0.0])) for k in range(n)]
    robots = DynamicRobots([truth] * n, np.array([s[0] for s in starts]),
                           np.array([s[1] for s in starts]))
    robots.drives.mode = "force"
    batch = registry.create(name)
    batch.reset_batch([ctx] * n)
    singles = [registry.create(name) for _ in range(n)]
    for s in singles:
        s.reset(ctx)
    for k in range(8):
        obs = _batch(world, robots, k * DT)
        out = batch.step_batch(obs)  # its one step: every row commanded
        assert out.reasons == [None] * n, (k, out.reasons)
        assert out.forces is not None
        for j, s in enumerate(singles):
            cmd = s.step(obs.item(j))
            assert cmd.reason is None
            assert out.forces[j].tobytes() == np.asarray(cmd.forces).tobytes()
            assert out.error_norm[j] == cmd.error_norm
        assert not robots.advance(np.arange(n), out.forces, DT / 20, 20).any()


@pytest.mark.slow
def test_a_row_without_leg_rates_is_refused_alone(geometry: HexapodGeometry) -> None:
    truth = ideal_drives(geometry)
    world = CtcWorld.make(truth)
    R0, t0, R1, t1, ref = line_reference(truth, "quintic", (0.5, -0.3, 0.4))
    ctx = world.context(world.goal(R1, t1), reference=ref)
    robots = DynamicRobots([truth] * 2, np.array([R0, R0]), np.array([t0, t0]))
    obs = _batch(world, robots, 0.0)
    assert obs.q_dot is not None
    obs = dataclasses.replace(obs, q_dot=obs.q_dot.copy())
    obs.q_dot[1, 2] = np.nan
    law = registry.create("computed-torque")
    law.reset_batch([ctx, ctx])
    full = law.step_batch(obs)
    assert full.reasons[0] is None
    assert full.reasons[1] is not None and "leg velocities" in full.reasons[1]


#: Per law: the rows its batched inputs take at each of 5 steps (row 1 hides leg 4's
#: second edge and so its direction from the third step; the pose laws' pose comes
#: from the encoders, vision-ctc's from the six legs: its row 1 goes to its numpy step).
#: leg-edge-ctc's row 1 is the batch's too (FeatureCTC.batch_partly_seen).
FAST_ROWS = {"leg-edge-ctc": [[0, 1, 2]] * 5,
             "leg-direction-ctc": [[0, 1, 2]] * 2 + [[0, 2]] * 3,
             # five legs seen: the batch's too (CartesianCTC.batch_partly_seen)
             "vision-ctc": [[0, 1, 2]] * 5,
             "cartesian-ctc": [[0, 1, 2]] * 5}


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(FAST_ROWS))
def test_batched_inputs_take_the_common_rows_the_others_row_by_row(
        geometry: HexapodGeometry, name: str) -> None:
    """The task laws' inputs as arrays (``batch_features``, ``batch_partly_seen``): the
    rows in the common case are written at once, a row with a hidden leg by its law's
    ``compiled_inputs`` (``leg-direction-ctc``) or by the batch (``leg-edge-ctc``: its
    leg's rows masked; ``vision-ctc``: its five legs seen); every command is the batch
    of one's to the last bit."""
    truth = ideal_drives(geometry)
    world = CtcWorld.make(truth)
    ctx, robots = line_trials(world)
    n = len(robots.R)
    batch = registry.create(name)
    batch.reset_batch([ctx] * n)
    singles = [registry.create(name) for _ in range(n)]
    for s in singles:
        s.reset(ctx)
    fast_rows: list[list[int]] = []
    prepared: list[int] = []
    inner = CompiledTaskStep.prepare

    def spy(self, law, *args):  # type: ignore[no-untyped-def]
        prepared.append(batch.trial_instances.index(law))
        return inner(self, law, *args)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(CompiledTaskStep, "prepare", spy)
        for k in range(5):
            obs = _batch(world, robots, k * DT)
            if k >= 2:
                obs = dataclasses.replace(obs, edge_visible=obs.edge_visible.copy(),
                                          direction_visible=obs.direction_visible.copy())
                obs.edge_visible[1, 4, 1] = False
                obs.direction_visible[1, 4] = False
            prepared.clear()
            out = batch.step_batch(obs)
            fast_rows.append([j for j in range(n) if j not in prepared])
            assert out.forces is not None
            mp.setattr(CompiledTaskStep, "prepare", inner)
            for j, s in enumerate(singles):
                cmd = s.step(obs.item(j))
                assert cmd.reason is None and out.reasons[j] is None
                assert out.forces[j].tobytes() == np.asarray(cmd.forces).tobytes()
                assert out.error_norm[j] == cmd.error_norm
            mp.setattr(CompiledTaskStep, "prepare", spy)
            assert not robots.advance(np.arange(n), out.forces, DT / 20, 20).any()
    assert fast_rows == FAST_ROWS[name]


def _not_called(*args: object) -> None:
    raise AssertionError("a row prepared by its law's own inputs")


def _hide(obs: ObservationBatch, row: int, leg: int) -> ObservationBatch:
    """The batch with leg ``leg`` of row ``row`` hidden (its features NaN, not visible)."""
    normals, directions = np.array(obs.normals), np.array(obs.directions)
    edges, legs = np.array(obs.edge_visible), np.array(obs.direction_visible)
    normals[row, leg] = np.nan
    directions[row, leg] = np.nan
    edges[row, leg] = False
    legs[row, leg] = False
    return dataclasses.replace(obs, normals=normals, directions=directions,
                               edge_visible=edges, direction_visible=legs)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["vision-ctc", "leg-edge-ctc"])
def test_rows_with_a_hidden_leg_go_through_the_one_call(geometry: HexapodGeometry,
                                                         name: str) -> None:
    """A hidden leg in a row every other period (``vision-ctc``: the fit to five legs;
    ``leg-edge-ctc``: its rows masked): every row's inputs written as arrays (none by
    its law's ``compiled_inputs``), the forces of each batch of one to the last bit, and
    the rows after a hidden one (their input row written in the common case) too."""
    truth = ideal_drives(geometry)
    world = CtcWorld.make(truth)
    ctx, robots = line_trials(world)
    n = len(robots.R)
    batch = registry.create(name)
    batch.reset_batch([ctx] * n)
    singles = [registry.create(name) for _ in range(n)]
    for s in singles:
        s.reset(ctx)
    notes = 0
    for k in range(8):
        obs = _batch(world, robots, k * DT)
        if k % 2:
            obs = _hide(obs, k % n, k % 6)
        with pytest.MonkeyPatch.context() as mp:  # no row by its law's own inputs
            mp.setattr(CompiledTaskStep, "prepare", _not_called)
            out = batch.step_batch(obs)
        assert out.reasons == [None] * n, (k, out.reasons)
        assert out.forces is not None
        for j, s in enumerate(singles):
            cmd = s.step(obs.item(j))
            assert cmd.reason is None, cmd.reason
            notes += bool(cmd.notes)
            assert out.forces[j].tobytes() == np.asarray(cmd.forces).tobytes()
            assert out.error_norm[j] == cmd.error_norm
        assert not robots.advance(np.arange(n), out.forces, DT / 20, 20).any()
    assert notes == (4 if name == "vision-ctc" else 0)  # "pose from legs [...]"


def test_the_rank_screen_clears_only_rows_the_exact_test_accepts(
        rng: np.random.Generator) -> None:
    """The kernels' rank screen (:func:`~controllers.law_algebra.rank_screen`, its
    ``det > 4 threshold^2 trace^6`` the test of the computed-torque steps' C) clears a
    row only where the exact test (:func:`~controllers.ctc_rows.rank_condition`)
    accepts, on ``L^T L`` of every condition from well posed to beyond the threshold (and
    the zero matrix, and one with a NaN); the well-posed ones are cleared."""
    import casadi as ca

    from controllers.ctc_rows import rank_condition
    from controllers.law_algebra import rank_screen

    threshold = 1e-6
    mats, conditions = [], []
    for _ in range(600):
        Q, _ = np.linalg.qr(rng.normal(size=(6, 6)))
        cond = 10.0 ** rng.uniform(0.0, 7.5)  # singular values of L: 1 down to 1 / cond
        s = np.geomspace(1.0, 1.0 / cond, 6) * 10.0 ** rng.uniform(-3, 3)
        L = (Q * s) @ np.linalg.qr(rng.normal(size=(6, 6)))[0]
        mats.append(L.T @ L)
        conditions.append(cond)
    M = np.array(mats)
    M[5] = 0.0
    M[4, 2, 3] = M[4, 3, 2] = np.nan
    F = ca.SX.sym("F", 6, 6)
    screen_of = ca.Function("screen", [F], [rank_screen(F)])
    Y = np.zeros((len(M), 39))  # status 0, then the screen, then L^T L
    Y[:, 1:3] = [np.asarray(screen_of(m)).ravel() for m in M]
    Y[:, 3:] = M.reshape(len(M), 36)
    det, trace = Y[:, 1], Y[:, 2]
    with np.errstate(invalid="ignore", over="ignore"):
        clear = (trace > 0) & (det > 4.0 * threshold**2 * trace**6)
    exact = np.array([rank_condition(m.ravel(), threshold) is not None for m in M])
    assert not (clear & ~exact).any()
    assert clear[6:][np.array(conditions[6:]) < 10.0].all()
    assert not clear[4] and not clear[5]
    assert exact.sum() > clear.sum() > 100  # both kinds of rows met


def test_the_norms_of_many_rows_are_each_rows_dot(rng: np.random.Generator) -> None:
    from controllers.ctc_rows import norms

    for m in (6, 18, 36):
        e = rng.normal(size=(300, m)) * rng.uniform(1e-6, 1.0, (300, 1))
        got = norms(e)
        assert [float(x) for x in got] == [float(v.dot(v)) for v in e]
