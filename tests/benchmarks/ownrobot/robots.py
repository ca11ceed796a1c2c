"""Files of a robot that is not the reference one (base radius 350 mm, platform radius
200 mm, strokes 380-540 mm) and its studies, written as a user writes them."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from controllers.base import Command, Controller, ControllerContext, Observation
from hexapod.geometry import HexapodGeometry, circular_points


def own_robot(stroke: tuple[float, float] = (0.380, 0.540)) -> HexapodGeometry:
    """A 6-6 platform: joint pairs 10 deg apart on the base, 12 deg on the platform."""
    a, b = np.deg2rad(5.0), np.deg2rad(6.0)
    base, plat = [], []
    for k in range(3):
        c = 2 * k * np.pi / 3
        base += [c + a, c - a]
        plat += [c + np.pi / 3 - b, c - np.pi / 3 + b]
    return HexapodGeometry(circular_points(0.350, np.array(base)),
                           circular_points(0.200, np.array(plat)), stroke, 0.015, 0.05,
                           "own")


def write_study(folder: Path, geometry: str | None = "robot.toml",
                camera: str | None = None, controllers: str = '["leg-edge"]',
                extra: str = "", trials: int = 2) -> Path:
    """A scenario file in ``folder`` naming the robot and camera files (relative paths)."""
    lines = ['name = "own"', f"trials = {trials}", f"controllers = {controllers}", extra]
    if geometry:
        lines += ["[robot]", f'geometry = "{geometry}"']
    if camera:
        lines += ["[camera]", f'file = "{camera}"']
    lines += ["[task]", "max_steps = 300", "position_tolerance_mm = 0.5",
              "orientation_tolerance_deg = 0.05"]
    path = folder / "study.toml"
    path.write_text("\n".join(lines) + "\n")
    return path


#: A perspective camera with the robot 2 m behind it (looking along +z, robot at z = -2 m).
BLIND_CAMERA = """kind = "perspective"
width_px = 1024
height_px = 780
fx_px = 1032.0
fy_px = 1032.0
cx_px = 511.5
cy_px = 389.5

[camera_from_base]
translation_mm = [0.0, 0.0, -2000.0]
rotation_vector_deg = [0.0, 0.0, 0.0]
"""


class AlwaysCrash(Controller):
    """A controller whose ``step`` always raises (a bug in a plugin)."""

    name = "test-always-crash"
    features = frozenset({"lengths"})

    def reset(self, context: ControllerContext) -> None:
        """Nothing to prepare."""

    def step(self, observation: Observation) -> Command:
        """Raise (deliberately)."""
        raise RuntimeError("deliberate bug for the test")


CRASH = "tests.benchmarks.ownrobot.robots:AlwaysCrash"


def run_cli(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    """``hexapod-bench ARGS`` in a fresh process (its own logging configuration)."""
    root = Path(__file__).resolve().parents[3]
    env = {**os.environ, "PYTHONPATH": str(root)}
    return subprocess.run([sys.executable, "-m", "benchmarks.cli", *args], capture_output=True,
                          text=True, env=env, cwd=cwd or root, timeout=240, check=False)
