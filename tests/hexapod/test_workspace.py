"""Tests of hexapod.workspace: home pose, random poses inside the strokes, the 64
extremal configurations."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from hexapod import (
    HexapodGeometry,
    extremal_configurations,
    home_pose,
    inverse_kinematics,
    sample_poses,
)
from hexapod.exceptions import WorkspaceError
from hexapod.se3 import log_so3


def test_home_pose(geometry: HexapodGeometry) -> None:
    R, t = home_pose(geometry)
    np.testing.assert_array_equal(R, np.eye(3))
    assert t[:2].tolist() == [0.0, 0.0]
    assert inverse_kinematics(geometry, R, t).mean() == pytest.approx(geometry.q_mid, abs=1e-12)
    _, t2 = home_pose(geometry, height=0.4)
    assert t2[2] == 0.4


@pytest.mark.parametrize("which", ["geometry", "other_geometry"])
def test_sample_poses_inside_strokes(which: str, request: pytest.FixtureRequest) -> None:
    geo = request.getfixturevalue(which)
    R, t = sample_poses(geo, 500, rng=3, max_translation=0.05, max_angle=np.deg2rad(8))
    assert R.shape == (500, 3, 3) and t.shape == (500, 3)
    q = inverse_kinematics(geo, R, t)
    assert q.min() >= geo.q_min and q.max() <= geo.q_max
    np.testing.assert_allclose(R @ np.swapaxes(R, -1, -2), np.broadcast_to(np.eye(3), R.shape),
                               atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)
    _, t0 = home_pose(geo)
    assert np.abs(t - t0).max() <= 0.05
    assert np.linalg.norm(log_so3(R), axis=1).max() <= np.deg2rad(8) + 1e-12
    # Spread over the box, not stuck at the home pose.
    assert np.ptp(t, axis=0).min() > 0.03


def test_sample_poses_margin(geometry: HexapodGeometry) -> None:
    margin = 0.02
    R, t = sample_poses(geometry, 200, rng=5, margin=margin)
    q = inverse_kinematics(geometry, R, t)
    assert q.min() >= geometry.q_min + margin and q.max() <= geometry.q_max - margin


def test_sample_poses_seeded(geometry: HexapodGeometry) -> None:
    a = sample_poses(geometry, 50, rng=11)
    b = sample_poses(geometry, 50, rng=np.random.default_rng(11))
    c = sample_poses(geometry, 50, rng=12)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])
    assert not np.allclose(a[1], c[1])


def test_sample_poses_impossible_box(geometry: HexapodGeometry) -> None:
    with pytest.raises(WorkspaceError, match="hardly intersects"):
        sample_poses(geometry, 5, rng=1, margin=0.08)  # margins leave an empty stroke


def test_extremal_configurations(geometry: HexapodGeometry) -> None:
    ext = extremal_configurations(geometry)
    assert ext.lengths.shape == (64, 6)
    expected = {tuple(c) for c in itertools.product(geometry.stroke, repeat=6)}
    assert {tuple(row) for row in ext.lengths} == expected
    assert ext.reachable.all()
    assert ext.unreachable_indices == []
    q = inverse_kinematics(geometry, ext.rotations, ext.translations)
    np.testing.assert_allclose(q, ext.lengths, atol=1e-10)
    # On the assembly mode of the home pose: platform above the base, moderate tilt.
    assert ext.translations[:, 2].min() > 0.2
    assert np.linalg.norm(log_so3(ext.rotations), axis=1).max() < np.deg2rad(60)


def test_extremal_configurations_margin_and_unreachable(geometry: HexapodGeometry,
                                                        other_geometry: HexapodGeometry) -> None:
    ext = extremal_configurations(geometry, margin=0.005)
    assert ext.lengths.min() == pytest.approx(geometry.q_min + 0.005)
    assert ext.lengths.max() == pytest.approx(geometry.q_max - 0.005)
    assert ext.reachable.all()
    # The other robot has a long stroke: most of its corners have no pose. They are
    # reported, with NaN poses; the reachable ones reproduce their lengths.
    other = extremal_configurations(other_geometry)
    bad = other.unreachable_indices
    assert 0 < len(bad) < 64
    assert np.isnan(other.rotations[bad]).all() and np.isnan(other.translations[bad]).all()
    ok = other.reachable
    np.testing.assert_allclose(
        inverse_kinematics(other_geometry, other.rotations[ok], other.translations[ok]),
        other.lengths[ok], atol=1e-10)


def test_home_height_bisection_is_inverse_kinematics_bisection_bitwise(geometry) -> None:
    """Each halving of the home height's bisection gives the mean leg length that
    :func:`inverse_kinematics` gives at the level pose, to the last bit (on robots with
    perturbed joint points, as a study's trials have)."""
    import dataclasses

    from hexapod.workspace import _bisect_home_height

    def reference(g) -> float:  # the plain bisection through inverse_kinematics
        lo, hi = 1e-3, 4.0 * g.q_max
        for _ in range(100):
            mid = 0.5 * (lo + hi)
            q = inverse_kinematics(g, np.eye(3), np.array([0.0, 0.0, mid]))
            lo, hi = (mid, hi) if q.mean() < g.q_mid else (lo, mid)
        return 0.5 * (lo + hi)

    rng = np.random.default_rng(7)
    for _ in range(20):
        g = dataclasses.replace(
            geometry, base_points=geometry.base_points + rng.normal(scale=1e-3, size=(6, 3)),
            platform_points=geometry.platform_points + rng.normal(scale=1e-3, size=(6, 3)))
        h = _bisect_home_height(g)
        assert h == reference(g)
        assert inverse_kinematics(g, np.eye(3), np.array([0.0, 0.0, h])).mean() == \
            pytest.approx(g.q_mid, abs=1e-12)


def test_remembered_home_heights_of_many_robots_are_each_robots_bisection(
        geometry, monkeypatch: pytest.MonkeyPatch) -> None:
    """remember_home_heights bisects many robots together and gives each the height of
    its own bisection, to the last bit, on the instance (more robots than the cache
    holds) and in the cache; a robot already known is not bisected again."""
    import dataclasses

    from hexapod import workspace

    rng = np.random.default_rng(11)
    robots = [dataclasses.replace(
        geometry, base_points=geometry.base_points + rng.normal(scale=s, size=(6, 3)),
        platform_points=geometry.platform_points + rng.normal(scale=s, size=(6, 3)))
        for s in rng.uniform(0.0, 3e-3, 12)]
    robots.append(dataclasses.replace(robots[0]))  # the same robot, another instance
    alone = [workspace._bisect_home_height(g) for g in robots]
    monkeypatch.setattr(workspace, "_HOME_HEIGHTS", {})
    monkeypatch.setattr(workspace, "HOME_CACHE_SIZE", 5)
    workspace.remember_home_heights(robots)
    assert [g.__dict__.get("home_height") for g in robots] == alone
    assert alone[-1] == alone[0] and len(workspace._HOME_HEIGHTS) <= 5
    calls: list[int] = []
    monkeypatch.setattr(workspace, "_bisect_home_heights",
                        lambda gs: calls.append(len(gs)) or np.zeros(len(gs)))
    last = dataclasses.replace(robots[-2])  # a new instance of the last robot remembered
    workspace.remember_home_heights([*robots, last])
    assert calls == [] and last.__dict__["home_height"] == alone[-2]
    assert all(g.home_height == h for g, h in zip(robots, alone, strict=True))
