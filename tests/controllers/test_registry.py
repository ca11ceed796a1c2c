"""Checks generated over the registry: every registered controller (built-in or plugin).

A plugin is registered from a temporary distribution's entry points (a
``*.dist-info`` with ``entry_points.txt`` and ``METADATA`` on ``sys.path``), next
to a broken one that must be reported without breaking the others.
"""

from __future__ import annotations

import copy
import pickle
import sys
import textwrap
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from controllers import BUILTIN_SPECS, registry
from controllers.base import (
    ENTRY_POINT_GROUP,
    GOAL_FIELDS,
    Command,
    CommandBatch,
    Controller,
    ControllerContext,
    GoalBatch,
    Observation,
    ObservationBatch,
)
from controllers.data import _BATCH_FIELDS
from controllers.exceptions import OptionError, PluginLoadError, UnknownControllerError
from controllers.tracking import TrackingController
from hexapod.actuation import Actuation
from tests.controllers.controller_world import World, make_camera

PLUGIN = "test-saturated-joints"
BROKEN = "test-broken"
PLUGIN_DIST = "hexapod-test-plugin"
PLUGIN_VERSION = "0.0.7"

PLUGIN_SOURCE = '''
"""A third-party controller, shipped by a test distribution."""
import numpy as np
from controllers.base import Command, Controller, observation_problem


class SaturatedJoints(Controller):
    """Joint-space law with leg-speed saturation (test plugin)."""

    name = "test-saturated-joints"
    features = frozenset({"lengths"})

    def __init__(self, gain=1.0):
        self.gain = gain

    def reset(self, context):
        self.q_star = np.asarray(context.goal.lengths, dtype=float)
        self.vmax = context.max_speed

    def step(self, observation):
        problem = observation_problem(observation, self.features)
        if problem:
            return Command.refuse(problem)
        e = np.asarray(observation.lengths) - self.q_star
        v = np.clip(-self.gain * e, -self.vmax, self.vmax)
        return Command(v, error=e, error_norm=float(np.linalg.norm(e)))
'''


def _write_distribution(root: Path) -> None:
    (root / "hexapod_test_plugin.py").write_text(textwrap.dedent(PLUGIN_SOURCE))
    (root / "hexapod_test_broken.py").write_text(
        "raise ImportError('needs the package frobnicate, which is not installed')\n")
    info = root / f"hexapod_test_plugin-{PLUGIN_VERSION}.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(
        f"Metadata-Version: 2.1\nName: {PLUGIN_DIST}\nVersion: {PLUGIN_VERSION}\n")
    (info / "entry_points.txt").write_text(
        f"[{ENTRY_POINT_GROUP}]\n"
        f"{PLUGIN} = hexapod_test_plugin:SaturatedJoints\n"
        f"{BROKEN} = hexapod_test_broken:Nope\n"
        "leg-edge = hexapod_test_plugin:SaturatedJoints\n")  # a built-in's name


@pytest.fixture(scope="module")
def plugin_distribution(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """Install the temporary distribution on sys.path and load the entry points."""
    root = tmp_path_factory.mktemp("site")
    _write_distribution(root)
    saved = (dict(registry._factories), dict(registry._info), list(registry.errors))
    sys.path.insert(0, str(root))
    try:
        registry.load_plugins(force=True)
        yield root
    finally:
        sys.path.remove(str(root))
        for mod in ("hexapod_test_plugin", "hexapod_test_broken"):
            sys.modules.pop(mod, None)
        registry._factories, registry._info = saved[0], saved[1]
        registry.errors[:] = saved[2]


#: Every controller the registry offers, plus the plugin of the temporary distribution.
# the velocity laws (force laws need the dynamic world: test_computed_torque.py)
NAMES = [*(n for n in registry.names()
           if getattr(registry.create(n), "actuation", "velocity") == "velocity"), PLUGIN]


@pytest.fixture(params=["perspective", "unified"])
def world(request: pytest.FixtureRequest, other_geometry) -> World:  # type: ignore[no-untyped-def]
    return World(other_geometry, make_camera(request.param, other_geometry))


def _poses(world: World) -> tuple[tuple, tuple]:
    Rs, ts = world.poses(2, np.random.default_rng(31), margin=0.02)
    return (Rs[0], ts[0]), (Rs[1], ts[1])


def _controller(name: str, world: World, goal: tuple, plugin_distribution: Path):  # type: ignore[no-untyped-def]
    ctrl = registry.create(name)
    ctrl.reset(world.context(world.goal(*goal), 0.01))
    return ctrl


def _check_command(cmd: Command) -> None:
    assert isinstance(cmd, Command)
    v = np.asarray(cmd.velocities)
    assert v.shape == (6,)
    assert np.all(np.isfinite(v))
    assert np.isfinite(cmd.error_norm)


# ----------------------------------------------------------------------------- registry
def test_builtins_are_registered() -> None:
    assert set(BUILTIN_SPECS) <= set(registry.names())
    for info in registry.info():
        if info.name in BUILTIN_SPECS:
            assert info.package == "hexapod-vs"
            assert info.version not in ("", "unknown")
            assert info.description


def test_plugin_from_entry_points(plugin_distribution: Path) -> None:
    assert PLUGIN in registry.names()
    info = registry.source(PLUGIN)
    assert (info.package, info.version) == (PLUGIN_DIST, PLUGIN_VERSION)
    assert info.description.startswith("Joint-space law with leg-speed saturation")


def test_broken_plugin_is_reported_and_others_work(plugin_distribution: Path) -> None:
    errors = [e for e in registry.errors if e.name == BROKEN]
    assert errors, registry.errors
    assert errors[0].source == PLUGIN_DIST
    assert "frobnicate" in errors[0].reason
    assert BROKEN not in registry.names()
    assert PLUGIN in registry.names()
    assert "leg-edge" in registry.names()


def test_a_plugin_named_as_a_built_in_does_not_replace_it(plugin_distribution: Path
                                                         ) -> None:
    """An installed plugin's entry point with a built-in's name ran under that name,
    the built-in gone without a word: the built-in stays and the clash is reported."""
    assert registry.source("leg-edge").package == "hexapod-vs"
    assert type(registry.create("leg-edge")).__name__ == "LegEdgeController"
    clash = [e for e in registry.errors if e.name == "leg-edge"]
    assert clash and clash[0].source == PLUGIN_DIST
    assert "taken by hexapod-vs" in clash[0].reason
    assert "hexapod_test_plugin:SaturatedJoints" in clash[0].reason


def test_a_plugin_module_that_raises_while_importing_is_one_error(tmp_path: Path,
                                                                 monkeypatch: pytest.MonkeyPatch
                                                                 ) -> None:
    """Whatever a ``module:attr`` plugin's module raises as it imports (an abstract class
    built at import, a RuntimeError, a syntax error) is a PluginLoadError naming it."""
    (tmp_path / "raises_at_import.py").write_text("raise RuntimeError('boom')\n")
    (tmp_path / "bad_syntax_plugin.py").write_text("def (:\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    for spec, what in (("raises_at_import:X", "RuntimeError: boom"),
                       ("bad_syntax_plugin:X", "SyntaxError")):
        with pytest.raises(PluginLoadError) as info:
            registry.factory(spec)
        assert what in str(info.value) and spec in str(info.value)


def test_unknown_name_suggests_the_closest() -> None:
    with pytest.raises(UnknownControllerError) as info:
        registry.create("leg-edgee")
    assert info.value.suggestion == "leg-edge"
    assert "did you mean 'leg-edge'" in str(info.value)
    for name in BUILTIN_SPECS:
        assert name in str(info.value)


def test_unknown_option_names_the_controller_its_options_and_the_close_one() -> None:
    with pytest.raises(OptionError, match=r"^leg-edge: option 'gian': no such option; its "
                       r"options: gain, adaptive_gain, .*leg_rate_feedforward "
                       r"\(did you mean 'gain'\?\)$") as info:
        registry.create("leg-edge", gian=5.0)
    assert (info.value.controller, info.value.option) == ("leg-edge", "gian")
    assert info.value.__cause__ is None and info.value.__suppress_context__
    with pytest.raises(OptionError, match=r"^joint-space: option 'zzz': no such option; its "
                       r"options: gain, adaptive_gain$"):
        registry.create("joint-space", zzz=1)
    # an open table (a wrapper that hands options on to its law): the law's own error, as
    # before; the scenario checks name the wrapper
    assert registry.options("latency-compensated").open
    with pytest.raises(TypeError, match="unexpected keyword argument 'gian'"):
        registry.create("latency-compensated", law="leg-edge", gian=5.0)
    with pytest.raises(OptionError, match=r"^controllers.joint:JointSpaceController: option "
                       r"'gain2': no such option; its options: gain, adaptive_gain "):
        registry.create("controllers.joint:JointSpaceController", gain2=1.0)


class NamedLikeLegEdge(Controller):
    """A plugin class that copied a built-in's ``name``."""

    name = "leg-edge"

    def reset(self, context: ControllerContext) -> None:  # type: ignore[misc]
        pass

    def step(self, observation: Observation) -> Command:  # type: ignore[misc]
        return Command.refuse("never stepped")


def test_module_attr_spec(caplog: pytest.LogCaptureFixture) -> None:
    ctrl = registry.create("controllers.joint:JointSpaceController", gain=3.0)
    assert ctrl.name == "joint-space"
    with pytest.raises(PluginLoadError):
        registry.factory("controllers.joint:NoSuchController")
    # a class named as another controller is warned about (its errors blamed that one)
    with caplog.at_level("WARNING", logger="controllers.registry"):
        registry.factory("controllers.joint:JointSpaceController")  # the built-in itself
        assert not caplog.records
        registry.factory("tests.controllers.test_registry:NamedLikeLegEdge")
    assert "tests.controllers.test_registry:NamedLikeLegEdge: its class's name 'leg-edge' is " \
           "another controller's" in caplog.text
    # a class that is not a controller is named so (it was built first: "Command.__init__()
    # missing 1 required positional argument: 'velocities'")
    with pytest.raises(PluginLoadError, match=r"Command is not a controller class"):
        registry.create("controllers.base:Command")


def test_step_before_reset_refuses() -> None:
    for name in BUILTIN_SPECS:
        cmd = registry.create(name).step(Observation(0.0, np.full(6, 0.4)))
        assert not cmd.ok and "reset" in (cmd.reason or "")


@pytest.mark.parametrize("rows", [1, 2])
def test_a_batch_step_before_reset_refuses_every_row(rows: int) -> None:
    """Every built-in (and the tracking wrapper around one) refuses each row of a batch
    stepped before its reset, as its per-trial step does: zeros, the reason naming it."""
    one = ObservationBatch.of(Observation(0.0, np.full(6, 0.4), q_dot=np.zeros(6)))
    assert one is not None
    batch = replace(one.rows(np.zeros(rows, dtype=int)), trials=np.arange(rows))
    controllers = [registry.create(name) for name in BUILTIN_SPECS]
    controllers.append(TrackingController(registry.create("vision-ctc")))
    for ctrl in controllers:
        out = ctrl.step_batch(batch)
        assert out.reasons == [f"{ctrl.name}: reset(context) was not called"] * rows
        assert out.values.shape == (rows, 6) and not out.values.any(), ctrl.name
        assert out.actuation is ctrl.actuation and not ctrl.crashes, ctrl.name


@pytest.mark.parametrize("name", sorted(BUILTIN_SPECS))
def test_a_row_of_a_trial_outside_the_batch_is_a_value_error(name: str,
                                                               other_geometry) -> None:  # type: ignore[no-untyped-def]
    """Each built-in (its step C indexes the batch's arrays with the rows' trials) raises
    a ValueError naming itself and the trials, for batches of two and of one, one naming
    trials that are not integers or a trial a batch gives twice, and one naming the field
    for an array not of the batch's shape; then steps its next batch as usual (nothing
    written outside its arrays)."""
    world = World(other_geometry, make_camera("perspective", other_geometry))
    start, goal = _poses(world)
    ctrl = registry.create(name)
    dt = 0.02 if ctrl.actuation is Actuation.FORCE else 0.01
    ctrl.reset_batch([world.context(world.goal(*goal), dt)] * 3)
    one = ObservationBatch.of(_at_rest(world.observation(*start)))
    assert one is not None
    for trials in ([0, 3], [-1], [2, 1, 1000]):
        batch = replace(one.rows(np.zeros(len(trials), dtype=int)), trials=np.array(trials))
        with pytest.raises(ValueError, match=rf"{name}: trials \[.*\] outside the batch's 3 "
                                             r"trials \(0 to 2\)"):
            ctrl.step_batch(batch)
    with pytest.raises(ValueError, match=rf"{name}: observations\.trials of dtype float64, "
                                         "expected integers"):
        ctrl.step_batch(replace(one.rows(np.zeros(2, dtype=int)), trials=np.array([0.0, 1.0])))
    for trials in ([1, 1], [2, 0, 2]):  # a trial twice in one batch
        batch = replace(one.rows(np.zeros(len(trials), dtype=int)), trials=np.array(trials))
        with pytest.raises(ValueError, match=rf"{name}: observations\.trials repeat trial "
                                             rf"{trials[-1]}: each row of a batch is another"):
            ctrl.step_batch(batch)
    two = replace(one.rows(np.zeros(2, dtype=int)), trials=np.arange(2))
    for field, value in (("lengths", two.lengths[:, :5]), ("normals", two.normals[:1]),
                         ("edge_visible", two.edge_visible[:, :, 0]), ("t", two.t[:1]),
                         ("q_dot", two.q_dot[:, None])):
        with pytest.raises(ValueError, match=rf"{name}: observations\.{field} of shape "):
            ctrl.step_batch(replace(two, **{field: value}))
    out = ctrl.step_batch(replace(one.rows(np.zeros(3, dtype=int)), trials=np.arange(3)))
    assert out.reasons == [None] * 3, out.reasons


@pytest.mark.parametrize("name", sorted(BUILTIN_SPECS))
def test_a_copy_after_a_reset_steps_as_its_original_and_apart_from_it(
        name: str, other_geometry) -> None:  # type: ignore[no-untyped-def]
    """Each built-in, reset on three trials, stepped once and given new goals (read by the
    image laws' instances only when needed), is deep-copied and pickled; then the original
    steps other observations than the copies. Each copy's next two batches (a leg hidden
    in one row: its direction dead-reckoned from the estimate) are those of a twin that
    lived the copy's history, to the last bit, and the original's next batch that of a
    twin of its own: copying shares no state (views of the batch's arrays, the
    compiled cores' inputs, the C's addresses) between a copy and its original, and a
    pickle carries all of it."""
    world = World(other_geometry, make_camera("perspective", other_geometry))
    Rs, ts = world.poses(9, np.random.default_rng(7), margin=0.02)
    dt = 0.02 if registry.create(name).actuation is Actuation.FORCE else 0.01

    def batch(poses: list[int], step: int, hidden: bool = False) -> ObservationBatch:
        """The observations of ``poses`` at period ``step``; ``hidden``: the first row's
        leg 2 not seen (a law dead-reckons its direction from its estimate)."""
        rows = [ObservationBatch.of(_at_rest(world.observation(Rs[k], ts[k], time=step * dt)))
                for k in poses]
        out = ObservationBatch(**{f: None if getattr(rows[0], f) is None else np.concatenate(
            [getattr(r, f) for r in rows]) for f in _BATCH_FIELDS})
        out.trials = np.arange(len(rows))  # (each row made of one observation: trial 0)
        if hidden:
            out.edge_visible[0, 2] = out.direction_visible[0, 2] = False
            for field in ("normals", "lines", "directions"):
                if getattr(out, field) is not None:
                    getattr(out, field)[0, 2] = np.nan
        return out

    def same(a: CommandBatch, b: CommandBatch) -> bool:
        return np.array_equal(a.values, b.values) and a.reasons == b.reasons

    one = GoalBatch.of(world.goal(Rs[8], ts[8]))
    goals = GoalBatch(**{f: None if getattr(one, f) is None else np.repeat(getattr(one, f), 2, 0)
                         for f in GOAL_FIELDS})
    # the original, its twin, and the twins of its deep copy and of its pickled copy
    controllers = [registry.create(name) for _ in range(4)]
    for ctrl in controllers:
        ctrl.reset_batch([world.context(world.goal(Rs[k], ts[k]), dt) for k in (6, 7, 6)])
        ctrl.step_batch(batch([0, 1, 2], 0))
        ctrl.retarget_batch(np.array([0, 2]), goals)
    original, twin, *copy_twins = controllers
    copies = [copy.deepcopy(original), pickle.loads(pickle.dumps(original))]
    assert same(original.step_batch(batch([3, 4, 5], 1)), twin.step_batch(batch([3, 4, 5], 1)))
    for copied, copy_twin in zip(copies, copy_twins, strict=True):
        for step in (1, 2):
            got, want = (copied.step_batch(batch([1, 2, 0], step, hidden=True)),
                         copy_twin.step_batch(batch([1, 2, 0], step, hidden=True)))
            assert same(got, want), (step, got.values - want.values, got.reasons, want.reasons)
    assert same(original.step_batch(batch([0, 1, 2], 2)), twin.step_batch(batch([0, 1, 2], 2)))


# ----------------------------------------------------------------------------- generated
@pytest.mark.parametrize("name", NAMES)
def test_shapes_and_motion(name: str, world: World, plugin_distribution: Path) -> None:
    start, goal = _poses(world)
    ctrl = _controller(name, world, goal, plugin_distribution)
    assert ctrl.name == name
    cmd = ctrl.step(world.observation(*start))
    _check_command(cmd)
    assert cmd.ok, cmd.reason
    assert cmd.error_norm > 0
    assert np.abs(cmd.velocities).max() > 0


@pytest.mark.parametrize("name", NAMES)
def test_zero_error_gives_zero_command(name: str, world: World,
                                       plugin_distribution: Path) -> None:
    _, goal = _poses(world)
    ctrl = _controller(name, world, goal, plugin_distribution)
    for _ in range(3):
        cmd = ctrl.step(world.observation(*goal))
        _check_command(cmd)
        assert cmd.ok, cmd.reason
        assert cmd.error_norm < 1e-9
        np.testing.assert_allclose(cmd.velocities, 0.0, atol=1e-9)


@pytest.mark.parametrize("field", ["lengths", "normals", "lines", "directions", "t"])
@pytest.mark.parametrize("name", NAMES)
def test_nan_observation_gives_zero_command_with_reason(
        name: str, field: str, world: World, plugin_distribution: Path) -> None:
    start, goal = _poses(world)
    ctrl = _controller(name, world, goal, plugin_distribution)
    obs = world.observation(*start)
    if field == "t":
        obs.t = float("nan")
    else:
        value = getattr(obs, field)
        if value is None:  # the unified camera gives no lines: nothing to corrupt
            value = world.observation(*start).normals
        value = np.array(value, dtype=float)
        value.flat[4] = np.nan
        setattr(obs, field, value)
    used = field in ctrl.features or field in ("lengths", "t")
    cmd = ctrl.step(obs)
    _check_command(cmd)
    if used:
        assert not cmd.ok
        assert cmd.reason
        assert np.array_equal(cmd.velocities, np.zeros(6))
    else:  # a field the controller does not use must not stop it
        assert cmd.ok, cmd.reason


@pytest.mark.parametrize("name", NAMES)
def test_malformed_observation_never_raises(name: str, world: World,
                                            plugin_distribution: Path) -> None:
    start, goal = _poses(world)
    ctrl = _controller(name, world, goal, plugin_distribution)
    good = world.observation(*start)
    bad = [Observation(0.0, np.full(5, 0.4)),
           Observation(0.0, good.lengths, normals=np.zeros((6, 3)), lines=np.zeros((6, 3)),
                       directions=np.zeros((6, 2, 3))),
           Observation(0.0, good.lengths, normals=np.full((6, 2, 3), np.inf),
                       lines=np.full((6, 2, 3), np.inf), directions=np.full((6, 3), np.inf)),
           Observation(0.0, good.lengths)]
    for obs in bad:
        cmd = ctrl.step(obs)
        _check_command(cmd)
        if obs.lengths.shape != (6,) or ctrl.features - {"lengths"}:
            assert not cmd.ok and cmd.reason
            assert np.array_equal(cmd.velocities, np.zeros(6))


# ----------------------------------------------------------------------------- force laws
#: Every registered controller that commands leg forces (the dynamic world's force-mode
#: drives): the same contract, with the measured leg velocities they need.
FORCE_NAMES = [n for n in registry.names()
               if getattr(registry.create(n), "actuation", None) is Actuation.FORCE]


def _at_rest(obs: Observation) -> Observation:
    """``obs`` with the leg velocities of a robot at rest (zeros)."""
    obs.q_dot = np.zeros(6)
    return obs


def _force_controller(name: str, world: World, goal: tuple):  # type: ignore[no-untyped-def]
    ctrl = registry.create(name)
    ctrl.reset(world.context(world.goal(*goal), 0.02))
    return ctrl


def _check_forces(cmd: Command) -> None:
    assert isinstance(cmd, Command)
    assert cmd.actuation is Actuation.FORCE
    f = np.asarray(cmd.forces)
    assert f.shape == (6,)
    assert np.all(np.isfinite(f))
    assert np.isfinite(cmd.error_norm)


def test_the_force_laws_are_found() -> None:
    assert {"computed-torque", "cartesian-ctc", "vision-ctc", "leg-edge-ctc",
            "leg-direction-ctc"} <= set(FORCE_NAMES)


@pytest.mark.parametrize("name", FORCE_NAMES)
def test_force_shapes_and_motion(name: str, world: World) -> None:
    start, goal = _poses(world)
    ctrl = _force_controller(name, world, goal)
    cmd = ctrl.step(_at_rest(world.observation(*start)))
    _check_forces(cmd)
    assert cmd.ok, cmd.reason  # (a smooth goal starts where the robot is: no error yet)
    assert np.abs(np.asarray(cmd.forces)).max() > 0


@pytest.mark.parametrize("name", FORCE_NAMES)
def test_force_laws_at_the_goal_hold_it(name: str, world: World) -> None:
    """At the goal, at rest: a zero error, and the same holding forces every period."""
    _, goal = _poses(world)
    ctrl = _force_controller(name, world, goal)
    forces = []
    for k in range(3):
        cmd = ctrl.step(_at_rest(world.observation(*goal, time=0.02 * k)))
        _check_forces(cmd)
        assert cmd.ok, cmd.reason
        assert cmd.error_norm < 1e-9
        forces.append(np.asarray(cmd.forces))
    np.testing.assert_allclose(forces[1], forces[0], rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(forces[2], forces[0], rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("field", ["lengths", "normals", "directions", "t", "q_dot"])
@pytest.mark.parametrize("name", FORCE_NAMES)
def test_force_laws_refuse_a_nan(name: str, field: str, world: World) -> None:
    start, goal = _poses(world)
    ctrl = _force_controller(name, world, goal)
    obs = _at_rest(world.observation(*start))
    if field == "t":
        obs.t = float("nan")
    else:
        value = np.array(getattr(obs, field), dtype=float)
        value.flat[4] = np.nan
        setattr(obs, field, value)
    cmd = ctrl.step(obs)
    _check_forces(cmd)
    if field in ("lengths", "t", "q_dot"):
        assert not cmd.ok and cmd.reason
        assert np.array_equal(np.asarray(cmd.forces), np.zeros(6))
    elif field in ctrl.features:  # refused, or the leg left out, visibly
        clean = _force_controller(name, world, goal).step(_at_rest(world.observation(*start)))
        assert (not cmd.ok and cmd.reason and not np.any(np.asarray(cmd.forces))) or \
            cmd.features_used < clean.features_used or cmd.notes != clean.notes, cmd
    else:  # a field the controller does not use must not stop it
        assert cmd.ok, cmd.reason


@pytest.mark.parametrize("name", FORCE_NAMES)
def test_force_laws_without_leg_velocities_say_so(name: str, world: World) -> None:
    start, goal = _poses(world)
    ctrl = _force_controller(name, world, goal)
    cmd = ctrl.step(world.observation(*start))  # no q_dot: a kinematic world's
    _check_forces(cmd)
    assert not cmd.ok and "leg velocities" in (cmd.reason or "")


@pytest.mark.parametrize("name", FORCE_NAMES)
def test_force_laws_never_raise_on_malformed_observations(name: str, world: World) -> None:
    start, goal = _poses(world)
    ctrl = _force_controller(name, world, goal)
    good = world.observation(*start)
    bad = [Observation(0.0, np.full(5, 0.4), q_dot=np.zeros(6)),
           Observation(0.0, good.lengths, normals=np.zeros((6, 3)), lines=np.zeros((6, 3)),
                       directions=np.zeros((6, 2, 3)), q_dot=np.zeros(6)),
           Observation(0.0, good.lengths, normals=np.full((6, 2, 3), np.inf),
                       directions=np.full((6, 3), np.inf), q_dot=np.zeros(6)),
           Observation(0.0, good.lengths, q_dot=np.zeros(5))]
    for obs in bad:
        cmd = ctrl.step(obs)
        _check_forces(cmd)
        if obs.lengths.shape != (6,) or ctrl.features - {"lengths"} or \
                np.shape(obs.q_dot) != (6,):
            assert not cmd.ok and cmd.reason
            assert np.array_equal(np.asarray(cmd.forces), np.zeros(6))


@pytest.mark.parametrize(("name", "option", "value"), [
    ("leg-edge-mpc", "gain", 0.0), ("leg-direction-mpc", "gain", 0.0),
    ("leg-edge-force-mpc", "damping", -1.0), ("pose-force-mpc", "natural_frequency", 0.0)])
def test_a_held_laws_option_error_is_the_holders(name: str, option: str, value: float) -> None:
    """A predictive controller passes these options to the law it holds, whose error
    named the law ("leg-edge-qp: option 'gain'", "cartesian-ctc: ..."), one the user
    never named: the holder's name now."""
    import re

    from controllers.exceptions import OptionError

    with pytest.raises(OptionError, match=rf"^{re.escape(name)}: option '{option}'"):
        registry.create(name, **{option: value})


def test_a_count_option_given_a_fraction_is_refused() -> None:
    """(model-based took fk_max_iterations = 2.5 as 2, and `check` said nothing.)"""
    from controllers.exceptions import OptionError

    with pytest.raises(OptionError, match=r"fk_max_iterations': expected an integer >= 1, "
                                          r"got 2.5"):
        registry.create("model-based", fk_max_iterations=2.5)
