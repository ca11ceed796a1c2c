"""Trial records: the ``.npz`` time series of one closed-loop trial, validated.

A record is what the benchmark writes for a recorded trial and what the viewer
replays: every array has the shape given by :data:`RECORD_SHAPES`; a file with a
missing key or a wrong shape is refused with :class:`~hexapod.exceptions.RecordError`
naming the file and the key.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hexapod.exceptions import RecordError
from hexapod.geometry import HexapodGeometry

#: Shape of every array of a trial record; ``"T"`` is the number of control periods.
RECORD_SHAPES: dict[str, tuple[int | str, ...]] = {
    "t": ("T",), "lengths": ("T", 6), "rotations": ("T", 3, 3), "translations": ("T", 3),
    "edge_visible": ("T", 6, 2), "error_norm": ("T",), "position_error": ("T",),
    "orientation_error": ("T",), "velocities": ("T", 6),
    "goal_rotation": (3, 3), "goal_translation": (3,),
    "camera_from_base": (4, 4), "camera_kind": (), "camera_K": (3, 3), "camera_size": (2,),
    "camera_xi": (), "base_points": (6, 3), "platform_points": (6, 3), "stroke": (2,),
    "leg_radius": (), "scenario": (), "controller": (), "trial": (),
}
#: Keys of a trial record, with their number of dimensions.
RECORD_KEYS: dict[str, int] = {k: len(s) for k, s in RECORD_SHAPES.items()}
#: Camera kinds a record may name.
CAMERA_KINDS = ("perspective", "unified", "fisheye", "double_sphere", "eucm")


@dataclass
class TrialRecord:
    """Time series of one closed-loop trial (as saved by the benchmark), validated.

    Attributes:
        arrays: Every array of the record, by key (see :data:`RECORD_SHAPES`): times
            ``t`` [s], ``lengths`` [m], the true platform pose ``rotations``,
            ``translations`` [m] in the base frame, ``edge_visible``, the errors
            ``error_norm``, ``position_error`` [m], ``orientation_error`` [rad],
            ``velocities`` [m/s], the goal, the camera, the geometry and the labels.
        path: The file it was read from.

    Raises:
        RecordError: A key is missing or has the wrong shape or value.
    """

    arrays: dict[str, np.ndarray]
    path: str = "<memory>"

    def __post_init__(self) -> None:
        self.arrays = _validated(self.arrays, self.path)

    def __getitem__(self, key: str) -> np.ndarray:
        return self.arrays[key]

    @property
    def frames(self) -> int:
        """Number of recorded control periods."""
        return len(self.arrays["t"])

    @property
    def camera_kind(self) -> str:
        """``"perspective"`` or ``"unified"``."""
        return str(self.arrays["camera_kind"])

    @property
    def geometry(self) -> HexapodGeometry:
        """The robot drawn (the nominal geometry of the study)."""
        a = self.arrays
        return HexapodGeometry(a["base_points"], a["platform_points"],
                               (float(a["stroke"][0]), float(a["stroke"][1])),
                               float(a["leg_radius"]), name=str(a["scenario"]))

    @property
    def title(self) -> str:
        """``scenario / controller / trial k``, with ``/ sweep point p`` for a record of a
        sweep point other than the first (its file name, ``SCENARIO__pP__...``)."""
        a = self.arrays
        parts = Path(self.path).stem.split("__")
        point = (f" / sweep point {parts[1][1:]}" if len(parts) == 4 and parts[1] != "p0"
                 and parts[1][1:].isdigit() else "")
        return f"{a['scenario']}{point} / {a['controller']} / trial {int(a['trial'])}"


def _validated(arrays: dict[str, Any], path: str) -> dict[str, np.ndarray]:
    """The arrays as numpy arrays, after checking every key's presence and shape."""
    out = {k: np.asarray(v) for k, v in arrays.items()}
    for key in RECORD_SHAPES:
        if key not in out:
            raise RecordError(path, "missing", key)
    if out["t"].ndim != 1 or len(out["t"]) == 0:
        raise RecordError(path, f"expected a non-empty (T,) array, got shape "
                          f"{out['t'].shape}", "t")
    n = len(out["t"])
    for key, shape in RECORD_SHAPES.items():
        want = tuple(n if s == "T" else s for s in shape)
        if out[key].shape != want:
            raise RecordError(path, f"expected shape {want} (T = {n} frames), got "
                              f"{out[key].shape}", key)
    if str(out["camera_kind"]) not in CAMERA_KINDS:
        raise RecordError(path, f"'{out['camera_kind']}' is not one of {CAMERA_KINDS}",
                          "camera_kind")
    for key, shape in (("leg_forces", (n, 6)), ("force_limit", (6,))):  # dynamic world
        if key in out and out[key].shape != shape:
            raise RecordError(path, f"expected shape {shape} (T = {n} frames), got "
                              f"{out[key].shape}", key)
    if ("leg_forces" in out) != ("force_limit" in out):
        raise RecordError(path, "leg_forces and force_limit go together", "force_limit")
    out["edge_visible"] = out["edge_visible"].astype(bool)
    return out


#: The end of the name of a record being written (``NAME.npz.PID`` + this), renamed to
#: ``NAME.npz`` when whole.
TMP_SUFFIX = ".tmp.npz"


def save_trial(path: str | Path, **arrays: Any) -> Path:
    """Save a trial record (compressed ``.npz``), checking its keys and shapes first.

    The file is written beside its final name and renamed, so that an interrupted
    run never leaves a truncated record.

    Args:
        path: Output file.
        **arrays: The arrays of :data:`RECORD_SHAPES` (extra keys are kept).

    Returns:
        The path written.

    Raises:
        RecordError: A key is missing or malformed (nothing is written).
        OSError: The file could not be written (named; nothing is left beside it).
    """
    missing = [k for k in RECORD_SHAPES if k not in arrays]
    if missing:
        raise RecordError(str(path), f"missing keys {missing}")
    data = _validated(arrays, str(path))
    p = Path(path)
    tmp = p.with_name(p.name + f".{os.getpid()}{TMP_SUFFIX}")
    try:
        np.savez_compressed(tmp, **data)  # type: ignore[arg-type]
        os.replace(tmp, p)
    except BaseException as exc:
        tmp.unlink(missing_ok=True)  # (a full disk, Ctrl-C: no part left beside)
        if isinstance(exc, OSError) and exc.filename is None:  # name the file
            raise OSError(exc.errno, exc.strerror or str(exc), str(p)) from exc
        raise
    return p


def load_trial(path: str | Path) -> TrialRecord:
    """Read and validate a trial record.

    Args:
        path: A ``.npz`` file written by :func:`save_trial`.

    Returns:
        The record.

    Raises:
        RecordError: Naming the file and the missing or malformed key.
    """
    p = Path(path)
    if not p.exists():
        raise RecordError(str(p), "no such trial record")
    try:
        with np.load(p, allow_pickle=False) as data:
            arrays = {k: np.array(data[k]) for k in data.files}
    except (OSError, ValueError) as exc:
        raise RecordError(str(p), f"not a readable .npz record: {exc}") from None
    return TrialRecord(arrays, str(p))


def synthetic_record(geometry: HexapodGeometry, frames: int = 101, duration: float = 2.0,
                     seed: int = 3, hidden: tuple[int, float, float] | None = (3, 0.4, 0.6),
                     camera_kind: str = "perspective") -> TrialRecord:
    """A made-up trial for tests and demos: the platform glides between two sampled poses.

    The start and goal poses come from :func:`hexapod.workspace.sample_poses`; the
    motion is a geodesic (constant rotation rate, straight translation), the leg
    lengths its inverse kinematics.

    Args:
        geometry: The robot.
        frames: Number of control periods.
        duration: Length of the trial [s].
        seed: Seed of the two poses.
        hidden: ``(leg, start, end)``: that leg's second edge is hidden between these
            fractions of the trial; None: every edge always visible.
        camera_kind: ``"perspective"`` or ``"unified"`` (the camera drawn).

    Returns:
        The record (``save_trial(path, **record.arrays)`` writes it).
    """
    from hexapod.kinematics import inverse_kinematics
    from hexapod.se3 import exp_so3, log_so3, look_at
    from hexapod.workspace import sample_poses

    R, t = sample_poses(geometry, 2, rng=seed, max_translation=0.06, max_angle=0.2)
    s = np.linspace(0.0, 1.0, frames)
    w = log_so3(R[1] @ R[0].T)
    rot = np.array([exp_so3(w * x) @ R[0] for x in s])
    trans = t[0] + s[:, None] * (t[1] - t[0])
    vis = np.ones((frames, 6, 2), dtype=bool)
    if hidden is not None:
        vis[(s >= hidden[1]) & (s <= hidden[2]), hidden[0], 1] = False
    lengths = inverse_kinematics(geometry, rot, trans)
    # a camera in front of the robot, looking at its centre (x right, y down, z forward)
    centre = np.array([0.0, 0.0, 0.5 * float(t[0][2])])
    eye = centre + np.array([0.9, 0.0, 0.35])
    base_from_camera = look_at(eye, centre, np.array([0.0, 0.0, 1.0]))
    camera_from_base = np.eye(4)
    camera_from_base[:3, :3] = base_from_camera.T
    camera_from_base[:3, 3] = -base_from_camera.T @ eye
    dt = duration / max(frames - 1, 1)
    arrays = {
        "t": s * duration, "lengths": lengths, "rotations": rot, "translations": trans,
        "edge_visible": vis, "error_norm": np.exp(-3.0 * s),
        "position_error": np.linalg.norm(trans - t[1], axis=1),
        "orientation_error": np.linalg.norm(log_so3(np.swapaxes(rot, 1, 2) @ R[1]),
                                            axis=-1),
        "velocities": np.gradient(lengths, dt, axis=0),
        "goal_rotation": R[1], "goal_translation": t[1],
        "camera_from_base": camera_from_base, "camera_kind": np.array(camera_kind),
        "camera_K": np.array([[600.0, 0, 320], [0, 600, 240], [0, 0, 1]]),
        "camera_size": np.array([640, 480]),
        "camera_xi": np.array(0.9 if camera_kind == "unified" else 0.0),
        "base_points": geometry.base_points, "platform_points": geometry.platform_points,
        "stroke": np.array(geometry.stroke), "leg_radius": np.array(geometry.leg_radius),
        "scenario": np.array("synthetic"), "controller": np.array("none"),
        "trial": np.array(0),
    }
    return TrialRecord(arrays)
