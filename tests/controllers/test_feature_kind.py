"""The built-in feature objects (:mod:`controllers.tasks.feature_kind`): what they read,
their kernels' names (the compiled libraries' cache keys), their two predictions (numpy
and CasADi) and their refusals."""

from __future__ import annotations

import pickle
from types import SimpleNamespace

import casadi as ca
import numpy as np
import pytest

from controllers.data import FEATURE_FIELDS
from controllers.exceptions import ContextError
from controllers.force_mpc.problem import ForceProblemSpec, kernel_function
from controllers.law_kernel import _edge_function
from controllers.mpc.prediction import FEATURE_KINDS
from controllers.solvers import compiled_task_ctc, reference_motion
from controllers.tasks import (
    BUILTIN_FEATURES,
    EDGE_LINES,
    EDGE_NORMALS,
    LEG_DIRECTIONS,
    PLATFORM_POSE,
    EdgeFeature,
    LegEdgeTask,
)
from controllers.tasks.feature_kind import builtin_feature
from controllers.tasks.leg_edge import edge_feature
from hexapod import deltalab
from hexapod.se3 import exp_so3
from hexapod.workspace import home_pose


def test_every_observed_feature_reads_a_declared_observation_field() -> None:
    observed = [f for f in BUILTIN_FEATURES if f.field is not None]
    assert [f.kind for f in observed] == ["normals", "lines", "directions"]
    for f in observed:
        assert (f.field, f.shape, f.visibility) in FEATURE_FIELDS
        assert f.task_rows == 3 * f.units == int(np.prod(f.shape))
    assert PLATFORM_POSE.field is None and PLATFORM_POSE.task_rows == 6


def test_an_option_value_is_parsed_once_into_the_object() -> None:
    assert edge_feature("lines") is EDGE_LINES and edge_feature("normals") is EDGE_NORMALS
    assert edge_feature(EDGE_LINES) is EDGE_LINES
    with pytest.raises(ValueError, match=r"normals, lines.*'pixels'"):
        edge_feature("pixels")
    assert LegEdgeTask(np.zeros((6, 2, 3)), "normals").feature is EDGE_NORMALS


@pytest.mark.slow
def test_the_kernels_keep_their_names() -> None:
    """The kernel names (part of the compiled libraries' cache key) come from the objects
    and are those the kind strings gave."""
    assert _edge_function(EDGE_LINES, "mean", True).name() == "hexapod_edge_law_lines_w_mean_lean"
    assert _edge_function(EDGE_NORMALS).name() == "hexapod_edge_law_normals_w"
    assert reference_motion._build(EDGE_NORMALS).name() == "hexapod_feature_reference_normals"
    assert (reference_motion._build(LEG_DIRECTIONS).name()
            == "hexapod_feature_reference_directions")
    assert kernel_function(ForceProblemSpec(1, 1)).name() == "hexapod_force_mpc_1_1"
    assert (kernel_function(ForceProblemSpec(1, 1, PLATFORM_POSE)).name()
            == "hexapod_force_pose_mpc_1_1")
    assert [f.kind for f in FEATURE_KINDS] == ["lines", "normals", "directions"]
    assert [f.ctc_name for f in (PLATFORM_POSE, EDGE_NORMALS, LEG_DIRECTIONS)] == [
        "pose", "edges", "directions"]
    names = list(compiled_task_ctc.layout(EDGE_NORMALS)[0])
    assert names[-8:] == ["normals", "directions", "of_normals", "base", "mask", "frame",
                          "reference_features", "integral"]
    pose = list(compiled_task_ctc.layout(PLATFORM_POSE, False)[0])
    assert pose[-6:] == ["reference", "directions", "base", "frame", "seen", "integral"]


@pytest.mark.parametrize("feature", FEATURE_KINDS, ids=lambda f: f.kind)
def test_the_numpy_and_symbolic_predictions_agree(feature) -> None:  # type: ignore[no-untyped-def]
    """``model_features`` (numpy, the predictive controller's) equals ``sx_of_legs`` (the
    compiled problems')."""
    g = deltalab()
    Rc, pc = exp_so3(np.array([0.02, -0.01, 0.03])), np.array([0.01, 0.02, -0.9])
    _, t = home_pose(g)
    A = g.base_points @ Rc.T + pc  # camera frame: the camera under the base, looking up
    d = (g.platform_points + t) @ Rc.T + pc - A
    u = d / np.linalg.norm(d, axis=1, keepdims=True)
    K = np.array([[800.0, 0.0, 320.0], [0.0, 780.0, 240.0], [0.0, 0.0, 1.0]])
    numeric = feature.model_features(A, u, g.leg_radius, K)
    us = [ca.SX.sym(f"u{i}", 3) for i in range(6)]
    As = [ca.SX.sym(f"A{i}", 3) for i in range(6)]
    Kit = ca.SX.sym("Kit", 3, 3)
    f = ca.Function("f", [*us, *As, Kit],
                    [ca.vertcat(*feature.sx_of_legs(us, As, g.leg_radius, Kit))])
    symbolic = np.asarray(f(*u, *A, feature.line_inv_t(K))).reshape(-1, 3)
    assert numeric.shape == symbolic.shape == (feature.units, 3)
    np.testing.assert_allclose(symbolic, numeric, rtol=0, atol=1e-14)
    if feature is not EDGE_LINES:
        np.testing.assert_array_equal(feature.line_inv_t(K), np.eye(3))


def test_a_feature_refuses_what_it_does_not_have() -> None:
    with pytest.raises(ValueError, match="'lines': no compiled computed-torque step"):
        compiled_task_ctc.task_step(EDGE_LINES, True)
    with pytest.raises(ValueError, match=r"'directions'.*encoders"):
        compiled_task_ctc.task_step(LEG_DIRECTIONS, False)
    with pytest.raises(ValueError, match="'pose': no features of legs"):
        PLATFORM_POSE.sx_of_legs([], [], 0.01)
    with pytest.raises(ValueError, match="'lines' needs the camera's line_matrix"):
        EDGE_LINES.line_inv_t(None)


def test_a_feature_is_pickled_by_reference() -> None:
    """One object per kind in every process: what holds it (a controller, a compiled
    step, a problem spec) compares and caches by it."""
    for feature in BUILTIN_FEATURES:
        if isinstance(feature, EdgeFeature):
            assert feature.block_function is not None  # cached: must not travel
        assert pickle.loads(pickle.dumps(feature)) is feature
        assert len(pickle.dumps(feature)) < 200
    spec = ForceProblemSpec(2, 1, PLATFORM_POSE)
    assert pickle.loads(pickle.dumps(spec)) == spec
    with pytest.raises(ValueError, match="expected one of normals, lines"):
        builtin_feature("pixels")


def _goal_edges() -> tuple[np.ndarray, np.ndarray]:
    """Edge normals (6, 2, 3) of the legs at home seen from a camera under the base, and
    a perspective line matrix."""
    g = deltalab()
    _, t = home_pose(g)
    A = g.base_points + np.array([0.01, 0.02, 0.9])
    d = g.platform_points + t - g.base_points
    u = d / np.linalg.norm(d, axis=1, keepdims=True)
    n = EDGE_NORMALS.model_features(A, u, g.leg_radius, None).reshape(6, 2, 3)
    return n, np.array([[800.0, 0.0, 0.0], [0.0, 780.0, 0.0], [320.0, 240.0, 1.0]])


def test_the_edge_feature_reads_the_camera() -> None:
    """The lines need a perspective camera's invertible line matrix; the normals any
    camera (the law keeps its identity)."""
    _, K = _goal_edges()
    perspective = SimpleNamespace(kind="perspective", line_matrix=K)
    assert EDGE_NORMALS.line_matrix_of(SimpleNamespace(kind="unified"), "law") is None
    np.testing.assert_array_equal(EDGE_LINES.line_matrix_of(perspective, "law"), K)
    with pytest.raises(ContextError, match=r"law: context field 'camera'.*got 'unified'"):
        EDGE_LINES.line_matrix_of(SimpleNamespace(kind="unified", line_matrix=K), "law")
    singular = SimpleNamespace(kind="perspective", line_matrix=np.zeros((3, 3)))
    with pytest.raises(ContextError, match=r"'camera.line_matrix'.*not an invertible"):
        EDGE_LINES.line_matrix_of(singular, "law")


def test_the_edge_feature_reads_the_goal() -> None:
    """The desired lines come from the goal's lines, else from its normals; the normals
    from the goal's, else from the lines; a hidden or non-finite line is zero and not
    visible; the law core's desired input is the feature's own."""
    n, K = _goal_edges()
    Kit = np.linalg.inv(K).T
    l = EDGE_LINES.features_of(n, Kit)
    vis = np.ones((6, 2), dtype=bool)
    vis[1, 0] = False
    # normals: the goal's normals, the lines unread (even of a wrong shape)
    goal = SimpleNamespace(normals=n, lines=np.zeros(3))
    lines, normals, v = EDGE_NORMALS.desired_of(goal, vis, np.eye(3), np.eye(3), "law")
    assert lines is None and v is vis
    np.testing.assert_array_equal(normals, n)
    assert EDGE_NORMALS.desired_input(None, n) is n
    # lines from the goal's lines only: a NaN line is hidden, the normals rebuilt
    l_nan = l.copy()
    l_nan[4, 1] = np.nan
    lines, normals, v = EDGE_LINES.desired_of(SimpleNamespace(normals=None, lines=l_nan),
                                              vis, K, Kit, "law")
    expected_vis = vis.copy()
    expected_vis[4, 1] = False
    np.testing.assert_array_equal(v, expected_vis)
    assert lines is not None and normals is not None
    np.testing.assert_array_equal(lines[~expected_vis], 0.0)
    np.testing.assert_array_equal(lines[expected_vis], l[expected_vis])
    np.testing.assert_allclose(normals[expected_vis], n[expected_vis], rtol=0, atol=1e-12)
    assert EDGE_LINES.desired_input(lines, normals) is lines
    # lines from the normals (an estimated camera): the goal's normals kept
    lines, normals, v = EDGE_LINES.desired_of(SimpleNamespace(normals=n, lines=None),
                                              vis, K, Kit, "law")
    assert normals is not None and lines is not None
    np.testing.assert_array_equal(normals, n)
    np.testing.assert_allclose(lines[vis], l[vis], rtol=0, atol=1e-15)
    with pytest.raises(ContextError, match=r"'goal.lines': missing \(and no goal.normals\)"):
        EDGE_LINES.desired_of(SimpleNamespace(normals=None, lines=None), vis, K, Kit, "law")
    with pytest.raises(ContextError, match=r"'goal.normals': expected shape \(6, 2, 3\)"):
        EDGE_NORMALS.desired_of(SimpleNamespace(normals=n[:5], lines=None), vis, K, Kit,
                                "law")
