"""A feature added as a plugin (``tests/controllers/plugin_feature_joints.py``: the platform
joints ``B_i = A_i + q_i u_i`` in the camera frame, one file) gets the pseudo-inverse, QP,
MPC and computed-torque controllers (:func:`controllers.features.controllers_for`), each
stepping through a kernel compiled to C from the feature's own expression.

Oracles: the true kinematics of the test worlds (the joints' motion under a twist, the
closed loops' true poses), never the feature's derivative formulas.
"""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np
import pytest

from controllers import registry
from controllers.base import ObservationBatch
from controllers.exceptions import ContextError, OptionError
from controllers.features import FeatureTask, LegFeature, controllers_for
from controllers.law_kernel import LawKernel
from controllers.law_rows import ACCEPTED, REJECTED, LawRows
from controllers.tasks import TaskState
from hexapod import HexapodGeometry
from hexapod.actuation import Actuation
from hexapod.compiled import CompiledFunction
from hexapod.se3 import exp_so3, pose_error
from hexapod.workspace import home_pose
from tests.controllers.controller_world import World, closed_loop, make_camera
from tests.controllers.ctc_world import (
    DT,
    CtcWorld,
    assert_tracks_the_rotated_line,
    ideal_drives,
)
from tests.controllers.plugin_feature_joints import JOINTS, PlatformJoints
from tests.controllers.task_ctc_oracles import numpy_law_step

PLUGIN = "tests.controllers.plugin_feature_joints"


@pytest.fixture
def world(geometry: HexapodGeometry) -> World:
    return World(geometry, make_camera("perspective", geometry))


def _goal_pose(geometry: HexapodGeometry) -> tuple[np.ndarray, np.ndarray]:
    R0, t0 = home_pose(geometry)
    return R0 @ exp_so3(np.deg2rad([2.0, -1.5, 1.0])), t0 + np.array([0.01, -0.008, 0.006])


@pytest.mark.slow
def test_one_file_gives_four_controllers_by_module_path() -> None:
    """The plugin file alone names the four controllers; the registry builds them from
    their ``module:attr`` path like any plugin (slow: the registry looks up the
    distribution of a module named on the command line, about 2 s)."""
    names = {c.name for c in JOINTS.all()}
    assert names == {"platform-joint-pinv", "platform-joint-qp", "platform-joint-mpc",
                     "platform-joint-ctc"}
    for attr, actuation in (("PlatformJointPinv", Actuation.VELOCITY),
                            ("PlatformJointQP", Actuation.VELOCITY),
                            ("PlatformJointMPC", Actuation.VELOCITY),
                            ("PlatformJointCTC", Actuation.FORCE)):
        ctrl = registry.create(f"{PLUGIN}:{attr}")
        assert ctrl.actuation is actuation
        assert isinstance(ctrl.feature if attr != "PlatformJointMPC" else ctrl.law.feature,
                          PlatformJoints)


def test_interaction_is_the_joints_true_motion(world: World) -> None:
    """``L tau`` of the feature's task is the true velocity of the joints seen in the camera
    (finite differences of the true legs moved by the twist)."""
    R, t = _goal_pose(world.geometry)
    legs = world.legs(R, t)
    state = TaskState(legs.base_points[None], legs.directions[None], legs.lengths[None])
    task = FeatureTask(PlatformJoints(), np.zeros((6, 3)))
    rng = np.random.default_rng(3)
    for _ in range(3):
        tau = rng.normal(size=6) * np.array([0.01, 0.01, 0.01, 0.05, 0.05, 0.05])
        h = 1e-6
        Rp, tp = world.move(R, t, tau, h)
        Rm, tm = world.move(R, t, tau, -h)
        joints = [(lg.base_points + lg.lengths[:, None] * lg.directions).ravel()
                  for lg in (world.legs(Rp, tp), world.legs(Rm, tm))]
        true_rate = (joints[0] - joints[1]) / (2 * h)
        np.testing.assert_allclose(task.jacobian(state)[0] @ tau, true_rate, atol=1e-9)
        # and the error is the joints' offset from the desired ones (zeros here)
        B = legs.base_points + legs.lengths[:, None] * legs.directions
        np.testing.assert_allclose(task.error(state)[0], B.ravel(), atol=1e-15)


def _count_kernel_calls(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Count the compiled core's calls: by the laws' Python, and by the batch's C (a row
    it evaluated: accepted or rejected)."""
    calls = [0]
    evaluate = LawKernel.evaluate
    step = LawRows.step

    def counted(self: LawKernel):  # type: ignore[no-untyped-def]
        calls[0] += 1
        return evaluate(self)

    def counted_rows(self: LawRows, *args: Any) -> tuple[np.ndarray, np.ndarray]:
        code, Y = step(self, *args)
        calls[0] += int(np.count_nonzero((code == ACCEPTED) | (code == REJECTED)))
        return code, Y

    monkeypatch.setattr(LawKernel, "evaluate", counted)
    monkeypatch.setattr(LawRows, "step", counted_rows)
    return calls


@pytest.mark.parametrize("which", ["pinv", "qp", "mpc"])
def test_first_order_controllers_converge_through_the_compiled_core(
        world: World, which: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """From home to a goal 14 mm and 2.7 degrees away: the true position error falls below
    10 um in 200 periods, every step through the feature's compiled core (the MPC through
    the compiled local problem, never falling back)."""
    cls = getattr(JOINTS, which)
    ctrl = cls(gain=2.0)  # (the MPC: horizon 10, the compiled problem of leg-direction-mpc)
    R1, t1 = _goal_pose(world.geometry)
    ctrl.reset(world.context(world.goal(R1, t1), 0.02))
    law = ctrl.law if which == "mpc" else ctrl
    kernel = law.kernel
    assert isinstance(kernel.function, CompiledFunction) and kernel.function.compiled
    assert kernel.function.name == "hexapod_platform_joint_law"
    calls = _count_kernel_calls(monkeypatch)
    run = closed_loop(world, ctrl, home_pose(world.geometry), (R1, t1), 0.02, 200)
    assert run.position_errors[0] > 0.014
    assert run.position_errors[-1] < 10e-6, run.position_errors[-1]
    assert run.error_norms[-1] < 0.01 * run.error_norms[0]
    assert calls[0] == 200  # one compiled call per step
    if which == "mpc":
        assert ctrl._kernel.compiled and ctrl.stats.steps == 200
        assert ctrl.stats.fallbacks == 0


def test_batch_rows_equal_the_trials_own_steps(world: World) -> None:
    """A batch of trials (the lean compiled core over the rows in C) commands what each
    trial's own step commands."""
    g = world.geometry
    R1, t1 = _goal_pose(g)
    ctx = world.context(world.goal(R1, t1), 0.02)
    Rs, ts = world.poses(4, np.random.default_rng(5))
    obs = [dataclasses.replace(world.observation(R, t), t=0.0) for R, t in zip(Rs, ts,
                                                                              strict=True)]
    batch_ctrl = JOINTS.pinv(gain=2.0)
    batch_ctrl.reset_batch([ctx] * 4)
    batch = ObservationBatch(
        trials=np.arange(4), t=np.zeros(4), lengths=np.stack([o.lengths for o in obs]),
        normals=None, lines=None, directions=np.stack([o.directions for o in obs]),
        edge_visible=np.ones((4, 6, 2), bool), direction_visible=np.ones((4, 6), bool))
    out = batch_ctrl.step_batch(batch)
    assert False in batch_ctrl._core_rows.functions  # the rows went through the lean core
    for k, o in enumerate(obs):
        one = JOINTS.pinv(gain=2.0)
        one.reset(ctx)
        cmd = one.step(o)
        np.testing.assert_allclose(out.command(k).velocities, cmd.velocities, rtol=1e-12,
                                   atol=1e-15)


def test_bad_goal_and_options_are_named(world: World) -> None:
    R1, t1 = _goal_pose(world.geometry)
    goal = world.goal(R1, t1)
    ctrl = JOINTS.pinv()
    with pytest.raises(ContextError, match=r"goal\.lengths"):
        ctrl.reset(world.context(dataclasses.replace(goal, lengths=None), 0.02))
    with pytest.raises(ContextError, match=r"goal\.directions"):
        ctrl.reset(world.context(dataclasses.replace(goal, directions=None), 0.02))
    with pytest.raises(OptionError, match="model"):
        JOINTS.mpc(model="global")
    with pytest.raises(OptionError, match="interaction"):
        JOINTS.qp(interaction="sideways")
    with pytest.raises(ContextError, match=r"goal\.lengths"):
        JOINTS.ctc().reset(world.context(dataclasses.replace(goal, lengths=None), 0.02))


@pytest.fixture
def ctc_world(geometry: HexapodGeometry) -> CtcWorld:
    return CtcWorld.make(ideal_drives(geometry))


@pytest.mark.parametrize("smooth", [False, True])
def test_computed_torque_converges_through_its_compiled_step(ctc_world: CtcWorld,
                                                             smooth: bool) -> None:
    """On the dynamic world (forces, perfect model): a 2.7 mm goal reached to 1 um within
    150 periods, a step or along the quintic line; every step by the feature's compiled
    step (the first one starts the reference at the pose it measures)."""
    R0, t0 = home_pose(ctc_world.truth)
    step = np.array([0.002, -0.001, 0.0015])
    ctrl = JOINTS.ctc(smooth_goal=smooth)
    ctrl.reset(ctc_world.context(ctc_world.goal(R0, t0 + step)))
    assert ctrl.compiled is not None and ctrl.compiled.function.compiled
    assert ctrl.compiled.function.name == "hexapod_ctc_platform_joint_step"
    p, _, cmds = ctc_world.run(ctrl, (R0, t0), 150)
    err = np.linalg.norm(p - (t0 + step), axis=1)
    assert err[-1] < 1e-6, err[-1]
    assert ctrl.compiled_steps == 150
    assert all(np.all(np.isfinite(c.forces)) for c in cmds)


@pytest.mark.parametrize("ki", [0.0, 5.0])
def test_computed_torque_compiled_step_equals_the_numpy_task(ctc_world: CtcWorld,
                                                             ki: float) -> None:
    """The compiled step's forces are the numpy oracle's (``task_ctc_oracles.py``: the
    feature's :class:`FeatureTask`, evaluated by CasADi's virtual machine) to rounding,
    from the first step (the line started at the pose each measures), on a moving
    reference (the smooth line: the reference terms ``e_t``, ``e_tt`` in play), with and
    without integral action (the step's ``integral`` input block)."""
    R0, t0 = home_pose(ctc_world.truth)
    goal = ctc_world.goal(R0, t0 + np.array([0.003, 0.001, -0.002]))
    fast, slow = JOINTS.ctc(integral_gain=ki), JOINTS.ctc(integral_gain=ki)
    fast.reset(ctc_world.context(goal))
    slow.reset(ctc_world.context(goal))
    from hexapod.dynamics.robots import DynamicRobots

    robot = DynamicRobots([ctc_world.truth], R0[None].copy(), t0[None].copy())
    robot.drives.mode = "force"
    rows = np.arange(1)
    for k in range(20):
        obs = ctc_world.observation(robot, k * DT)
        a, b = fast.step(obs), numpy_law_step(slow, obs)
        assert a.reason is None and b.reason is None
        np.testing.assert_allclose(a.forces, b.forces, rtol=1e-8, atol=1e-9)
        robot.advance(rows, np.asarray(a.forces)[None], DT / 10, 10)
    assert fast.compiled_steps == 20 and slow.compiled_steps == 0
    assert bool(np.any(fast.integral != 0.0)) is bool(ki)
    if ki:  # (without integral action the oracle never sizes its integral)
        np.testing.assert_allclose(fast.integral, slow.integral, rtol=1e-8, atol=1e-12)
    else:
        assert not np.any(slow.integral)


def _heavy_world(truth: HexapodGeometry) -> CtcWorld:
    """The nominal platform 30 % too heavy (as ``test_ctc_integral.py``)."""
    return CtcWorld.make(truth, dataclasses.replace(truth, inertia=dataclasses.replace(
        truth.inertia, platform_mass=1.3 * truth.inertia.platform_mass)))


def test_computed_torque_integral_action_removes_a_model_error_offset(
        geometry: HexapodGeometry) -> None:
    """``integral_gain`` on the plugin's computed torque, as on the built-ins
    (``test_ctc_integral.py``): the nominal platform 30 % too heavy leaves the law a
    static error (measured 2.47 mm after 3 s); with ``Ki = 5 1/s`` after the same 3 s,
    less than a hundredth of it (measured 0.68 um), every step by the feature's compiled
    step."""
    truth = ideal_drives(geometry)
    R0, t0 = home_pose(truth)
    Rg, tg = R0 @ exp_so3(np.array([0.02, -0.01, 0.015])), t0 + np.array([0.015, -0.01, 0.008])
    errors = []
    for ki in (0.0, 5.0):
        world = _heavy_world(truth)
        ctrl = JOINTS.ctc(integral_gain=ki)
        ctrl.reset(world.context(world.goal(Rg, tg)))
        p, R, _ = world.run(ctrl, (R0, t0), 150)
        errors.append(float(pose_error(R[-1], p[-1], Rg, tg)[0]))
        assert ctrl.compiled_steps == 150
    without, with_ = errors
    assert without > 1e-3
    assert with_ < 0.01 * without, (without, with_)


def test_computed_torque_saturation_holds_the_integral(geometry: HexapodGeometry) -> None:
    """``saturation = "scale"`` and anti-windup on the plugin's compiled step: a nominal
    limit of 1 N (every step over it), the commanded forces scaled to it (the most
    loaded leg at the limit, the others under it) and the integral held at zero; at
    1 kN the forces are the law's and the integral grows."""
    truth = ideal_drives(geometry)
    R0, t0 = home_pose(truth)
    goal = t0 + np.array([0.002, -0.001, 0.0015])
    for limit, grows in ((1.0, False), (1e3, True)):
        nominal = dataclasses.replace(truth, drives=dataclasses.replace(
            truth.drives, force_limit=np.full(6, limit)))
        world = CtcWorld.make(truth, nominal)
        ctrl = JOINTS.ctc(integral_gain=5.0, saturation="scale")
        ctrl.reset(world.context(world.goal(R0, goal)))
        _, _, cmds = world.run(ctrl, (R0, t0), 5)
        assert ctrl.compiled_steps == 5
        peaks = [float(np.abs(c.forces).max()) for c in cmds]
        if grows:  # under the limit: the law's forces
            assert max(peaks) < limit, peaks
        else:  # scaled: the most loaded leg at the limit, not every leg (as "clip")
            np.testing.assert_allclose(peaks, limit, rtol=1e-12)
            # (the first step, at rest at home, loads the six legs alike)
            assert all(float(np.abs(c.forces).min()) < 0.99 * limit for c in cmds[1:])
        assert bool(np.any(ctrl.integral != 0.0)) is grows


def test_computed_torque_batch_rows_equal_the_trials_own_steps(geometry: HexapodGeometry
                                                               ) -> None:
    """The plugin's computed torque over a batch (``test_ctc_rows.py``'s check, with
    integral action): every row through the one compiled call, the forces of each trial's
    own step to the last bit; a deep copy of a trial (its step rebuilt from the feature)
    steps as the original."""
    from tests.controllers.test_ctc_rows import _batch, line_trials

    world = _heavy_world(ideal_drives(geometry))
    ctx, robots = line_trials(world)
    n = len(robots.R)
    batch = JOINTS.ctc(integral_gain=5.0)
    batch.reset_batch([ctx] * n)
    singles = [JOINTS.ctc(integral_gain=5.0) for _ in range(n)]
    for one in singles:
        one.reset(ctx)
    for k in range(8):
        obs = _batch(world, robots, k * DT)
        out = batch.step_batch(obs)
        assert out.reasons == [None] * n, (k, out.reasons)
        assert out.forces is not None
        if k == 4:
            twin = copy.deepcopy(singles[0])
            assert twin.compiled is not None and singles[0].compiled is not None
            assert twin.compiled.function is singles[0].compiled.function
            assert not np.shares_memory(twin.compiled.row, singles[0].compiled.row)
        for j, one in enumerate(singles):
            cmd = one.step(obs.item(j))
            assert cmd.reason is None
            assert out.forces[j].tobytes() == np.asarray(cmd.forces).tobytes()
            assert out.error_norm[j] == cmd.error_norm
            if k >= 4 and j == 0:
                assert twin.step(obs.item(j)).forces.tobytes() == cmd.forces.tobytes()
        assert not robots.advance(np.arange(n), out.forces, DT / 20, 20).any()
    assert bool(np.any(singles[0].integral != 0.0))


def test_computed_torque_tracks_a_line_with_a_rotation(ctc_world: CtcWorld) -> None:
    """A 12 mm line with a 2 degree rotation through the study's tracking wrapper: the
    feature's reference, its rate and acceleration (automatic differentiation along the
    pose trajectory) keep the true pose within the bounds the built-in computed-torque
    laws meet (``test_ctc_laws.py``: 30 um, 0.005 degree; measured 20.5 um, 0.0035 degree
    as ``leg-direction-ctc``)."""
    assert_tracks_the_rotated_line(ctc_world, JOINTS.ctc())


def test_a_hidden_leg_is_left_out(world: World) -> None:
    """Leg 2 never seen (NaN direction, marked hidden): the law steps on the five others
    (its rows weight 0 in the compiled core, its direction for ``J_inv`` from the goal's
    approximation then the estimate) and still reaches the goal."""
    R1, t1 = _goal_pose(world.geometry)
    ctrl = JOINTS.pinv(gain=2.0)
    ctrl.reset(world.context(world.goal(R1, t1), 0.02))

    def hide(obs, k):  # type: ignore[no-untyped-def]
        obs.directions = obs.directions.copy()
        obs.directions[2] = np.nan
        obs.direction_visible = np.arange(6) != 2

    run = closed_loop(world, ctrl, home_pose(world.geometry), (R1, t1), 0.02, 200, hide=hide)
    assert "using 5 of 6 legs" in run.commands[0].notes
    assert run.commands[0].features_used == 15
    assert run.position_errors[-1] < 10e-6, run.position_errors[-1]


def test_options_are_the_built_in_laws() -> None:
    """Each generated controller declares the options of the built-in law of its solver
    (``hexapod-bench list --options``, the scenario checks)."""
    from controllers.options import option_table

    expected = {"pinv": {"gain", "adaptive_gain", "threshold", "damping", "compiled"},
                "qp": {"gain", "stroke_margin", "max_speed", "regularization"},
                "mpc": {"horizon", "model", "effort_weight", "max_iter", "drive_model"},
                "ctc": {"natural_frequency", "damping", "smooth_goal", "integral_gain",
                        "saturation"}}
    for which, names in expected.items():
        table = option_table(getattr(JOINTS, which))
        assert names <= set(table.names), (which, table.names)


@pytest.mark.parametrize("interaction", ["desired", "mean"])
def test_desired_and_mean_interactions_converge(world: World, interaction: str) -> None:
    """``L`` at the legs' goal state (the goal's directions and lengths), or the mean of
    both: the same goal reached, through the feature's core of that interaction."""
    R1, t1 = _goal_pose(world.geometry)
    ctrl = JOINTS.pinv(gain=2.0, interaction=interaction)
    ctrl.reset(world.context(world.goal(R1, t1), 0.02))
    assert ctrl.kernel.function.name == f"hexapod_platform_joint_law_{interaction}"
    run = closed_loop(world, ctrl, home_pose(world.geometry), (R1, t1), 0.02, 200)
    assert run.position_errors[-1] < 10e-6, run.position_errors[-1]


def test_computed_torque_with_hidden_legs(ctc_world: CtcWorld) -> None:
    """Leg 4 hidden all along: its rows are masked in the compiled step and the goal is
    reached; four legs hidden (two left, 6 rows of rank < 6): a refusal naming the rank."""
    R0, t0 = home_pose(ctc_world.truth)
    goal = t0 + np.array([0.002, -0.001, 0.0015])
    ctrl = JOINTS.ctc(smooth_goal=False)
    ctrl.reset(ctc_world.context(ctc_world.goal(R0, goal)))

    def hide(legs: np.ndarray):  # type: ignore[no-untyped-def]
        def edit(obs, k):  # type: ignore[no-untyped-def]
            u = np.array(obs.directions)
            u[legs] = np.nan
            return dataclasses.replace(obs, directions=u, normals=None,
                                       direction_visible=~legs)
        return edit

    one = np.arange(6) == 4
    p, _, cmds = ctc_world.run(ctrl, (R0, t0), 150, edit=hide(one))
    assert np.linalg.norm(p[-1] - goal) < 1e-6
    assert cmds[-1].features_used == 15
    assert ctrl.compiled_steps == 150
    few = np.array([True, True, False, True, False, True])
    from hexapod.dynamics.robots import DynamicRobots

    robot = DynamicRobots([ctc_world.truth], R0[None].copy(), t0[None].copy())
    cmd = ctrl.step(hide(few)(ctc_world.observation(robot, 150 * DT), 0))
    assert cmd.reason is not None and "rank" in cmd.reason, cmd.reason
    np.testing.assert_array_equal(cmd.values, np.zeros(6))


@pytest.fixture
def registered() -> Iterator[None]:
    """The plugin's controllers registered under their names (removed after)."""
    saved = (dict(registry._factories), dict(registry._info))
    for cls in JOINTS.all():
        registry.register(cls.name, cls, "tests", "0")
    try:
        yield
    finally:
        registry._factories, registry._info = saved


@pytest.mark.parametrize("camera", ["perspective", "unified"])
@pytest.mark.parametrize("which", ["pinv", "qp", "mpc"])
def test_registry_contract(which: str, camera: str, other_geometry: HexapodGeometry,
                           registered: None) -> None:
    """The registry-generated contract checks of ``test_registry.py`` (shapes and motion,
    zero error, NaN in each field, malformed observations) on the plugin's velocity
    controllers, registered as a plugin's are."""
    from tests.controllers import test_registry as contract

    name = getattr(JOINTS, which).name
    world = World(other_geometry, make_camera(camera, other_geometry))
    contract.test_shapes_and_motion(name, world, Path())
    contract.test_zero_error_gives_zero_command(name, world, Path())
    for field in ("lengths", "normals", "lines", "directions", "t"):
        contract.test_nan_observation_gives_zero_command_with_reason(name, field, world,
                                                                     Path())
    contract.test_malformed_observation_never_raises(name, world, Path())


@pytest.mark.parametrize("which", ["pinv", "qp", "mpc"])
def test_tracking_a_batch(which: str, registered: None) -> None:
    """``test_tracking.py``'s batch check on the plugin's controllers: four trials tracking
    circles (a new goal each period, hidden features at random, a NaN time, a trial
    missing from some steps) through one :class:`TrackingController` over the batch give
    the commands of one per trial stepped alone, to the last bit."""
    from tests.controllers import test_tracking as tracking

    tracking.test_tracking_a_batch_gives_the_rows_of_one_tracking_controller_per_trial(
        getattr(JOINTS, which).name, {})


def test_a_feature_whose_value_is_not_its_rows_is_refused_where_it_is_defined() -> None:
    """A feature's ``value`` of another shape than its ``rows`` (a column of 2 for 3, a
    row instead of a column) failed every trial with a reshape or CasADi error deep in
    a run; :func:`controllers_for` refuses it, naming the feature and the shapes."""
    import casadi as ca

    from controllers.features import LegFeature, controllers_for

    class TwoForThree(LegFeature):
        name = "two-for-three"
        rows = 3

        def value(self, u: Any, q: Any, A: Any) -> Any:
            m = A + 0.5 * q * u
            return ca.vertcat(m[0] / m[2], m[1] / m[2])

    class RowNotColumn(TwoForThree):
        name = "row-not-column"
        rows = 2

        def value(self, u: Any, q: Any, A: Any) -> Any:
            m = A + 0.5 * q * u
            return ca.horzcat(m[0] / m[2], m[1] / m[2])

    class NotCasadi(TwoForThree):
        name = "not-casadi"

        def value(self, u: Any, q: Any, A: Any) -> Any:
            return np.linalg.norm(np.asarray(u))  # numpy on symbols

    for feature, text in ((TwoForThree(), "returned shape (2, 1), rows = 3 declares (3, 1)"),
                          (RowNotColumn(), "returned shape (1, 2), rows = 2 declares (2, 1)"),
                          (NotCasadi(), "failed on symbols")):
        with pytest.raises(ValueError) as info:
            controllers_for(feature)
        assert f"feature {feature.name!r}: value(u, q, A)" in str(info.value), str(info.value)
        assert text in str(info.value)


@pytest.mark.parametrize("which", ["pinv", "qp", "mpc"])
def test_a_reset_controller_pickles_and_steps_as_the_original(world: World, which: str
                                                              ) -> None:
    """The generated classes are bound in the plugin's module under names of its own
    (``PlatformJointPinv``, not the class's ``PlatformJointPseudoInverse``): a reset,
    stepped controller still pickles (found again in its module by its registry name),
    and the copy commands what the original commands next, to the last bit."""
    import pickle

    R1, t1 = _goal_pose(world.geometry)
    ctrl = getattr(JOINTS, which)(gain=2.0)
    ctrl.reset(world.context(world.goal(R1, t1), 0.02))
    R0, t0 = home_pose(world.geometry)
    ctrl.step(world.observation(R0, t0))
    copy_ = pickle.loads(pickle.dumps(ctrl))
    assert type(copy_) is type(ctrl)
    obs = world.observation(R0 @ exp_so3(np.deg2rad([0.3, 0.0, 0.0])), t0 + 0.001, 0.02)
    np.testing.assert_array_equal(copy_.step(obs).velocities, ctrl.step(obs).velocities)


def test_the_computed_torque_controller_pickles_into_another_process(ctc_world: CtcWorld
                                                                      ) -> None:
    """A reset computed-torque controller of the plugin, pickled here, is unpickled and
    stepped by a new Python process (which imports the plugin's module to find the
    class), commanding the original's forces to the last bit."""
    import pickle
    import subprocess
    import sys

    from hexapod.dynamics.robots import DynamicRobots

    R0, t0 = home_pose(ctc_world.truth)
    ctrl = JOINTS.ctc()
    ctrl.reset(ctc_world.context(ctc_world.goal(R0, t0 + np.array([0.002, 0.0, 0.001]))))
    robot = DynamicRobots([ctc_world.truth], R0[None].copy(), t0[None].copy())
    obs = ctc_world.observation(robot, 0.0)
    blob = pickle.dumps((ctrl, obs))
    script = ("import pickle, sys; ctrl, obs = pickle.loads(sys.stdin.buffer.read()); "
              "sys.stdout.buffer.write(pickle.dumps(ctrl.step(obs).forces))")
    done = subprocess.run([sys.executable, "-c", script], input=blob, capture_output=True,
                          cwd=Path(__file__).parents[2], timeout=300, check=False)
    assert done.returncode == 0, done.stderr.decode()[-2000:]
    np.testing.assert_array_equal(pickle.loads(done.stdout), ctrl.step(obs).forces)


def test_a_class_its_module_does_not_hold_is_copied_but_not_pickled() -> None:
    """``controllers_for`` called inside a function: its classes deep-copy as any object
    but cannot be pickled by name (pickle's own error, naming the class)."""
    import pickle

    from controllers.features import controllers_for

    local = controllers_for(PlatformJoints())
    ctrl = local.pinv()
    assert type(copy.deepcopy(ctrl)) is local.pinv
    with pytest.raises(pickle.PicklingError, match="PlatformJointPseudoInverse"):
        pickle.dumps(ctrl)


class JointHeights(LegFeature):
    """One row per leg: the platform joint's depth in the camera frame (it sees three of
    the six degrees of freedom: rank 3 with every leg)."""

    name = "joint-height"
    rows = 1

    def value(self, u: ca.SX, q: ca.SX, A: ca.SX) -> ca.SX:
        return (A + q * u)[2]


HEIGHTS = controllers_for(JointHeights())


def test_a_rank_refusal_counts_the_legs_of_a_feature_of_any_size(world: World) -> None:
    R1, t1 = _goal_pose(world.geometry)
    ctrl = HEIGHTS.pinv()
    ctrl.reset(world.context(world.goal(R1, t1), 0.02))
    cmd = ctrl.step(world.observation(*home_pose(world.geometry)))
    assert cmd.reason is not None and cmd.reason.startswith(
        "interaction matrix rank 3 < 6 with 6 legs"), cmd.reason  # (it said 2 legs)


def test_two_features_of_one_name_in_a_module_are_named_when_pickled(world: World) -> None:
    """It was pickle's own 'attribute lookup JointQP on ... failed', naming neither."""
    import pickle

    from tests.controllers.plugin_feature_clash import DEPTHS

    ctrl = DEPTHS.qp()
    ctrl.reset(world.context(world.goal(*_goal_pose(world.geometry)), 0.02))
    with pytest.raises(LookupError, match=r"controller 'joint-qp': module "
                       r"tests\.controllers\.plugin_feature_clash makes it from 2 features "
                       r"of one name \(Depths, Joints\): give each feature"):
        pickle.dumps(ctrl)
