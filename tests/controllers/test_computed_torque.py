"""``computed-torque`` on the dynamic world (a perfect model, no noise).

The world is :class:`hexapod.dynamics.robots.DynamicRobots` (the study's dynamic world's
integrator, force-mode drives) whose drives have no friction (a force held over the period
against a velocity-dependent friction is not a model error the law can cancel); their
rotor inertia is kept (it is in the nominal model). The response is measured from the
simulated lengths and compared with the design, and with the design sampled with a
zero-order hold (the exact discretisation of the linear error dynamics, eigenvalues of the
sampled closed loop), never with the controller's formula.
"""

from __future__ import annotations

import dataclasses
import math
from typing import ClassVar

import numpy as np
import pytest
from scipy.optimize import curve_fit

from controllers import registry
from controllers.base import ControllerContext, Goal, Observation
from controllers.computed_torque import ComputedTorqueController
from controllers.data import CommandBatch, ObservationBatch
from hexapod import HexapodGeometry
from hexapod.actuation import Actuation
from hexapod.dynamics.robots import DynamicRobots
from hexapod.trajectory import PoseTrajectory
from hexapod.workspace import home_pose

DT = 0.02
PHYSICS_STEPS = 20


def _ideal_drives(g: HexapodGeometry) -> HexapodGeometry:
    return dataclasses.replace(g, drives=dataclasses.replace(
        g.drives, viscous=np.zeros(6), coulomb=np.zeros(6)))


def _simulate(g: HexapodGeometry, ctrl: ComputedTorqueController, steps: int
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Lengths (steps, 6), forces (steps, 6) and poses' translations (steps, 3)."""
    R0, t0 = home_pose(g)
    R, t = R0[None].copy(), t0[None].copy()
    robot = DynamicRobots([g], R, t)
    robot.drives.mode = "force"
    rows = np.arange(1)
    qs, fs, ps = [], [], []
    for k in range(steps):
        q = robot.lengths(rows)[0]
        rates, _ = robot.model.legs_batch(robot.R, robot.t, robot.twist)
        cmd = ctrl.step(Observation(t=k * DT, lengths=q, q_dot=rates[0]))
        assert cmd.reason is None, cmd.reason
        assert cmd.actuation is Actuation.FORCE
        qs.append(q)
        fs.append(cmd.forces)
        ps.append(robot.t[0].copy())
        assert not robot.advance(rows, np.asarray(cmd.forces)[None], DT / PHYSICS_STEPS,
                                 PHYSICS_STEPS).any()
    return np.array(qs), np.array(fs), np.array(ps)


def _context(g: HexapodGeometry, goal_lengths: np.ndarray | None = None,
             reference: object = None) -> ControllerContext:
    return ControllerContext(base_points=g.base_points, geometry=g, camera=None, dt=DT,
                             goal=Goal(lengths=goal_lengths), reference=reference)


def _step_response(t: np.ndarray, omega: float, zeta: float) -> np.ndarray:
    """Error of a unit step from rest: ``e(0) = -1``, ``e_dot(0) = 0``."""
    wd = omega * math.sqrt(1 - zeta**2)
    return -np.exp(-zeta * omega * t) * (np.cos(wd * t)  # type: ignore[no-any-return]
                                         + zeta / math.sqrt(1 - zeta**2) * np.sin(wd * t))


def _sampled_design(omega: float, zeta: float) -> tuple[float, float]:
    """Natural frequency and damping of the design held over ``DT`` (zero-order hold)."""
    A = np.array([[1.0, DT], [0.0, 1.0]])
    B = np.array([[DT**2 / 2], [DT]])
    poles = np.linalg.eigvals(A - B @ np.array([[omega**2, 2 * zeta * omega]]))
    s = np.log(poles.astype(complex)) / DT
    return float(abs(s[0])), float(-s[0].real / abs(s[0]))


def test_registered_as_a_force_controller() -> None:
    ctrl = registry.create("computed-torque")
    assert isinstance(ctrl, ComputedTorqueController)
    assert ctrl.actuation is Actuation.FORCE


def test_step_in_leg_space_is_the_designed_second_order(geometry: HexapodGeometry) -> None:
    g = _ideal_drives(geometry)
    fn, zeta = 2.0, 0.3
    R0, t0 = home_pose(g)
    q0 = DynamicRobots([g], R0[None].copy(), t0[None].copy()).lengths(np.arange(1))[0]
    step = np.array([1.0, -1.0, 0.5, -0.5, 0.8, -0.2]) * 1e-3
    ctrl = ComputedTorqueController(natural_frequency=fn, damping=zeta, smooth_goal=False)
    ctrl.reset(_context(g, q0 + step))
    q, f, _ = _simulate(g, ctrl, 100)
    assert np.all(np.isfinite(f))
    e = (q - q0 - step) / step  # every leg's normalised error, -1 at t = 0
    t = DT * np.arange(len(e))
    omega = 2 * math.pi * fn
    (w_fit, z_fit), _ = curve_fit(_step_response, np.tile(t, 6), e.T.ravel(),
                                  p0=(omega, zeta))
    residual = np.abs(e - _step_response(t, w_fit, z_fit)[:, None]).max()
    assert residual < 0.02, residual  # a second-order response, the same for every leg
    w_zoh, z_zoh = _sampled_design(omega, zeta)  # 1.035 omega, 0.244
    assert w_fit == pytest.approx(w_zoh, rel=0.02)
    assert z_fit == pytest.approx(z_zoh, abs=0.02)
    # and the continuous design within what the 20 ms hold shifts (omega_n dt = 0.25)
    assert w_fit == pytest.approx(omega, rel=0.06)
    assert z_fit == pytest.approx(zeta, abs=0.08)
    overshoot = e.max()  # sampled peak of the first overshoot
    assert overshoot == pytest.approx(math.exp(-math.pi * z_zoh / math.sqrt(1 - z_zoh**2)),
                                      abs=0.03)


def test_tracks_a_slow_trajectory(geometry: HexapodGeometry) -> None:
    g = _ideal_drives(geometry)
    R0, t0 = home_pose(g)
    ref = PoseTrajectory("circle", "quintic", R0, t0, speed=0.005, acceleration=0.01,
                         radius=0.01, plane="xy")
    ctrl = ComputedTorqueController()  # the defaults: 2 Hz, zeta 1
    ctrl.reset(_context(g, reference=ref))
    steps = math.ceil(ref.duration / DT) + 25
    _, f, p = _simulate(g, ctrl, steps)
    assert np.all(np.isfinite(f))
    p_ref = ref.at(DT * np.arange(steps)).translation
    err = np.linalg.norm(p - p_ref, axis=1)
    assert np.abs(p_ref - t0).max() > 0.009  # it went round the 10 mm circle
    assert err.max() < 20e-6, err.max()  # 20 um along a 10 mm circle at 5 mm/s
    assert err[-1] < 2e-6


def test_nan_lengths_are_refused_with_a_reason(geometry: HexapodGeometry) -> None:
    g = geometry
    R0, t0 = home_pose(g)
    q0 = DynamicRobots([g], R0[None].copy(), t0[None].copy()).lengths(np.arange(1))[0]
    ctrl = ComputedTorqueController()
    ctrl.reset(_context(g, q0))
    bad = q0.copy()
    bad[2] = np.nan
    cmd = ctrl.step(Observation(t=0.0, lengths=bad, q_dot=np.zeros(6)))
    assert cmd.reason is not None and "lengths not finite" in cmd.reason
    assert cmd.actuation is Actuation.FORCE
    np.testing.assert_array_equal(cmd.values, np.zeros(6))
    cmd = ctrl.step(Observation(t=0.0, lengths=q0, q_dot=None))
    assert cmd.reason is not None and "q_dot" in cmd.reason
    velocities = np.zeros(6)
    velocities[4] = np.inf
    cmd = ctrl.step(Observation(t=0.0, lengths=q0, q_dot=velocities))
    assert cmd.reason is not None and "leg velocities not finite" in cmd.reason
    assert np.all(np.isfinite(cmd.values))


@pytest.mark.slow
@pytest.mark.parametrize("engine", ["batched", "per-trial"])
def test_the_study_worlds_apply_or_refuse_it(engine: str) -> None:
    from benchmarks.sim import run_trials
    from benchmarks.study.scenario import ControllerSpec, load_scenario
    from benchmarks.study.scenario_model import CalibrationErrorConfig

    spec = (ControllerSpec("computed-torque", "ctc"),)
    # quick-dynamic's robot and random pose pairs, without calibration error (joint-space
    # control cannot see a pose error the encoders do not measure)
    dynamic = dataclasses.replace(load_scenario("quick-dynamic").with_overrides(trials=2),
                                  controllers=spec, calibration_error=CalibrationErrorConfig())
    rows = [r.row for r in run_trials(dynamic.expand()[0], 0, [0, 1], engine=engine)]
    for row in rows:
        assert row["failure"] is None, row["failure"]
        assert row["converged"] is True
        assert 0.0 < row["max_leg_force_n"] < 200.0  # below the drives' limit
    kinematic = dataclasses.replace(load_scenario("quick").with_overrides(trials=1),
                                    controllers=spec)
    row = run_trials(kinematic.expand()[0], 0, [0], engine=engine)[0].row
    assert row["converged"] is False and row["steps"] == 0
    assert row["failure"].startswith("ActuationError")
    assert ("controller 'ctc' commands leg forces [N], but the kinematic world applies only "
            "leg velocities [m/s]") in row["failure"]


class RecordingSprings(ComputedTorqueController):
    """computed-torque keeping what it observed (every instance appends here)."""

    seen: ClassVar[list[Observation]] = []

    def step_batch(self, observations: ObservationBatch) -> CommandBatch:
        RecordingSprings.seen.extend(observations.item(j) for j in range(len(observations)))
        return super().step_batch(observations)


@pytest.mark.slow
def test_the_dynamic_world_measures_leg_velocities() -> None:
    """``q_dot`` is the leg rate the encoders see: it agrees with the change of the
    measured lengths over the period (their mean over the period, to the velocity's
    change within it and one count of quantisation)."""
    from benchmarks.sim import run_trials
    from benchmarks.study.scenario import ControllerSpec, load_scenario

    RecordingSprings.seen = []
    spec = (ControllerSpec("tests.controllers.test_computed_torque:RecordingSprings", "rec"),)
    sc = dataclasses.replace(load_scenario("quick-dynamic").with_overrides(trials=1),
                             controllers=spec)
    run_trials(sc.expand()[0], 0, [0], engine="per-trial")
    obs = RecordingSprings.seen[:60]
    q = np.array([o.lengths for o in obs])
    qd = np.array([o.q_dot for o in obs])
    dt = sc.dt
    mean_rate = (q[1:] - q[:-1]) / dt  # the average rate over each period
    between = (qd[1:] + qd[:-1]) / 2  # trapezoid of the sampled rates
    assert np.abs(qd).max() > 0.01  # the legs moved (over 10 mm/s)
    assert np.abs(mean_rate - between).max() < 0.02 * np.abs(qd).max() + 2e-6 / dt
    # quantised to one encoder count per period (1 um / 20 ms)
    counts = qd * dt / 1e-6
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-6)


def test_a_batchs_reference_grids_are_each_trials_own(geometry: HexapodGeometry) -> None:
    """reset_batch samples every trial's reference grid together (sample_grids, by
    chunks of CHUNK trials): each grid holds the numbers of its trial's own
    evaluation (reference_legs on its control grid), to the last bit."""
    from controllers.control_grid import CHUNK
    from tests.controllers.ctc_world import CtcWorld, ideal_drives, line_reference

    truth = ideal_drives(geometry)
    world = CtcWorld.make(truth)
    n = CHUNK + 3  # two chunks
    contexts = []
    for k in range(n):  # a reference of its own per trial, of its own duration
        _, _, R1, t1, ref = line_reference(truth, "quintic", (0.5 + 0.2 * k, -0.3, 0.4))
        contexts.append(world.context(world.goal(R1, t1), reference=ref))
    batch = registry.create("computed-torque")
    batch.reset_batch(contexts)
    sizes = set()
    for inst in batch.trial_instances:
        assert isinstance(inst, ComputedTorqueController) and inst._grid is not None
        own = inst.reference_legs(inst.grid_times()).reshape(-1, 18)
        assert inst.grid.tobytes() == own.tobytes()
        sizes.add(len(own))
    assert len(sizes) > 1  # grids of several lengths, stacked and split again
