"""Motion blur (:mod:`vision.exposure`): one pose is the renderer's image bit for bit; a
robot at rest over the exposure too; a moving leg edge's profile along an image row is
the sharp profile convolved with the edge's motion during the exposure, the motion
predicted from the model (the edge's image line ``K^-T n`` at every sampled pose): its
centre moves to the mean of the sampled edge positions and its variance grows by theirs."""

from __future__ import annotations

import numpy as np
import pytest

from hexapod.geometry import deltalab
from hexapod.workspace import home_pose
from vision.cameras.presets import front_camera
from vision.exceptions import RenderError
from vision.exposure import middle_pose, render_exposed
from vision.legs import observe_legs
from vision.render import Renderer, RenderStyle

G = deltalab()
CAM = front_camera(G)
R0, T0 = home_pose(G)
ROW = 300  # image row crossing leg 1 near its platform end
BACKGROUND, LEG = 230, 35
FLAT = RenderStyle(leg_edge_level=LEG, leg_centre_level=LEG, shading_bands=1,
                   platform=False)


def _edge_u(t: np.ndarray) -> float:
    """Column where the left edge of leg 1 crosses ROW at platform position ``t``: the
    image line of the edge's interpretation plane, ``l = K^-T n``."""
    n = observe_legs(CAM, G, R0[None], t[None]).normals[0, 1]  # (2, 3) the two edges
    lines = n @ np.linalg.inv(CAM.K)
    u = -(lines[:, 1] * ROW + lines[:, 2]) / lines[:, 0]
    return float(u.min())


def _profile(img: np.ndarray, lo: int, hi: int) -> tuple[float, float]:
    """Mean and variance [px, px^2] of the edge in columns ``lo..hi`` of ROW: the
    coverage ``f`` rises from 0 (background) to 1 (leg); ``diff(f)`` is its density
    (pixel centres at integer columns, the step between two centres at the half)."""
    f = (BACKGROUND - img[ROW, lo:hi + 1].astype(float)) / (BACKGROUND - LEG)
    assert f[0] == pytest.approx(0.0, abs=1e-9) and f[-1] == pytest.approx(1.0, abs=1e-9)
    g = np.diff(f)
    x = np.arange(lo, hi) + 0.5
    mean = float(np.sum(g * x) / np.sum(g))
    return mean, float(np.sum(g * (x - mean) ** 2) / np.sum(g))


def test_one_pose_is_the_renderers_image_bit_for_bit() -> None:
    style = RenderStyle(blur_px=0.8, noise_std=2.0)
    a = Renderer(CAM, G, style, np.random.default_rng(4)).render(R0, T0)
    b = render_exposed(Renderer(CAM, G, style, np.random.default_rng(4)), R0, T0)
    np.testing.assert_array_equal(a, b)


def test_a_robot_at_rest_is_not_blurred() -> None:
    """Eight identical poses: the mean of identical drawings is the drawing; the blur
    and the noise are applied once (the same draws as one render)."""
    style = RenderStyle(blur_px=0.8, noise_std=2.0)
    a = Renderer(CAM, G, style, np.random.default_rng(4)).render(R0, T0)
    b = render_exposed(Renderer(CAM, G, style, np.random.default_rng(4)),
                       np.repeat(R0[None], 8, axis=0), np.repeat(T0[None], 8, axis=0))
    np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize(("move_mm", "samples"), [(6.0, 16), (12.0, 32)])
def test_a_moving_edge_widens_by_its_image_motion(move_mm: float, samples: int) -> None:
    d = np.array([1e-3 * move_mm, 0.0, 0.0])
    ts = T0 + np.outer((np.arange(samples) + 0.5) / samples, d)  # midpoints of the slices
    u = np.array([_edge_u(t) for t in ts])
    motion = u.max() - u.min()
    assert motion > 2.0  # pixels: a real smear
    renderer = Renderer(CAM, G, FLAT)
    lo, hi = int(np.floor(u.min())) - 4, int(np.ceil(u.max())) + 4
    sharp = renderer.render(R0, T0 + 0.5 * d)
    m_sharp, v_sharp = _profile(sharp, lo, hi)
    assert m_sharp == pytest.approx(_edge_u(T0 + 0.5 * d), abs=0.1)  # the renderer's edge
    exposed = render_exposed(renderer, np.repeat(R0[None], samples, axis=0), ts)
    m_exp, v_exp = _profile(exposed, lo, hi)
    # convolution with the edge's motion: the means and the variances add
    assert m_exp == pytest.approx(float(np.mean(u)), abs=0.1)
    assert v_exp == pytest.approx(v_sharp + float(np.var(u)), rel=0.05, abs=0.1)
    assert v_exp > 3.0 * v_sharp


def test_bad_pose_sequences_are_refused() -> None:
    renderer = Renderer(CAM, G, FLAT)
    with pytest.raises(RenderError, match="exposure poses"):
        render_exposed(renderer, np.zeros((0, 3, 3)), np.zeros((0, 3)))
    with pytest.raises(RenderError, match="exposure poses"):
        render_exposed(renderer, np.repeat(R0[None], 3, axis=0), np.zeros((2, 3)))


def test_the_prediction_uses_the_middle_of_the_exposure() -> None:
    ts = T0 + np.outer(np.arange(5), [1e-3, 0.0, 0.0])
    Rs = np.array([R0 * (k + 1) for k in range(5)])  # distinguishable samples
    R, t = middle_pose(Rs, ts)
    np.testing.assert_array_equal(t, ts[2])
    np.testing.assert_array_equal(R, Rs[2])
    R1, t1 = middle_pose(R0, T0)
    np.testing.assert_array_equal(R1, R0)
    np.testing.assert_array_equal(t1, T0)
