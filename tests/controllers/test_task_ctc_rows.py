"""The task-space CTC laws' compiled step on its own input row (the pose guess kept in the
row, the readings and the law's inputs written in place, the command built from the
output row) against an oracle that builds every row afresh.

The oracle is the plain use of :func:`controllers.solvers.compiled_task_ctc.task_step`:
a fresh input row filled field by field from the documented layout (the guess ``R``
column-major and ``t``, the lengths, their rates, the nominal points, the model's
parameters, the drives, the gains, then the kind's fields: the reference row, the leg
directions, the camera frame, the normals, the mask, the reference's features),
:meth:`CompiledFunction.single` called again from the pose reached until the residual
is below its tolerance, LAPACK's ``syevd`` of ``L^T L`` for the condition number. The
law must give the same numbers bitwise whatever the guess (the previous pose, one set
from outside, one left by a refused or a numpy step), for commands kept over later
steps (no output row shared), after a deep copy and after pickling (copies stepping
apart from the original). The common-case checks (readings, directions, visibility)
must answer as the general ones they shortcut.
"""

from __future__ import annotations

import copy
import math
import pickle

import numpy as np
import pytest
from scipy.linalg.lapack import dsyevd

from controllers import registry
from controllers.base import Command, Observation
from controllers.cartesian_ctc import all_seen, directions_seen, every_seen
from controllers.feature_ctc import FeatureCTC
from controllers.solvers.compiled_task_ctc import layout, task_step
from controllers.task_ctc import TaskComputedTorque
from controllers.task_ctc_compiled import FIT_TOLERANCE, FK_MAX_CALLS, FK_TOLERANCE
from hexapod import deltalab, sample_poses
from hexapod.dynamics import DynamicModel
from hexapod.kinematics import legs_in_frame
from hexapod.se3 import exp_so3
from hexapod.trajectory import PoseTrajectory
from hexapod.workspace import home_pose
from tests.controllers.ctc_world import DT, CtcWorld, perturbed
from tests.controllers.task_ctc_oracles import feature_reference
from vision.legs import leg_edges

LAWS = ("cartesian-ctc", "vision-ctc", "leg-edge-ctc", "leg-direction-ctc")


def _law(name: str, tracking: bool = True) -> tuple[TaskComputedTorque, CtcWorld]:
    """A law on a nominal model 1 mm off the truth, tracking a circle (or regulating to
    a fixed goal as a step)."""
    truth = deltalab()
    world = CtcWorld.make(truth, perturbed(truth, 1e-3, 4))
    R, t = sample_poses(truth, 2, rng=np.random.default_rng(3), max_translation=0.01)
    ref = PoseTrajectory("circle", "trapezoidal", R[0], t[0], speed=0.02, acceleration=0.1,
                         radius=0.01, plane="xz") if tracking else None
    law = registry.create(name) if tracking else registry.create(name, smooth_goal=False)
    assert isinstance(law, TaskComputedTorque)
    law.reset(world.context(world.goal(R[1], t[1]), reference=ref))
    return law, world


def _observations(world: CtcWorld, n: int, seed: int
                  ) -> tuple[list[Observation], np.ndarray, np.ndarray]:
    """Poses 3 cm and 6 degrees apart with leg rates, every feature seen, on the control
    grid; and the true poses (n, 3, 3), (n, 3)."""
    rng = np.random.default_rng(seed)
    Rs, ts = sample_poses(world.truth, n, rng=rng, max_translation=0.03,
                          max_angle=np.deg2rad(6), margin=0.01)
    out = []
    for k, (R, t) in enumerate(zip(Rs, ts, strict=True)):
        legs = legs_in_frame(world.truth, R, t, world.camera.camera_from_base)
        normals, _ = leg_edges(legs.base_points, legs.directions, world.truth.leg_radius)
        out.append(Observation(DT * (k + 1), legs.lengths, normals=normals,
                               directions=legs.directions, q_dot=rng.normal(0, 0.01, 6)))
    return out, Rs, ts


def _far_guess(R: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A guess 80 degrees and 10 cm off ``(R, t)``: the compiled step's pose needs more
    calls from the pose reached (the Newton loop's path)."""
    axis = np.array([0.6, 0.0, 0.8])
    return exp_so3(np.deg2rad(80.0) * axis) @ R, t + np.array([0.0, 0.0, 0.1])


def _oracle(law: TaskComputedTorque, obs: Observation,
            guess: tuple[np.ndarray, np.ndarray] | None) -> tuple[Command, int]:
    """The command of one step from a fresh row, and the compiled calls it took."""
    ctx = law.context
    assert ctx is not None and law.compiled_kind is not None
    g, d = ctx.geometry, ctx.geometry.drives
    feature, fk = law.compiled_kind, law.compiled_fk
    kind = feature.ctc_name  # the oracle writes the row by hand, block by block
    inputs, outputs = layout(feature, fk)
    fn = task_step(feature, fk)
    row = np.full(fn.n_in, np.nan)  # every field must be written
    R0, t0 = home_pose(g) if guess is None else guess
    tr = obs.t - law.reference_start
    fields: dict[str, object] = {
        "pose": np.concatenate([R0.T.ravel(), t0]), "q": obs.lengths, "q_dot": obs.q_dot,
        "points": np.concatenate([g.base_points.ravel(), g.platform_points.ravel()]),
        "params": DynamicModel(g).parameters,
        "rotor": np.broadcast_to(np.asarray(d.rotor_inertia, dtype=float), (6,)),
        "viscous": np.broadcast_to(np.asarray(d.viscous, dtype=float), (6,)),
        "coulomb": np.broadcast_to(np.asarray(d.coulomb, dtype=float), (6,)),
        "gains": [law.gains.kp, law.gains.kd, DT]}
    if kind == "pose":
        if law.reference is None:
            R, t = law.goal_pose()
            fields["reference"] = np.concatenate([R.ravel(), t, np.zeros(12)])
        else:
            fields["reference"] = law.pose_reference(tr)
        if not fk:
            bc = ctx.camera.camera_from_base.inverse()  # type: ignore[union-attr]
            fields["directions"] = np.asarray(obs.directions).ravel()
            fields["base"] = np.asarray(ctx.base_points).ravel()
            fields["frame"] = np.concatenate([bc.rotation.ravel(), bc.translation])
            fields["seen"] = np.ones(6)  # every leg seen
    else:
        cam = ctx.camera.camera_from_base  # type: ignore[union-attr]
        m = 36 if kind == "edges" else 18
        if kind == "edges":
            fields["normals"] = np.asarray(obs.normals).ravel()
            fields["directions"] = np.zeros(18)
            fields["of_normals"] = 1.0
        else:
            fields["directions"] = np.asarray(obs.directions).ravel()
        fields["base"] = np.asarray(ctx.base_points).ravel()
        fields["mask"] = np.ones(m)
        fields["frame"] = np.concatenate([cam.rotation.ravel(), cam.translation])
        if law.reference is None:
            s = np.asarray(law._taught).ravel()  # type: ignore[attr-defined]
            fields["reference_features"] = np.concatenate([s, np.zeros(2 * m)])
        else:
            assert isinstance(law, FeatureCTC)
            ref = feature_reference(law, tr)
            assert np.isfinite(ref).all()
            fields["reference_features"] = np.asarray(ref).ravel()
    fields["integral"] = np.zeros({"pose": 6, "edges": 36, "directions": 18}[str(kind)])
    assert set(fields) == set(inputs)
    for name, value in fields.items():
        row[inputs[name]] = value
    assert np.isfinite(row).all()
    y = fn.single(row)
    calls, tolerance = 1, FK_TOLERANCE if fk else FIT_TOLERANCE
    while not y[outputs["fk_residual"].start] < tolerance:
        assert calls < FK_MAX_CALLS, "no pose from this guess"
        row[0:12] = y[0:12]
        y = fn.single(row)
        calls += 1
    assert y[outputs["solved"].start] == 1.0
    w, _, info = dsyevd(y[outputs["factor"]].reshape(6, 6), compute_v=0)
    assert info == 0
    e = y[outputs["error"]]
    limit = np.asarray(d.force_limit, dtype=float)  # the default saturation: clip per leg
    return Command.of_forces(np.clip(y[outputs["forces"]], -limit, limit), error=e, rank=6,
                             error_norm=math.sqrt(float(e @ e)),
                             condition=math.sqrt(float(w[-1] / w[0])),
                             features_used=len(e)), calls


def _same(a: Command, b: Command) -> None:
    assert a.reason is None and b.reason is None, (a.reason, b.reason)
    assert a.forces is not None and b.forces is not None
    assert a.forces.tobytes() == b.forces.tobytes()
    assert a.error.tobytes() == b.error.tobytes()
    assert (a.error_norm, a.condition, a.rank, a.features_used, a.notes) == \
        (b.error_norm, b.condition, b.rank, b.features_used, b.notes)
    assert a.velocities.tobytes() == b.velocities.tobytes()


@pytest.mark.parametrize("tracking", [True, False])
@pytest.mark.parametrize("name", LAWS)
def test_every_step_equals_a_fresh_row_from_its_guess(name: str, tracking: bool) -> None:
    law, world = _law(name, tracking)
    obs, Rs, ts = _observations(world, 25, seed=5)
    kept: list[tuple[Command, Command]] = []
    calls = []
    law.step(obs[0])  # a fixed goal's first step starts the line (two compiled calls)
    assert law.compiled is not None
    for k, o in enumerate(obs[1:]):
        if k % 6 == 2:  # a guess set from outside (as the tests and the numpy path do)
            law.compiled.guess = _far_guess(Rs[k + 1], ts[k + 1])
        if k % 6 == 0 and not law.compiled_fk:  # the fit's loop, then forces that
            # overflow: refused (status NON_FINITE), the guess left as it was (the row not)
            law.compiled.guess = _far_guess(Rs[k + 1], ts[k + 1])
            huge = Observation(o.t, o.lengths, normals=o.normals, directions=o.directions,
                               q_dot=o.q_dot * 1e200)
            with np.errstate(all="ignore"):
                refused = law.step(huge)
            assert refused.reason is not None and "non-finite" in refused.reason
            assert np.isfinite(np.asarray(refused.forces)).all()
        if k % 6 == 4:  # a refusal in between: the guess in the row must stay right
            bad = Observation(o.t, o.lengths, normals=o.normals, directions=o.directions,
                              q_dot=np.full(6, np.nan))
            assert law.step(bad).reason is not None
        if k % 6 == 5:  # a hidden leg (vision-ctc: the fit to five legs; feature laws:
            # masked rows)
            visible = np.ones((6, 2), bool)
            visible[1, 1] = False
            hidden = Observation(o.t, o.lengths, normals=o.normals, directions=o.directions,
                                 q_dot=o.q_dot, edge_visible=visible,
                                 direction_visible=visible.all(axis=1))
            law.step(hidden)
        guess = law.guess
        before = law.compiled_steps
        cmd = law.step(o)
        assert law.compiled_steps == before + 1, cmd.reason
        expected, n = _oracle(law, o, guess)  # from the same guess (not a pose left in
        # the row): the same numbers only if the step called again from the same poses
        kept.append((cmd, expected))
        calls.append(n)
    for cmd, expected in kept:  # compared after every step: nothing shared with later ones
        _same(cmd, expected)
    # both paths taken: the pose of the last step in the row (one call) and a guess
    # rewritten (more)
    assert max(calls) >= 2 and 1 in calls, calls


def _replayed(name: str, observations: list[Observation]) -> TaskComputedTorque:
    law, _ = _law(name)
    for o in observations:
        assert law.step(o).reason is None
    return law


@pytest.mark.parametrize("name", LAWS)
def test_copies_and_pickles_step_like_the_original_and_apart_from_it(name: str) -> None:
    _, world = _law(name)
    obs = _observations(world, 12, seed=8)[0]
    law = _replayed(name, obs[:4])
    for c in (copy.deepcopy(law), pickle.loads(pickle.dumps(law))):
        assert c.compiled is not None and law.compiled is not None
        assert not np.shares_memory(c.compiled.row, law.compiled.row)
        twin = _replayed(name, obs[:4])
        _same(c.step(obs[4]), twin.step(obs[4]))  # the pose guess travelled with the copy
        assert c.step(obs[9]).reason is None  # the copy moves on
        assert c.compiled_steps == law.compiled_steps + 2
    twin = _replayed(name, obs[:4])  # the original is untouched by its copies' steps
    for o in obs[4:8]:
        _same(law.step(o), twin.step(o))


def _varied(o: Observation) -> list[Observation]:
    """Observations the common-case checks must leave to the general ones, or accept."""
    out = []
    for k in range(11):
        v = Observation(o.t, o.lengths.copy(), normals=o.normals.copy(),
                        directions=o.directions.copy(), q_dot=o.q_dot.copy())
        if k == 1:
            v.lengths[3] = np.nan
        elif k == 2:
            v.q_dot = None
        elif k == 3:
            v.q_dot[0] = -np.inf
        elif k == 4:
            v.t = float("nan")
        elif k == 5:
            v.q_dot = v.q_dot * 1e200  # finite, but the sum of squares overflows
        elif k == 6:
            v.lengths = v.lengths[:5]
        elif k == 7:
            v.direction_visible = np.arange(6) != 2
            v.edge_visible[4, 1] = False
        elif k == 8:
            v.directions[1, 2] = np.nan
        elif k == 9:
            v.directions = None
        elif k == 10:
            v.direction_visible = [True] * 6  # type: ignore[assignment]
        out.append(v)
    return out


@pytest.mark.filterwarnings("ignore:overflow encountered")
def test_the_common_case_checks_answer_as_the_general_ones() -> None:
    _, world = _law("vision-ctc")
    accepted = 0
    for v in _varied(_observations(world, 1, seed=2)[0][0]):
        u = every_seen(v.directions, v.direction_visible)  # vision-ctc's common case
        seen_u, seen = directions_seen(v.directions, v.normals, v.direction_visible,
                                       v.edge_visible)
        if u is not None and u.shape == (6, 3):
            accepted += 1
            assert seen.all() and u.tobytes() == seen_u.tobytes()
        else:  # the general check sees a hidden or non-finite leg, or other directions
            assert not seen.all() or v.directions is None
        assert all_seen(v.direction_visible) == bool(np.all(v.direction_visible))
        assert all_seen(v.edge_visible) == bool(np.all(v.edge_visible))
    assert accepted == 8  # the plain, the unusual-but-fine and the refused
    assert all_seen(None)


def test_a_parallel_singularity_is_refused_as_computed_torque_refuses_it() -> None:
    """A robot whose stroke reaches the parallel singularity (the platform turned 90 deg
    about z, legs of 436-592 mm in a 300-600 mm stroke): computed torque refused ("rank
    < 6"), the task laws clipped the forces that hold their task to the drives' 200 N,
    their task Jacobian regular there: refused now, alone and in a batch of rows, while
    at 89 deg (a regular pose) every law commands forces."""
    import dataclasses

    from controllers import registry
    from controllers.base import ControllerContext, Goal, Observation
    from controllers.data import ObservationBatch
    from hexapod import deltalab
    from hexapod.se3 import exp_so3
    from hexapod.workspace import home_pose
    from vision.cameras import omni_camera
    from vision.legs import observe_legs

    robot = dataclasses.replace(deltalab(), stroke=(0.30, 0.60))
    cam = omni_camera(robot)
    R0, t0 = home_pose(robot)[:2]

    def seen(R: np.ndarray) -> Observation:
        o = observe_legs(cam, robot, R, t0)
        return Observation(0.0, o.lengths, normals=o.normals, directions=o.directions,
                           edge_visible=o.edge_visible, q_dot=np.zeros(6))

    home = seen(R0)
    goal = Goal(normals=home.normals, directions=home.directions, lengths=home.lengths,
                rotation=R0, translation=t0, edge_visible=home.edge_visible)
    context = ControllerContext(cam.camera_from_base.apply(robot.base_points), robot, cam,
                                0.02, goal)
    turned = {deg: seen(exp_so3(np.array([0.0, 0.0, np.deg2rad(deg)])) @ R0)
              for deg in (89.0, 90.0)}
    for name in ("cartesian-ctc", "leg-edge-ctc", "leg-direction-ctc"):
        law = registry.create(name)
        law.reset(context)
        assert law.step(turned[89.0]).ok
        law.reset(context)
        cmd = law.step(turned[90.0])
        assert not cmd.ok and "parallel singularity" in (cmd.reason or ""), (name, cmd.reason)
        assert not np.any(cmd.values)
        for n in (3, 10):  # (one C call; the lanes)
            law.reset_batch([context] * n)
            batch = ObservationBatch.of(turned[90.0])
            assert batch is not None
            rows = batch.rows(np.zeros(n, dtype=int))
            rows.trials[:] = np.arange(n)
            reasons = list(law.step_batch(rows).reasons)
            assert all("parallel singularity" in (r or "") for r in reasons), reasons
