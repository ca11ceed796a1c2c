"""Goals of the real servo loop: goal files (TOML, ``docs/servo.md``), the features taught at
the goal (``--teach``: a burst of frames averaged) and the desired features predicted from
the nominal model; the feature error the loop's convergence test reads."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.exceptions import BenchmarkError
from benchmarks.robot.records import mm_list
from benchmarks.sim.sensors import seen_edges
from hexapod.config import check_keys, get_matrix, load_toml
from hexapod.exceptions import ConfigFileError, ForwardKinematicsError
from hexapod.geometry import HexapodGeometry
from hexapod.outputs import TEXT_MARKER
from vision.feature_cameras import Features, sensor_camera

#: Keys a goal file may have.
GOAL_KEYS = ("lengths_mm", "features", "name")
#: Default number of frames averaged by ``--teach`` (a burst of 0.2 s at 50 Hz).
DEFAULT_TEACH_FRAMES = 10


@dataclass(frozen=True)
class ServoGoal:
    """A goal file: the goal leg lengths (6,) [m], the features recorded there
    (``--teach``; None: predicted from the nominal model), the file and its label."""

    lengths: np.ndarray
    features: Features | None
    source: str
    name: str = ""


def average_features(frames: list[Features], max_deviation: float | None = None
                     ) -> Features:
    """The features of a burst of frames of a still scene, averaged (``--teach``) by
    :func:`vision.estimate.average_normals` (a frame farther than ``max_deviation``
    [rad] from the median does not count for that edge).

    Raises:
        BenchmarkError: No frame.
    """
    from vision.estimate import average_normals

    if not frames:
        raise BenchmarkError("no frame to average")
    normals, visible = average_normals(np.array([f.normals for f in frames], float),
                                       np.array([f.edge_visible for f in frames], bool),
                                       max_deviation=max_deviation)
    return Features(normals, visible)


def teach_tolerance(sensor: Any) -> float | None:
    """The largest deviation of a frame from the median of a taught burst [rad]: the
    detector's inlier distance (``outlier_px``) seen from the camera
    (:func:`vision.estimate.radians_per_pixel`); None if the sensor has no detector."""
    from vision.estimate import radians_per_pixel

    detector = getattr(getattr(sensor, "sensor", sensor), "detector", None)
    if detector is None or not hasattr(detector, "outlier_px"):
        return None
    return float(detector.outlier_px) * radians_per_pixel(sensor_camera(sensor))


def _load_features(path: Path, goal_file: str) -> Features:
    """Read recorded goal features (``normals`` (6, 2, 3), ``edge_visible`` (6, 2)).

    Raises:
        ConfigFileError: Missing or unreadable file, missing array or bad shape.
    """
    if not path.is_file():
        raise ConfigFileError(goal_file, f"features file {path} not found", key="features")
    try:
        with np.load(path) as data:
            arrays = {k: np.asarray(data[k]) for k in data.files}
    except (OSError, ValueError) as exc:
        raise ConfigFileError(goal_file, f"features file {path} cannot be read: {exc}",
                              key="features") from None
    for name, shape in (("normals", (6, 2, 3)), ("edge_visible", (6, 2))):
        if name not in arrays:
            raise ConfigFileError(goal_file, f"features file {path} has no array '{name}' "
                                             f"(has: {', '.join(sorted(arrays)) or 'none'})",
                                  key="features")
        if arrays[name].shape != shape:
            raise ConfigFileError(goal_file, f"features file {path}: '{name}' has shape "
                                             f"{arrays[name].shape}, expected {shape}",
                                  key="features")
    visible = arrays["edge_visible"].astype(bool)
    normals = arrays["normals"].astype(float)
    if not np.all(np.isfinite(normals[visible])):
        raise ConfigFileError(goal_file, f"features file {path}: a visible normal is not "
                                         "finite", key="features")
    if not visible.any():
        raise ConfigFileError(goal_file, f"features file {path}: no edge was seen at the goal",
                              key="features")
    norms = np.linalg.norm(normals, axis=-1)
    off = np.argwhere(visible & (np.abs(norms - 1.0) > 1e-6))
    if len(off):
        leg, edge = (int(i) for i in off[0])
        raise ConfigFileError(goal_file, f"features file {path}: leg {leg} edge {edge}'s "
                                         f"normal has length {norms[leg, edge]:.6g}, not 1 "
                                         "(an edge normal is a unit vector)", key="features")
    return Features(np.where(visible[..., None], normals, np.nan), visible)


def load_goal(path: str | Path, geometry: HexapodGeometry) -> ServoGoal:
    """Read a goal file (``lengths_mm``, optional ``features`` and ``name``) and check it
    against the stroke of ``geometry`` (nothing is sent to the robot).

    Raises:
        ConfigFileError: Missing file, bad TOML, missing or misspelt key, wrong count,
            a length outside the stroke (named by leg), or a bad features file. The
            message names the file and the key.
    """
    src = str(path)
    if not Path(path).exists():  # (the file's own error did not say which option named it)
        raise ConfigFileError(src, f"file not found (--goal): tried {Path(path).resolve()}")
    table = load_toml(path)
    check_keys(table, GOAL_KEYS, src, required=("lengths_mm",))
    q = get_matrix(table, "lengths_mm", (6,), src) * 1e-3
    q_min, q_max = geometry.stroke
    for i, x in enumerate(q):
        if not q_min <= x <= q_max:
            raise ConfigFileError(src, f"leg {i}: {x * 1e3:.3f} mm is outside the stroke "
                                       f"[{q_min * 1e3:.3f}, {q_max * 1e3:.3f}] mm",
                                  key="lengths_mm")
    name = table.get("name", "")
    if not isinstance(name, str):
        raise ConfigFileError(src, f"expected a string, got {name!r}", key="name")
    features = None
    if "features" in table:
        ref = table["features"]
        if not isinstance(ref, str) or not ref:
            raise ConfigFileError(src, f"expected a file name (.npz), got {ref!r}",
                                  key="features")
        fpath = Path(ref) if Path(ref).is_absolute() else Path(path).parent / ref
        features = _load_features(fpath, src)
    return ServoGoal(q, features, src, name)


def save_goal(path: str | Path, lengths: np.ndarray, features: Features,
              name: str = "") -> Path:
    """Write a taught goal: ``path`` (TOML: the measured leg ``lengths`` (6,) [m] and
    the optional label ``name``) and its ``features`` beside it; returns the path of the
    features file (``.npz``)."""
    import tomli_w

    p = Path(path)
    npz = p.with_suffix(".features.npz")
    np.savez(npz, normals=np.asarray(features.normals, float),
             edge_visible=np.asarray(features.edge_visible, bool))
    doc: dict[str, Any] = {"lengths_mm": mm_list(lengths), "features": npz.name}
    if name:
        doc["name"] = name
    p.write_text(f"# {TEXT_MARKER}: taught by hexapod-bench servo --teach\n"
                 + tomli_w.dumps(doc))
    return npz


def goal_features(goal: ServoGoal, camera: Any, geometry: HexapodGeometry) -> Any:
    """The controller's :class:`~controllers.base.Goal` of a taught goal: the forward
    kinematics of the goal lengths in the nominal model, and the recorded features if
    the goal file has some, else what the (estimated) camera sees of the nominal model
    there (:func:`benchmarks.sim.goal.predicted_features`).

    Raises:
        BenchmarkError: No pose for these lengths, or no edge visible at the goal.
    """
    from benchmarks.sim.goal import predicted_features, row_features
    from controllers.base import Goal
    from hexapod.fk import forward_kinematics

    try:
        sol = forward_kinematics(geometry, goal.lengths)
    except ForwardKinematicsError as exc:
        raise BenchmarkError(f"{goal.source}: key 'lengths_mm': no platform pose for these "
                             f"lengths in the nominal model ({exc})") from None
    if goal.features is None:
        feats = predicted_features(camera, geometry, sol.rotation, sol.translation)
    else:
        feats = row_features(seen_edges(camera, np.asarray(goal.features.normals, float)[None],
                                        np.asarray(goal.features.edge_visible, bool)[None]), 0)
    if not feats["edge_visible"].any():
        where = getattr(camera, "source", None)
        fix = (f"change [camera_from_base] in {where}" if where else
               "change the camera's pose (--camera-pose, --camera-file)")
        raise BenchmarkError(f"{goal.source}: the camera sees no leg edge at the goal pose: "
                             f"{fix}, or check that its pose looks at the robot (the robot "
                             "behind it, outside its image, a pose in metres where mm are "
                             "meant; hexapod-bench check shows what it sees)")
    return Goal(lengths=goal.lengths.copy(), rotation=sol.rotation,
                translation=sol.translation, **feats)


def feature_error(measured: Features, desired_normals: np.ndarray,
                  desired_visible: np.ndarray) -> float:
    """Norm of the stacked normal differences over the edges seen in both [-].

    NaN when no edge is seen in both.
    """
    both = measured.edge_visible & desired_visible
    if not both.any():
        return math.nan
    d = measured.normals[both] - desired_normals[both]
    return float(np.linalg.norm(d))
