"""Replaying a servo session: its log (``hexapod-bench servo --log FILE.jsonl``) as a trial
record, which ``hexapod-bench viz`` replays as it replays a recorded trial (MeshCat, or
``--html FILE`` with the curves beside it).

A session log has one JSON object a line; the periods carry ``step``, ``t_s``,
``lengths_mm``, ``feature_error``, ``velocities_mm_s`` and ``visible_edges``
(:meth:`benchmarks.robot.loop.PeriodStatus.to_json`); any other line (a header, a final
record) is skipped. The platform pose of a period is the nominal forward kinematics of
its measured lengths (what the session itself used), for the robot of ``--geometry``;
the camera drawn is ``--camera-file`` (``--camera-pose``); the errors are measured to
the goal of ``--goal`` (the session's goal file), else to the last period's pose. The
log says how many edges were seen, not which: a period with none shows every edge
hidden, any other every edge seen (an ``edge_visible`` field, when a log has it, is
used as it is).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.exceptions import BenchmarkError

__all__ = ["find_session_log", "is_session_log", "load_session"]


def _is_period(row: Any) -> bool:
    return isinstance(row, dict) and {"step", "t_s", "lengths_mm"} <= set(row)


def is_session_log(path: Path) -> bool:
    """A file a servo session wrote: its first period line has ``step``, ``t_s`` and
    ``lengths_mm`` (within its first lines: a header may come first)."""
    try:
        with path.open(encoding="utf-8") as f:
            for _, line in zip(range(5), f, strict=False):
                if line.strip() and _is_period(json.loads(line)):
                    return True
    except (OSError, UnicodeDecodeError, ValueError):
        return False
    return False


def find_session_log(path: Path) -> Path | None:
    """The servo log of ``path``: the file itself, or the one servo log of a directory
    (a session directory); None when there is none.

    Raises:
        BenchmarkError: A directory with several servo logs.
    """
    if path.is_file():
        return path if is_session_log(path) else None
    if not path.is_dir():
        return None
    logs = sorted(p for p in path.glob("*.jsonl") if is_session_log(p))
    if len(logs) > 1:
        raise BenchmarkError(f"{path}: {len(logs)} servo session logs "
                             f"({', '.join(p.name for p in logs[:6])}); give the file")
    return logs[0] if logs else None


def _rows(path: Path) -> list[dict[str, Any]]:
    rows = []
    with path.open(encoding="utf-8") as f:
        for n, line in enumerate(f, 1):
            if not line.strip():
                continue
            try:
                row = json.loads(line)
            except ValueError as exc:
                if n > 1 and not line.endswith("\n"):  # cut mid-line by a crash: the rest
                    break
                raise BenchmarkError(f"{path}, line {n}: not JSON ({exc})") from None
            if not _is_period(row):
                continue
            lengths = row["lengths_mm"]
            if not (isinstance(lengths, list) and len(lengths) == 6 and all(
                    isinstance(x, int | float) and math.isfinite(x) for x in lengths)):
                raise BenchmarkError(f"{path}, line {n}: lengths_mm must be 6 finite numbers "
                                     f"[mm], got {lengths!r}")
            rows.append(row)
    if not rows:
        raise BenchmarkError(f"{path}: no period in this servo log")
    return rows


def _num(x: Any) -> float:
    return float(x) if isinstance(x, int | float) else math.nan


def load_session(path: str | Path, geometry_spec: str = "deltalab",
                 camera_file: str = "front", camera_pose: str | None = None,
                 goal_file: str | None = None) -> Any:
    """The trial record (:class:`hexapod.visualize.records.TrialRecord`) of a servo log.

    Args:
        path: The ``--log`` file of a session.
        geometry_spec: The session's ``--geometry``.
        camera_file: Its ``--camera-file``.
        camera_pose: Its ``--camera-pose``.
        goal_file: Its ``--goal`` (None: the errors are to the last period's pose).

    Returns:
        The record (``scenario`` = the log's name, ``controller`` = ``servo``).

    Raises:
        BenchmarkError: A line that is not JSON, a period without six finite lengths, no
            period, or lengths without a platform pose.
    """
    from benchmarks.robot.goals import load_goal
    from benchmarks.robot.models import camera_model, robot_geometry
    from hexapod.exceptions import ForwardKinematicsError
    from hexapod.fk import forward_kinematics
    from hexapod.se3 import log_so3
    from hexapod.visualize.records import TrialRecord

    p = Path(path)
    rows = _rows(p)
    geometry = robot_geometry(geometry_spec)
    camera = camera_model(camera_file, camera_pose, geometry)
    n = len(rows)
    q = np.array([r["lengths_mm"] for r in rows], float) * 1e-3
    R, t = np.zeros((n, 3, 3)), np.zeros((n, 3))
    guess = None
    for k in range(n):
        try:
            sol = forward_kinematics(geometry, q[k], guess=guess, check_stroke=False)
        except ForwardKinematicsError as exc:
            raise BenchmarkError(f"{p}, period {rows[k]['step']}: no platform pose for the "
                                 f"lengths {rows[k]['lengths_mm']} mm of --geometry "
                                 f"{geometry_spec}: {exc}") from None
        R[k], t[k] = sol.rotation, sol.translation
        guess = (sol.rotation, sol.translation)
    if goal_file is not None:
        goal = forward_kinematics(geometry, load_goal(goal_file, geometry).lengths,
                                  check_stroke=False)
        Rg, tg = goal.rotation, goal.translation
    else:
        Rg, tg = R[-1], t[-1]
    vis = np.ones((n, 6, 2), bool)
    for k, r in enumerate(rows):
        if "edge_visible" in r:
            vis[k] = np.asarray(r["edge_visible"], bool).reshape(6, 2)
        elif not r.get("visible_edges") or r.get("lost_frame"):
            vis[k] = False
    vel = np.array([r.get("velocities_mm_s") or [0.0] * 6 for r in rows], float) * 1e-3
    arrays = {
        "t": np.array([_num(r["t_s"]) for r in rows]), "lengths": q, "rotations": R,
        "translations": t, "edge_visible": vis,
        "error_norm": np.array([_num(r.get("feature_error")) for r in rows]),
        "position_error": np.linalg.norm(t - tg, axis=1),
        "orientation_error": np.linalg.norm(log_so3(np.swapaxes(R, 1, 2) @ Rg), axis=-1),
        "velocities": vel, "goal_rotation": Rg, "goal_translation": tg,
        "camera_from_base": camera.camera_from_base.as_matrix(),
        "camera_kind": np.array(camera.kind), "camera_K": np.asarray(camera.K, float),
        "camera_size": np.array([camera.width, camera.height]),
        "camera_xi": np.array(float(getattr(camera, "xi", 0.0))),
        "base_points": geometry.base_points, "platform_points": geometry.platform_points,
        "stroke": np.array(geometry.stroke), "leg_radius": np.array(geometry.leg_radius),
        "scenario": np.array(f"servo session {p.name}"), "controller": np.array("servo"),
        "trial": np.array(0),
    }
    return TrialRecord(arrays, str(p))
