"""What the computed-torque laws command over the drives' force limit
(:mod:`controllers.solvers.saturation`): the hand-made cases, and the laws with each
strategy against their own unsaturated forces.

The hand-made force vector is over the 200 N limit on two legs, ``f = (250, -230, 100,
50, 0, -20)`` N:

- clip: ``(200, -200, 100, 50, 0, -20)`` (each leg on its own);
- scale: ``s = min(200/250, 200/230) = 0.8``: ``(200, -184, 80, 40, 0, -16)``;
- qp with the forces at zero acceleration ``f_0 = (50, 0, 30, 20, 10, 0)``: leg 0 allows
  ``s <= (200 - 50) / 200 = 0.75``, leg 1 ``s <= 200 / 230``: ``s = 0.75``,
  ``f_0 + s (f - f_0) = (200, -172.5, 82.5, 42.5, 2.5, -15)``, and the same ``s`` from
  ``scipy.optimize.linprog`` (an independent solver of the one-variable problem).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.optimize import linprog

from controllers import registry
from controllers.base import ControllerContext, ObservationBatch
from controllers.exceptions import OptionError
from controllers.solvers.saturation import (
    acceleration_fraction,
    saturated,
    zero_acceleration_forces,
)
from hexapod import HexapodGeometry
from hexapod.se3 import exp_so3
from hexapod.workspace import home_pose
from tests.controllers.ctc_world import DT, CtcWorld, ideal_drives

F = np.array([250.0, -230.0, 100.0, 50.0, 0.0, -20.0])
F0 = np.array([50.0, 0.0, 30.0, 20.0, 10.0, 0.0])
LIMIT = np.full(6, 200.0)
LAWS = ("computed-torque", "cartesian-ctc", "vision-ctc", "leg-edge-ctc",
        "leg-direction-ctc")


def _linprog_fraction(f: np.ndarray, f0: np.ndarray, limit: np.ndarray) -> float:
    """The largest s in [0, 1] with |f0 + s (f - f0)| <= limit, by linear programming."""
    g = f - f0
    res = linprog(c=[-1.0], A_ub=np.concatenate([g, -g])[:, None],
                  b_ub=np.concatenate([limit - f0, limit + f0]), bounds=[(0.0, 1.0)])
    assert res.status == 0
    return float(res.x[0])


def test_the_hand_made_case() -> None:
    assert saturated("clip", F, LIMIT).tolist() == [200, -200, 100, 50, 0, -20]
    assert saturated("scale", F, LIMIT) == pytest.approx([200, -184, 80, 40, 0, -16],
                                                         abs=1e-12)
    assert acceleration_fraction(F, F0, LIMIT) == pytest.approx(0.75, abs=1e-15)
    assert _linprog_fraction(F, F0, LIMIT) == pytest.approx(0.75, abs=1e-9)
    assert saturated("qp", F, LIMIT, F0) == pytest.approx(
        [200, -172.5, 82.5, 42.5, 2.5, -15], abs=1e-12)


def test_under_the_limit_nothing_changes() -> None:
    f = np.array([199.0, -199.0, 0.0, 1.0, -1.0, 5.0])
    for strategy in ("clip", "scale", "qp"):
        assert saturated(strategy, f, LIMIT, F0) is f


def test_qp_clips_when_the_bias_alone_is_over() -> None:
    bias = np.array([210.0, 0, 0, 0, 0, 0])
    assert acceleration_fraction(F, bias, LIMIT) is None
    assert saturated("qp", F, LIMIT, bias).tolist() == [200, -200, 100, 50, 0, -20]


@pytest.mark.parametrize("seed", range(5))
def test_qp_against_linprog_on_random_cases(seed: int) -> None:
    rng = np.random.default_rng(seed)
    limit = rng.uniform(50, 200, 6)
    f0 = rng.uniform(-0.5, 0.5, 6) * limit
    f = rng.normal(0, 300, 6)
    s = acceleration_fraction(f, f0, limit)
    assert s == pytest.approx(_linprog_fraction(f, f0, limit), abs=1e-9)
    out = saturated("qp", f, limit, f0)
    assert np.all(np.abs(out) <= limit + 1e-12)


def test_an_unknown_strategy_is_named() -> None:
    with pytest.raises(OptionError, match=r"saturation.*'clip', 'scale', 'qp'.*'box'"):
        registry.create("computed-torque", saturation="box")


def _world(geometry: HexapodGeometry, limit: float) -> tuple[CtcWorld, ControllerContext]:
    """A step to a goal 15 mm away (no smooth goal: the forces are large), the nominal
    drives' limit ``limit`` [N]."""
    truth = ideal_drives(geometry)
    nominal = dataclasses.replace(truth, drives=dataclasses.replace(
        truth.drives, force_limit=np.full(6, limit)))
    world = CtcWorld.make(truth, nominal)
    R0, t0 = home_pose(truth)
    goal = world.goal(R0 @ exp_so3(np.array([0.02, -0.01, 0.015])),
                      t0 + np.array([0.015, -0.01, 0.008]))
    return world, world.context(goal)


@pytest.mark.slow
@pytest.mark.parametrize("name", LAWS)
def test_each_strategy_on_a_law(geometry: HexapodGeometry, name: str) -> None:
    """The law's forces with each strategy against its unsaturated forces (the second
    step, the compiled one, per trial and over a batch of two), the limit set between
    the second and the third largest force (two legs over it)."""
    from hexapod.dynamics import DynamicModel
    from hexapod.dynamics.robots import DynamicRobots

    world, free_ctx = _world(geometry, 1e9)
    R0, t0 = home_pose(world.truth)
    robot = DynamicRobots([world.truth], R0[None].copy(), t0[None].copy())
    obs = [world.observation(robot, 0.0), world.observation(robot, DT)]
    free = registry.create(name, smooth_goal=False)
    free.reset(free_ctx)
    free.step(obs[0])
    raw = np.asarray(free.step(obs[1]).forces)
    if name == "computed-torque":
        R, t = free._pose
    else:
        assert free.guess is not None  # the pose of its last step
        R, t = free.guess
    big = np.sort(np.abs(raw))
    limit = 0.5 * (big[-2] + big[-3])
    _, ctx = _world(geometry, limit)
    lim = np.full(6, limit)
    assert (np.abs(raw) > lim).sum() == 2
    f0 = zero_acceleration_forces(DynamicModel(ctx.geometry), np.concatenate([R.T.ravel(), t]),
                                  obs[1].q_dot, np.zeros(6) if name == "computed-torque"
                                  else None, 0.0 if name == "computed-torque" else DT)
    assert np.all(np.abs(f0) < lim), "the case must leave the bias under the limit"
    for strategy in ("clip", "scale", "qp"):
        law = registry.create(name, smooth_goal=False, saturation=strategy)
        law.reset(ctx)
        law.step(obs[0])
        got = np.asarray(law.step(obs[1]).forces)
        batch = registry.create(name, smooth_goal=False, saturation=strategy)
        batch.reset_batch([ctx, ctx])
        two = [dataclasses.replace(ObservationBatch.of(o).rows(np.array([0, 0])),
                                   trials=np.array([0, 1])) for o in obs]
        batch.step_batch(two[0])
        rows = batch.step_batch(two[1])
        assert rows.forces is not None
        assert rows.forces[0].tobytes() == got.tobytes() == rows.forces[1].tobytes()
        assert np.all(np.abs(got) <= lim * (1 + 1e-12))
        if strategy == "clip":
            assert got.tolist() == np.clip(raw, -lim, lim).tolist()
        elif strategy == "scale":
            assert got == pytest.approx(raw * np.min(lim / np.abs(raw)), rel=1e-12)
        else:
            s = _linprog_fraction(raw, f0, lim)
            assert 0.0 < s < 1.0
            assert got == pytest.approx(f0 + s * (raw - f0), rel=1e-7, abs=1e-9)
