"""MeshCat viewer: records, HTML export, and a real headless browser looking at it."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from hexapod import HexapodGeometry, inverse_kinematics, sample_poses
from hexapod.se3 import exp_so3, log_so3
from hexapod.visualize import (
    RECORD_KEYS,
    HexapodViewer,
    RecordError,
    load_trial,
    plot_trial,
    replay_html,
    replay_trial,
    save_trial,
)

BROWSER_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                 "--no-first-run", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--window-size=800,600",
                 "--use-angle=swiftshader", "--enable-unsafe-swiftshader"]


def _browser() -> str:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    raise AssertionError("no headless browser: install Debian's chromium (.ci/run does); "
                         "the viewer test must run, not skip")


def _screenshot(html: Path, png: Path, budget_ms: int, tmp: Path) -> np.ndarray:
    import cv2

    cmd = [_browser(), *BROWSER_FLAGS, f"--user-data-dir={tmp / ('profile' + png.stem)}",
           f"--virtual-time-budget={budget_ms}", f"--screenshot={png}", html.as_uri()]
    subprocess.run(cmd, check=True, timeout=120, capture_output=True)
    image = cv2.imread(str(png))
    assert image is not None, f"the browser wrote no screenshot {png}"
    return image[:, :, ::-1].astype(int)  # RGB


def _fractions(rgb: np.ndarray) -> tuple[float, float]:
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    orange = (r > 170) & (g > 70) & (g < 175) & (b < 90)          # platform
    blue = (b > 140) & (r < 90) & (g < 140) & (b - r > 90)         # leg bodies
    return float(orange.mean()), float(blue.mean())


@pytest.fixture
def record_path(tmp_path: Path, geometry: HexapodGeometry) -> Path:
    """A synthetic trial: the platform moves from one pose to another over 2 s."""
    R, t = sample_poses(geometry, 2, rng=3, max_translation=0.06, max_angle=0.2)
    n = 101
    s = np.linspace(0.0, 1.0, n)
    w = log_so3(R[1] @ R[0].T)
    rot = np.array([exp_so3(w * x) @ R[0] for x in s])
    trans = t[0] + s[:, None] * (t[1] - t[0])
    vis = np.ones((n, 6, 2), dtype=bool)
    vis[40:60, 3, 1] = False
    arrays = {
        "t": s * 2.0, "lengths": inverse_kinematics(geometry, rot, trans), "rotations": rot,
        "translations": trans, "edge_visible": vis, "error_norm": np.exp(-3 * s),
        "position_error": np.linalg.norm(trans - t[1], axis=1),
        "orientation_error": np.linalg.norm(log_so3(np.swapaxes(rot, 1, 2) @ R[1]), axis=-1),
        "velocities": np.zeros((n, 6)), "goal_rotation": R[1], "goal_translation": t[1],
        "camera_from_base": np.array([[0, -1, 0, 0], [0, 0, -1, 0.3], [1, 0, 0, 0.8],
                                      [0, 0, 0, 1.0]]),
        "camera_kind": np.array("perspective"),
        "camera_K": np.array([[1000.0, 0, 512], [0, 1000, 390], [0, 0, 1]]),
        "camera_size": np.array([1024, 780]), "camera_xi": np.array(0.0),
        "base_points": geometry.base_points, "platform_points": geometry.platform_points,
        "stroke": np.array(geometry.stroke), "leg_radius": np.array(geometry.leg_radius),
        "scenario": np.array("synthetic"), "controller": np.array("none"),
        "trial": np.array(0),
    }
    return save_trial(tmp_path / "trial.npz", **arrays)


def test_record_round_trip_and_errors(record_path: Path, tmp_path: Path) -> None:
    rec = load_trial(record_path)
    assert rec.frames == 101 and "synthetic" in rec.title
    with pytest.raises(RecordError, match="no such"):
        load_trial(tmp_path / "missing.npz")
    with np.load(record_path) as data:
        arrays = {k: data[k] for k in data.files if k != "goal_rotation"}
    np.savez(tmp_path / "bad.npz", **arrays)
    with pytest.raises(RecordError) as info:
        load_trial(tmp_path / "bad.npz")
    assert info.value.key == "goal_rotation"
    with pytest.raises(RecordError, match="missing keys"):
        save_trial(tmp_path / "x.npz", t=np.zeros(3))
    assert set(RECORD_KEYS) <= set(np.load(record_path).files)


def test_html_is_self_contained(record_path: Path, tmp_path: Path) -> None:
    html = replay_html(load_trial(record_path), tmp_path / "replay.html").read_text()
    assert len(html) > 10_000
    remote = re.findall(r"<(?:script|link)[^>]+(?:src|href)=[\"']https?://", html)
    assert not remote, f"the page loads remote resources: {remote[:3]}"


def test_replay_in_a_real_browser(record_path: Path, tmp_path: Path) -> None:
    html, png = replay_trial(record_path, tmp_path / "replay.html")
    assert png.exists() and png.stat().st_size > 10_000  # the matplotlib companion
    early = _screenshot(html, tmp_path / "early.png", 300, tmp_path)
    late = _screenshot(html, tmp_path / "late.png", 2500, tmp_path)
    for image in (early, late):
        orange, blue = _fractions(image)
        assert 0.004 < orange < 0.3, f"platform colour fraction {orange:.4f}"
        assert 0.005 < blue < 0.3, f"leg colour fraction {blue:.4f}"
    # the platform moved between the two frames: the images differ, mostly near it
    changed = np.any(np.abs(early - late) > 30, axis=-1)
    assert changed.mean() > 0.003, "two frames of the animation look the same"
    rows = np.flatnonzero(changed.any(axis=1))
    plat_rows = np.flatnonzero(_platform_mask(early).any(axis=1))
    assert rows.min() <= plat_rows.max() and rows.max() >= plat_rows.min()


def _platform_mask(rgb: np.ndarray) -> np.ndarray:
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    return (r > 170) & (g > 70) & (g < 175) & (b < 90)


def test_live_viewer_is_rate_limited_and_closes(geometry: HexapodGeometry,
                                                tmp_path: Path) -> None:
    viewer = HexapodViewer(geometry)
    try:
        assert viewer.url().startswith("http://127.0.0.1")
        R, t = sample_poses(geometry, 1, rng=1)
        assert viewer.display(R[0], t[0], force=True)
        assert not viewer.display(R[0], t[0]), "a second update within 1/30 s is skipped"
        hidden = np.ones((6, 2), dtype=bool)
        hidden[2] = False
        assert viewer.display(R[0], t[0], hidden, force=True)
        plot_trial  # noqa: B018 - imported for the companion plot (tested above)
    finally:
        viewer.close()
    server = getattr(viewer.viewer.window, "server_proc", None)
    assert server is None or server.poll() is not None, "the MeshCat server is still running"
