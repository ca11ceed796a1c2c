"""Replaying a servo session: its record (:mod:`benchmarks.robot.records`) as a trial
record, which ``hexapod-bench viz`` replays as it replays a recorded trial.

The periods are replayed (not the header or the final record; older logs without a
header, whose periods carry ``velocities_mm_s``, too), each at the nominal forward
kinematics of its measured lengths (what the session used), with the applied
velocities, else the commanded ones. The robot, camera and goal are the header's unless
given (viz's ``--geometry``, ``--camera-file``, ``--camera-pose``, ``--goal``); without a
header, ``deltalab``, ``front`` and the last period's pose. The log says how many edges
were seen, not which: a period with none shows every edge hidden, any other every edge
seen (an ``edge_visible`` field, when a log has it, is used as it is).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.exceptions import BenchmarkError
from benchmarks.robot.records import is_header, is_period, is_servo_log


def find_session_log(path: Path) -> Path | None:
    """The servo log of ``path``: the file itself, or the one servo log of a directory
    (a session directory); None when there is none.

    Raises:
        BenchmarkError: A directory with several servo logs.
    """
    if path.is_file():
        return path if is_servo_log(path) else None
    if not path.is_dir():
        return None
    logs = sorted(p for p in path.glob("*.jsonl") if is_servo_log(p))
    if len(logs) > 1:
        raise BenchmarkError(f"{path}: {len(logs)} servo session logs "
                             f"({', '.join(p.name for p in logs[:6])}); give the file")
    return logs[0] if logs else None


def _rows(path: Path) -> tuple[dict[str, Any], list[dict[str, Any]], dict[str, Any]]:
    """The header (empty without one), the periods and the final record (empty
    without one: a session cut by a crash)."""
    header: dict[str, Any] = {}
    final: dict[str, Any] = {}
    rows: list[dict[str, Any]] = []
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
            if is_header(row) and not header and not rows:
                header = row
                continue
            if isinstance(row, dict) and row.get("final") is True:
                final = row
                continue
            if not (is_period(row) and "lengths_mm" in row):
                continue
            lengths = row["lengths_mm"]
            if not (isinstance(lengths, list) and len(lengths) == 6 and all(
                    isinstance(x, int | float) and math.isfinite(x) for x in lengths)):
                raise BenchmarkError(f"{path}, line {n}: lengths_mm must be 6 finite numbers "
                                     f"[mm], got {lengths!r}")
            rows.append(row)
    if not rows:
        why = f" (the session ended before its first period: {final['reason']})" \
            if final.get("reason") else ""
        raise BenchmarkError(f"{path}: no period in this servo log{why}")
    return header, rows, final


def _velocities(row: dict[str, Any]) -> list[float]:
    """A period's leg velocities [mm/s]: applied, else commanded (older logs:
    ``velocities_mm_s``), else zeros."""
    for key in ("applied_mm_s", "velocities_mm_s", "commanded_mm_s"):
        v = row.get(key)
        if isinstance(v, list) and len(v) == 6:
            return [_num(x) for x in v]
    return [0.0] * 6


def _num(x: Any) -> float:
    return float(x) if isinstance(x, int | float) else math.nan


def load_session(path: str | Path, geometry_spec: str | None = None,
                 camera_file: str | None = None, camera_pose: str | None = None,
                 goal_file: str | None = None) -> Any:
    """The trial record (:class:`hexapod.visualize.records.TrialRecord`, ``scenario``:
    ``servo session`` and the log's name) of a servo log ``path``, with the session's
    ``--geometry``, ``--camera-file``, ``--camera-pose`` and ``--goal`` (None: the
    module docstring's).

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
    header, rows, _ = _rows(p)
    if geometry_spec is None:
        geometry_spec = str(header.get("geometry") or "deltalab")
    if camera_file is None:
        camera_file = str(header.get("camera_file") or "front")
        if camera_pose is None and header.get("camera_pose"):
            camera_pose = str(header["camera_pose"])
    geometry = robot_geometry(geometry_spec)
    camera = camera_model(camera_file, camera_pose, geometry)
    n = len(rows)
    q = np.array([r["lengths_mm"] for r in rows], float) * 1e-3
    R, t = np.zeros((n, 3, 3)), np.zeros((n, 3))

    def pose(lengths: np.ndarray, where: str, what: str, guess: Any = None) -> Any:
        try:
            sol = forward_kinematics(geometry, lengths, guess=guess, check_stroke=False)
        except ForwardKinematicsError as exc:
            raise BenchmarkError(f"{p}{where}: no platform pose for the {what} mm of "
                                 f"--geometry {geometry_spec}: {exc}") from None
        return sol.rotation, sol.translation

    guess = None
    for k in range(n):
        guess = pose(q[k], f", period {rows[k]['step']}", f"lengths {rows[k]['lengths_mm']}",
                     guess)
        R[k], t[k] = guess
    goal_q = None
    if goal_file is not None:
        goal_q = load_goal(goal_file, geometry).lengths
    elif header.get("goal_lengths_mm") is not None:
        goal_q = np.asarray(header["goal_lengths_mm"], float) * 1e-3
        if goal_q.shape != (6,) or not np.all(np.isfinite(goal_q)):
            raise BenchmarkError(f"{p}, line 1: goal_lengths_mm must be 6 finite numbers "
                                 f"[mm], got {header['goal_lengths_mm']!r}")
    if goal_q is not None:
        Rg, tg = pose(goal_q, "", f"goal lengths {np.round(goal_q * 1e3, 3).tolist()}")
    else:
        Rg, tg = R[-1], t[-1]
    vis = np.ones((n, 6, 2), bool)
    for k, r in enumerate(rows):
        if "edge_visible" in r:
            vis[k] = np.asarray(r["edge_visible"], bool).reshape(6, 2)
        elif not r.get("visible_edges") or r.get("lost_frame"):
            vis[k] = False
    vel = np.array([_velocities(r) for r in rows], float) * 1e-3
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
        "scenario": np.array(f"servo session {p.name}"),
        "controller": np.array(str(header.get("controller") or "servo")),
        "trial": np.array(0),
    }
    return TrialRecord(arrays, str(p))
