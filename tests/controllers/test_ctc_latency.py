"""Latency compensation of the vision computed-torque laws (``latency-compensated`` with
``law = "vision-ctc"`` / ``"leg-edge-ctc"``): on the dynamic world, with an exact model, an
image one period old predicted to the control instant gives the command of the image
taken at the instant; without the prediction the command differs."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from controllers import registry
from controllers.latency import LatencyCompensated
from hexapod import HexapodGeometry
from hexapod.actuation import Actuation
from hexapod.dynamics.robots import DynamicRobots
from hexapod.workspace import home_pose
from tests.controllers.ctc_world import DT, PHYSICS_STEPS, CtcWorld, ideal_drives, line_reference


@pytest.mark.parametrize("law", ["vision-ctc", "leg-edge-ctc", "leg-direction-ctc"])
def test_an_old_image_predicted_with_an_exact_model(geometry: HexapodGeometry,
                                                    law: str) -> None:
    world = CtcWorld.make(ideal_drives(geometry))
    R0, t0 = home_pose(world.truth)
    ctx = world.context(world.goal(R0, t0 + np.array([0.004, -0.003, 0.002])))
    comp = LatencyCompensated(law=law)
    assert comp.actuation is Actuation.FORCE
    plain, late_law = registry.create(law), registry.create(law)
    for c in (comp, plain, late_law):
        c.reset(ctx)
    robot = DynamicRobots([world.truth], R0[None].copy(), t0[None].copy())
    robot.drives.mode = "force"
    rows = np.arange(1)
    previous = None
    for k in range(12):
        now = world.observation(robot, k * DT)
        expected = plain.step(now)
        if previous is None:
            got = comp.step(now)
            late_law.step(now)
        else:
            late = replace(now, normals=previous.normals, directions=previous.directions,
                           image_t=previous.t)
            got = comp.step(late)
            stale = late_law.step(late)
            assert got.reason is None and expected.reason is None, (got.reason,
                                                                    expected.reason)
            np.testing.assert_allclose(got.forces, expected.forces, rtol=1e-6, atol=1e-6)
            if k > 2:  # moving: the stale image gives other forces
                assert np.abs(stale.forces - expected.forces).max() > 1e-3
        robot.advance(rows, np.asarray(expected.forces)[None], DT / PHYSICS_STEPS,
                      PHYSICS_STEPS)
        previous = now


def test_an_image_between_readings_uses_the_leg_rates(geometry: HexapodGeometry) -> None:
    """An image taken half a period before the instant, while the legs accelerate: the
    lengths at its time interpolated with the measured rates (cubic Hermite) predict it
    far better than the linear interpolation (the kinematic world's exact one). (The
    drives' speed limit out of reach: holding a leg to it would bend the smooth motion
    the interpolation is judged on.)"""
    world = CtcWorld.make(ideal_drives(geometry).replace(max_speed=10.0))
    R0, t0 = home_pose(world.truth)
    ctx = world.context(world.goal(R0, t0 + np.array([0.006, -0.004, 0.003])))
    laws = {"plain": registry.create("vision-ctc"),
            "hermite": LatencyCompensated(law="vision-ctc"),
            "linear": LatencyCompensated(law="vision-ctc", use_rates=False)}
    for c in laws.values():
        c.reset(ctx)
    robot = DynamicRobots([world.truth], R0[None].copy(), t0[None].copy())
    robot.drives.mode = "force"
    rows = np.arange(1)
    half = PHYSICS_STEPS // 2
    gaps: dict[str, list[float]] = {"hermite": [], "linear": []}
    mid = None
    for k in range(30):
        now = world.observation(robot, k * DT)
        expected = laws["plain"].step(now)
        for key in gaps:
            obs = now if mid is None else replace(now, directions=mid.directions,
                                                  normals=mid.normals, image_t=mid.t)
            got = laws[key].step(obs)
            assert got.reason is None, got.reason
            if mid is not None:
                gaps[key].append(float(np.abs(got.forces - expected.forces).max()))
        f = np.asarray(expected.forces)[None]
        robot.advance(rows, f, DT / PHYSICS_STEPS, half)
        mid = world.observation(robot, (k + 0.5) * DT)
        robot.advance(rows, f, DT / PHYSICS_STEPS, PHYSICS_STEPS - half)
    hermite, linear = max(gaps["hermite"]), max(gaps["linear"])
    assert linear > 1e-3  # the linear interpolation misses the acceleration
    assert hermite < 0.01 * linear, (hermite, linear)  # measured: 1.6e-5 N, 0.026 N


def test_the_tracking_wrapper_passes_the_compensated_law_through(
        geometry: HexapodGeometry) -> None:
    """``latency-compensated`` around a CTC law samples the reference like the law (the
    study's tracking wrapper resets it with the taught goal, never retargets it): it
    tracks a line as the bare law does."""
    import math

    from controllers.tracking import TrackingController

    world = CtcWorld.make(ideal_drives(geometry))
    R0, t0, R1, t1, ref = line_reference(world.truth, "quintic", (1.0, -1.0, 0.5))
    ctrl = TrackingController(LatencyCompensated(law="leg-edge-ctc"))
    assert ctrl.inner.tracks_reference
    ctrl.reset(world.context(world.goal(R1, t1), ref))
    steps = math.ceil(ref.duration / DT) + 25
    p, _, _ = world.run(ctrl, (R0, t0), steps)
    err = np.linalg.norm(p - ref.at(DT * np.arange(steps + 1)).translation, axis=1)
    assert err.max() < 30e-6 and err[-1] < 2e-6, (err.max(), err[-1])
