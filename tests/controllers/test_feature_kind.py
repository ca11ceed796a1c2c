"""The built-in feature objects (:mod:`controllers.tasks.feature_kind`): what they read,
their kernels' names (the compiled libraries' cache keys), their two predictions (numpy
and CasADi) and their refusals."""

from __future__ import annotations

import pickle

import casadi as ca
import numpy as np
import pytest

from controllers.data import FEATURE_FIELDS
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
