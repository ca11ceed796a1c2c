"""Per-trial time series saved as ``.npz`` records (replayed by ``hexapod-bench viz``).

The keys are those :func:`hexapod.visualize.load_trial` reads.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from benchmarks.sim import load_camera, load_geometry
from benchmarks.study.scenario import Scenario

if TYPE_CHECKING:
    from benchmarks.study.runner import WorkUnit


def trial_record(sc: Scenario, unit: WorkUnit, row: dict[str, Any],
                 series: dict[str, np.ndarray]) -> dict[str, Any]:
    """The arrays of one recorded trial (nominal robot and camera drawn; true pose)."""
    g = load_geometry(sc)
    cam = load_camera(sc, g)
    return {
        "t": series["t"],
        "lengths": series["lengths"],
        "rotations": series["rotations"],
        "translations": series["translations"],
        "edge_visible": series["edge_visible"].astype(bool),
        "error_norm": series["error_norm"],
        "position_error": series["position_error"],
        "orientation_error": series["orientation_error"],
        "velocities": series["velocities"],
        "goal_rotation": series["goal_rotation"],
        "goal_translation": series["goal_translation"],
        "camera_from_base": cam.camera_from_base.as_matrix(),
        "camera_kind": np.array(cam.kind),
        "camera_K": cam.K,
        "camera_size": np.array([cam.width, cam.height]),
        "camera_xi": np.array(float(getattr(cam, "xi", 0.0))),
        "base_points": g.base_points,
        "platform_points": g.platform_points,
        "stroke": np.array(g.stroke),
        "leg_radius": np.array(g.leg_radius),
        "scenario": np.array(sc.name),
        "controller": np.array(unit.controller),
        "trial": np.array(int(row["trial"])),
        # the dynamic world: the drives' forces [N] and their limits (the viewer's colours)
        **({"leg_forces": series["leg_forces"], "force_limit": g.drives.force_limit}
           if "leg_forces" in series else {}),
    }
